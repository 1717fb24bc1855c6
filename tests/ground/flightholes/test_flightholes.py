"""``holescan holes``: a flight logged with the real FlightLogWriter, exported in every format
through the real CLI and parsed back with each format's standard reader (gpxpy, ElementTree,
zipfile, json, pymavlink's MAVWPLoader); rotated and cut-off logs; one-line errors."""

from __future__ import annotations

import base64
import dataclasses
import datetime as dt
import json
import os
import re
import shutil
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import gpxpy
import numpy as np
import numpy.typing as npt
import pytest

from holescan import cli
from holescan.detect import CameraIntrinsics, Detection, FeatureScores, Frame
from holescan.flightlog import FlightLogWriter, LogOptions
from holescan.geotag import Hole, VehiclePose
from holescan.ground import flight_log_files, read_flight_holes
from holescan.link import mavlink as mavlink2

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavwp

CAM = CameraIntrinsics(160, 120, 140.0, 140.0, 79.5, 59.5)
T0_UNIX_NS = 1_750_000_000_000_000_000
T0_BOOT_NS = 95_000_000_000
DT_NS = 33_333_333
N_FRAMES = 40
HOME = (43.7123, 10.4012, 31.5)  # HOME_POSITION: lat, lon, alt MSL
KML = {"k": "http://www.opengis.net/kml/2.2"}


@dataclasses.dataclass(frozen=True)
class Truth:
    """One simulated hole: where it is, which frames see it and how well."""

    hid: int
    lat: float
    lon: float
    frames: tuple[int, ...]  # detection frames that see it
    peak: int  # its best view
    box: tuple[int, int, int, int]

    def score(self, i: int) -> float:
        return round(0.9 - 0.02 * abs(i - self.peak) - 0.05 * self.hid, 4)


TRUTHS = (
    # six views over 0.33 s: announced (AnnounceGate: two sightings over 0.3 s)
    Truth(1, 43.71234567, 10.40123456, (4, 6, 8, 10, 12, 14), 8, (40, 30, 20, 16)),
    Truth(2, 43.71238901, 10.40129876, (12, 14, 16, 18, 20, 22), 16, (90, 60, 24, 20)),
    Truth(3, 43.71231111, 10.40122222, (22,), 22, (60, 40, 18, 18)),  # seen once
)


def colour(i: int) -> tuple[int, int, int]:
    """The unique fill of frame i's hole boxes, to tell frames apart in a thumbnail."""
    return (6 * i % 256, 220, 40)


def t_boot(i: int) -> int:
    return T0_BOOT_NS + i * DT_NS


def make_frame(i: int) -> Frame:
    rng = np.random.default_rng(i)
    rgb = rng.integers(90, 140, (CAM.height, CAM.width, 3), dtype=np.uint8)
    depth = np.full((CAM.height, CAM.width), 1500, np.uint16)
    for t in TRUTHS:
        if i in t.frames:
            x, y, w, h = t.box
            rgb[y : y + h, x : x + w] = colour(i)
            depth[y : y + h, x : x + w] = 2600
    return Frame(i, rgb, depth, 5_000_000_000 + i * DT_NS, i * DT_NS)


def make_pose(i: int) -> VehiclePose:
    return VehiclePose(t_boot(i), 43.71235 + i * 1e-7, 10.40125, 34.0, 2.5, 0.0, 0.0, 1.0)


def detection(t: Truth, i: int) -> Detection:
    return Detection(t.box, t.score(i), FeatureScores(0.9, 0.8, 0.7, 0.6, 0.5), 1.1, 0.7, 0.5, 2.5)


def hole_state(t: Truth, upto: int) -> Hole | None:
    """The tracker's view of hole ``t`` after the detections of frame ``upto``."""
    seen = [i for i in t.frames if i <= upto]
    if not seen:
        return None
    best = max(seen, key=t.score)
    return Hole(
        t.hid,
        t.lat,
        t.lon,
        29.0 + t.hid,
        0.8,
        max(t.score(i) for i in seen),
        len(seen),
        t_boot(seen[0]),
        t_boot(seen[-1]),
        best,
        t.box,
        0.7,
        0.5,
    )


def final_holes() -> dict[int, Hole]:
    holes = [hole_state(t, N_FRAMES) for t in TRUTHS]
    return {h.id: h for h in holes if h is not None}


def home_position_packet() -> bytes:
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = mav.home_position_encode(
        round(HOME[0] * 1e7), round(HOME[1] * 1e7), round(HOME[2] * 1000),
        0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
    )  # fmt: skip
    return bytes(msg.pack(mav))


def write_flight(
    prefix: Path, options: LogOptions | None = None, lost_frames: frozenset[int] = frozenset()
) -> tuple[Path, ...]:
    """A flight as the daemon logs it: frames, then (lagging) each detected frame's
    detections and the whole hole list; the detection worker skips odd frames. Frames in
    ``lost_frames`` are not logged (as when the logger's queue is full)."""
    dets_frames = sorted({i for t in TRUTHS for i in t.frames} | {2, 24, 26})
    with FlightLogWriter(prefix, CAM, options=options) as w:
        w.write_mavlink(home_position_packet(), T0_UNIX_NS, "HOME_POSITION")
        for i in range(N_FRAMES):
            t_unix = T0_UNIX_NS + i * DT_NS
            w.write_pose(make_pose(i), t_unix)
            if i not in lost_frames:
                assert w.write_frame(make_frame(i), t_unix, pose=make_pose(i), t_boot_ns=t_boot(i))
            done = i - 3  # results come three frames late
            if done in dets_frames:
                dets = [detection(t, done) for t in TRUTHS if done in t.frames]
                w.write_detections(done, dets, T0_UNIX_NS + done * DT_NS)
                if dets:
                    holes = [h for t in TRUTHS if (h := hole_state(t, done)) is not None]
                    w.write_holes(holes, T0_UNIX_NS + done * DT_NS)
        w.write_holes(list(final_holes().values()), T0_UNIX_NS + N_FRAMES * DT_NS)
    return w.paths


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    (path,) = write_flight(tmp_path_factory.mktemp("flight") / "flight")
    return path


Main = Callable[[Sequence[str] | None], int]


@pytest.fixture
def main() -> Main:
    return cli.main


def _exported(holes: dict[int, Hole], min_sightings: int = 2) -> list[Hole]:
    keep = [h for h in holes.values() if h.sightings >= min_sightings]
    return sorted(keep, key=lambda h: (-h.score, -h.sightings, h.id))


def _check_thumbnail(jpeg: bytes, hole: Hole) -> None:
    """The picture is the hole's best frame: its box fill colour is at the panel centre."""
    pic = cv2.cvtColor(
        cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB
    )
    assert pic.shape[0] == 160
    _, _, w, h = hole.best_box
    margin = max(24, max(w, h) // 2)
    crop_w, crop_h = w + 2 * margin, h + 2 * margin  # boxes lie away from the frame edges
    scale = 160 / crop_h
    assert pic.shape[1] == 2 * round(crop_w * scale) + 4
    cx, cy = round(crop_w / 2 * scale), round(crop_h / 2 * scale)
    patch: npt.NDArray[np.float64] = pic[cy - 5 : cy + 5, cx - 5 : cx + 5].reshape(-1, 3).mean(0)
    assert hole.best_frame_index is not None
    assert np.abs(patch - colour(hole.best_frame_index)).max() < 8


# --------------------------------------------------------------------------- reading


def test_reader_takes_the_last_record_and_the_best_views(flight: Path) -> None:
    got = read_flight_holes(flight)
    want = final_holes()
    assert got.holes == tuple(want[k] for k in sorted(want))
    assert got.holes_records == 11  # one per frame with detections, and the final one
    assert got.truncated == ()
    assert got.home == pytest.approx(HOME)
    assert got.home_source == "HOME_POSITION"
    assert got.boot_to_unix_ns == T0_UNIX_NS - T0_BOOT_NS
    assert got.frames_read == N_FRAMES
    assert sorted(got.thumbnails) == [1, 2, 3]
    for hid, thumb in got.thumbnails.items():
        assert (thumb.frame_index, thumb.box) == (want[hid].best_frame_index, want[hid].best_box)
        assert thumb.t_unix_ns == T0_UNIX_NS + thumb.frame_index * DT_NS
        _check_thumbnail(thumb.jpeg, want[hid])
    # Without pictures the frames are not decoded; the clock comes from the poses.
    # Results come 3 frames late: 4 frames waiting are enough, 3 are not.
    assert sorted(read_flight_holes(flight, max_pending_frames=4).thumbnails) == [1, 2, 3]
    assert read_flight_holes(flight, max_pending_frames=3).thumbnails == {}
    quick = read_flight_holes(flight, thumbnails=False)
    assert quick.holes == got.holes
    assert (quick.frames_read, quick.thumbnails) == (0, {})
    assert quick.boot_to_unix_ns == T0_UNIX_NS - T0_BOOT_NS


# ------------------------------------------------------------------------------- CLI


def test_every_format_parses_back_with_its_standard_reader(
    flight: Path, tmp_path: Path, main: Main, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out" / "h"
    out.parent.mkdir()
    assert main(["holes", str(flight), "--format", "all", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("2 of 3 holes from 1 file(s), 3 thumbnail(s), home: HOME_POSITION")
    holes = _exported(final_holes())
    ids = [h.id for h in holes]
    assert ids == [1, 2]  # hole 3 was seen once

    # GPX: gpxpy.
    gpx = gpxpy.parse((tmp_path / "out" / "h.gpx").read_text(encoding="utf-8"))
    # the hole seen once is not for the crew (below --min-sightings): not in the files
    assert [p.name for p in gpx.waypoints] == [f"hole {i}" for i in ids]
    for wpt, h in zip(gpx.waypoints[:2], holes, strict=True):
        assert (wpt.latitude, wpt.longitude) == (
            pytest.approx(h.lat_deg, abs=1e-7), pytest.approx(h.lon_deg, abs=1e-7))  # fmt: skip
        assert f"score {h.score:.2f}" in wpt.description
        assert f"seen in {h.sightings} frames" in wpt.description
        first = dt.datetime.fromtimestamp(
            (T0_UNIX_NS - T0_BOOT_NS + h.t_first_boot_ns) / 1e9, dt.UTC
        )
        assert f"first seen {first:%Y-%m-%dT%H:%M:%S.%f}"[:-3] + "Z" in wpt.description

    # KML: an XML parser; thumbnails inline as data: URIs.
    root = ET.parse(tmp_path / "out" / "h.kml").getroot()
    pms = root.findall(".//k:Placemark", KML)
    assert len(pms) == 2
    for pm, h in zip(pms[:2], holes, strict=True):
        data = {
            d.get("name"): json.loads(d.findtext("k:value", "", KML))
            for d in pm.iterfind(".//k:Data", KML)
        }
        assert (data["hole_id"], data["score"], data["sightings"]) == (h.id, h.score, h.sightings)
        assert data["tier"] == "announced" and data["p_hole"] is None  # a log from before
        lon, lat, _ = (float(v) for v in pm.findtext(".//k:coordinates", "", KML).split(","))
        assert (lat, lon) == (
            pytest.approx(h.lat_deg, abs=1e-7),
            pytest.approx(h.lon_deg, abs=1e-7),
        )
        desc = pm.findtext("k:description", "", KML)
        match = re.search(r'src="data:image/jpeg;base64,([A-Za-z0-9+/=]+)"', desc)
        assert match is not None
        _check_thumbnail(base64.b64decode(match.group(1)), h)

    # KMZ: zipfile + XML parser; thumbnails as files.
    with zipfile.ZipFile(tmp_path / "out" / "h.kmz") as kmz:
        assert kmz.namelist()[0] == "doc.kml"
        doc = ET.fromstring(kmz.read("doc.kml"))
        for pm, h in zip(doc.findall(".//k:Placemark", KML), holes, strict=True):
            src = re.search(r'<img src="([^"]+)"', pm.findtext("k:description", "", KML))
            assert src is not None
            _check_thumbnail(kmz.read(src.group(1)), h)

    # GeoJSON: json.
    feats = json.loads((tmp_path / "out" / "h.geojson").read_text())["features"]
    assert len(feats) == 2 and [f["properties"]["tier"] for f in feats] == ["announced"] * 2
    for f, h in zip(feats[:2], holes, strict=True):
        lon, lat = f["geometry"]["coordinates"]
        assert (lat, lon) == (
            pytest.approx(h.lat_deg, abs=1e-7),
            pytest.approx(h.lon_deg, abs=1e-7),
        )
        props = f["properties"]
        assert (props["hole_id"], props["score"], props["sightings"]) == (
            h.id,
            h.score,
            h.sightings,
        )
        assert props["first_seen_utc"].startswith("2025-06-15T15:06:")

    # QGC .plan: json.
    plan = json.loads((tmp_path / "out" / "h.plan").read_text())["mission"]
    assert plan["plannedHomePosition"] == pytest.approx(list(HOME))
    for item, h in zip(plan["items"], holes, strict=True):
        assert item["params"][4:6] == [pytest.approx(h.lat_deg, abs=1e-7),
                                       pytest.approx(h.lon_deg, abs=1e-7)]  # fmt: skip
        assert item["holescan"]["properties"]["hole_id"] == h.id
        assert item["holescan"]["properties"]["score"] == h.score

    # QGC WPL 110: pymavlink's loader (what MAVProxy's ``wp load`` uses).
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(tmp_path / "out" / "h.waypoints")) == 3
    assert (loader.wp(0).x, loader.wp(0).y) == (pytest.approx(HOME[0]), pytest.approx(HOME[1]))
    for seq, h in enumerate(holes, start=1):
        w = loader.wp(seq)
        assert (w.x, w.y) == (
            pytest.approx(h.lat_deg, abs=1e-7),
            pytest.approx(h.lon_deg, abs=1e-7),
        )
        assert w.z == pytest.approx(10.0)  # holes lie below home: 10 m above home


def test_default_names_repeated_formats_and_min_sightings(
    flight: Path, tmp_path: Path, main: Main, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "flight_0000.mcap"
    shutil.copy(flight, log)
    args = ["holes", str(log), "-f", "gpx", "-f", "wpl", "-f", "gpx", "--min-sightings", "1"]
    assert main(args) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "flight_0000.mcap", "flight_holes.gpx", "flight_holes.waypoints"]  # fmt: skip
    gpx = gpxpy.parse((tmp_path / "flight_holes.gpx").read_text())
    assert [p.name for p in gpx.waypoints] == ["hole 1", "hole 2", "review 3"]  # by score
    wpl = (tmp_path / "flight_holes.waypoints").read_text().splitlines()
    assert len(wpl) == 4  # header, home, holes 1 and 2: a hole for review is no waypoint
    assert "wrote" in capsys.readouterr().out


def test_rotated_parts_are_read_as_one_flight(tmp_path: Path, main: Main) -> None:
    # compressed images: 64 KiB parts give 3-5 files
    opts = LogOptions(chunk_size=16 * 1024, max_file_bytes=64 * 1024)
    paths = write_flight(tmp_path / "rot", opts)
    assert len(paths) >= 3
    assert flight_log_files(paths[0]) == paths
    assert flight_log_files(tmp_path / "rot") == paths
    got = read_flight_holes(paths[0])
    assert got.paths == paths
    assert got.holes == tuple(final_holes()[k] for k in (1, 2, 3))
    assert sorted(got.thumbnails) == [1, 2, 3]  # best views found across file boundaries
    for hid, thumb in got.thumbnails.items():
        _check_thumbnail(thumb.jpeg, final_holes()[hid])
    out = tmp_path / "rot.geojson"
    assert main(["holes", str(paths[0]), "--format", "geojson", "--out", str(out)]) == 0
    feats = json.loads(out.read_text())["features"]
    # hole 3, seen once, is below --min-sightings (2): not for the crew
    assert [f["properties"]["hole_id"] for f in feats] == [1, 2]
    assert [f["properties"]["tier"] for f in feats] == ["announced", "announced"]


def test_a_log_cut_off_by_a_crash_still_exports(
    tmp_path: Path, main: Main, capsys: pytest.CaptureFixture[str]
) -> None:
    (path,) = write_flight(tmp_path / "crash", LogOptions(chunk_size=16 * 1024))
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 9 // 10])  # the last frames and the summary are lost
    out = tmp_path / "cut.kml"
    assert main(["holes", str(cut), "--format", "kml", "--out", str(out)]) == 0
    assert "cut off, read up to their last chunk" in capsys.readouterr().out
    got = read_flight_holes(cut)
    assert got.frames_read < N_FRAMES
    assert len(got.truncated) == 1
    assert "recover" in got.truncated[0]
    assert got.holes == tuple(final_holes()[k] for k in (1, 2, 3))
    pms = ET.parse(out).getroot().findall(".//k:Placemark", KML)
    assert [pm.findtext("k:name", "", KML) for pm in pms] == ["hole 1", "hole 2"]  # 3: seen once


def test_a_best_view_missing_from_the_log_only_loses_its_picture(
    tmp_path: Path, main: Main, caplog: pytest.LogCaptureFixture
) -> None:
    (path,) = write_flight(tmp_path / "lossy", lost_frames=frozenset({8}))  # hole 1's best
    got = read_flight_holes(path)
    assert sorted(got.thumbnails) == [2, 3]
    assert "hole 1: its best view (frame 8) is not in the log" in caplog.text
    out = tmp_path / "lossy.kml"
    assert main(["holes", str(path), "-f", "kml", "-o", str(out)]) == 0
    descs = [
        pm.findtext("k:description", "", KML)
        for pm in ET.parse(out).getroot().findall(".//k:Placemark", KML)
    ]
    assert "<img" not in descs[0]  # hole 1
    assert "data:image/jpeg;base64," in descs[1]  # hole 2


@pytest.mark.parametrize(
    ("content", "extra", "message"),
    [
        (None, [], "no such file"),
        (b"not an mcap file at all" * 100, [], "not an MCAP file"),
        (b"", [], "empty file"),
        ("no-holes", [], "no /holes record"),
        ("flight", ["--min-sightings", "9"], r"none of the 3 holes was seen in >= 9 frames"),
        ("flight", ["--out", "/nonexistent-dir/x.gpx"], "cannot write /nonexistent-dir/x.gpx"),
    ],
)
def test_errors_exit_2_with_one_line(
    flight: Path,
    tmp_path: Path,
    main: Main,
    capsys: pytest.CaptureFixture[str],
    content: bytes | str | None,
    extra: list[str],
    message: str,
) -> None:
    path = tmp_path / "bad.mcap"
    if content == "flight":
        path = flight
    elif content == "no-holes":
        with FlightLogWriter(tmp_path / "quiet", CAM) as w:
            w.write_frame(make_frame(0), T0_UNIX_NS)
        (path,) = w.paths
    elif isinstance(content, bytes):
        path.write_bytes(content)
    assert main(["holes", str(path), *extra]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("holescan holes:")]
    assert len(lines) == 1
    assert re.search(message, lines[0])
