"""``holescan reprocess``: a real short flight (flight daemon, simulated autopilot over loopback
UDP, simulated Xtion over a small rubble world, log rotated every 3 s) reprocessed in parallel
and in process; the copies are checked byte for byte against the originals and read back
with mcap's indexed reader; logs cut off mid-write, stops, bad inputs, the CLI."""

from __future__ import annotations

import itertools
import json
import math
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import gpxpy
import pymap3d
import pytest
from mcap.reader import make_reader

from capture import Flight, FlightConfig, FlightSummary, LogOptions, log_info
from capture._mcapread import scan_records
from detect import CameraIntrinsics
from geotag import Hole
from ground._reprocess import (
    Progress,
    ReprocessOptions,
    group_flights,
    match_points,
    reprocess,
)
from holescan import cli
from holescan_errors import InputError
from sim import SimAutopilot, SimPath
from sim._source import SimSource, WorldAnchor
from sim._world import make_world

CAM = CameraIntrinsics.xtion()
ANCHOR = WorldAnchor(43.6532, -79.3832, 120.0)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], FlightSummary]:
    """A 40-frame flight at 6 frames/s over two access holes, logged in rotated files of 3 s."""
    world = make_world(
        11,
        (8.0, 6.0),
        n_access_holes=2,
        n_small_holes=2,
        n_cracks=1,
        n_depressions=1,
        n_stains=1,
        n_shadows=1,
    )
    xs = [h.centre_xy[0] for h in world.access_holes]
    ys = [h.centre_xy[1] for h in world.access_holes]
    x0, x1 = max(min(xs) - 0.6, 1.8), min(max(xs) + 0.6, 6.2)
    y0, y1 = max(min(ys) - 0.4, 1.5), min(max(ys) + 0.4, 4.5)
    path = SimPath(
        home_lat_deg=ANCHOR.lat_deg,
        home_lon_deg=ANCHOR.lon_deg,
        home_alt_m=ANCHOR.alt_m,
        waypoints_enu=((x0, y0, 2.8), (x1, y0, 2.8), (x1, y1, 2.8), (x0, y1, 2.8)),
        speed_m_s=0.8,
    )
    out = tmp_path_factory.mktemp("flight")
    port = free_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", path) as ap:

        def source() -> SimSource:
            truth = lambda t: ap.truth_pose(ap.boot_ns_at_mono(t))  # noqa: E731
            return SimSource(world, ANCHOR, truth, CAM, fps=6.0)

        cfg = FlightConfig(
            log_prefix=out / "sortie",
            max_frames=40,
            log_options=LogOptions(max_file_s=3.0),
            pose_wait_s=1.0,  # a loaded test machine can delay telemetry; the flight waits
        )
        summary = Flight(cfg, source, CAM, mavlink=f"udpin:127.0.0.1:{port}").run()
    files = list(summary.log.files)
    assert len(files) >= 2 and summary.frames_logged == 40
    assert any(h.sightings >= 3 for h in summary.holes), summary.holes
    return files, summary


def messages(path: Path) -> dict[str, list[tuple[int, int, bytes]]]:
    """topic -> [(log_time, sequence, data)] in file order, read front to back."""
    channels: dict[int, str] = {}
    out: dict[str, list[tuple[int, int, bytes]]] = defaultdict(list)
    for rec in scan_records(path):
        if type(rec).__name__ == "Channel":
            channels[rec.id] = rec.topic
        elif type(rec).__name__ == "Message":
            out[channels[rec.channel_id]].append((rec.log_time, rec.sequence, bytes(rec.data)))
    return out


def new_records(paths: tuple[Path, ...]) -> dict[str, list[tuple[int, int, bytes]]]:
    out: dict[str, list[tuple[int, int, bytes]]] = defaultdict(list)
    for p in paths:
        for topic, msgs in messages(p).items():
            if topic.startswith("/reprocess/"):
                out[topic] += msgs
    return dict(out)


def same_holes(a: tuple[Hole, ...], b: tuple[Hole, ...], tol_m: float) -> None:
    assert [h.id for h in a] == [h.id for h in b]
    for x, y in zip(a, b, strict=True):
        e, n, _ = pymap3d.geodetic2enu(x.lat_deg, x.lon_deg, 0, y.lat_deg, y.lon_deg, 0)
        assert math.hypot(e, n) < tol_m, (x, y)
        assert x.sightings == y.sightings and x.best_frame_index == y.best_frame_index


def test_flight_frames_reproduce_the_flights_holes(
    flight: tuple[list[Path], FlightSummary], tmp_path: Path
) -> None:
    files, summary = flight
    res = reprocess(files, tmp_path, ReprocessOptions(workers=0, frames="flight"))
    (f,) = res.flights
    c = summary.counters
    assert f.frames_read == summary.frames_logged
    assert f.frames_detected == c.frames_detected - c.detect_errors
    assert f.flight_holes == summary.holes  # the log's own final list, read back
    assert f.flight_matches and all(
        m.found is not None and m.distance_m < 0.05 for m in f.flight_matches
    ), f.flight_matches
    assert f.flight_same_ids <= len(f.flight_matches)
    if c.pose_refusals == 0 and c.frames_unposed < c.frames_captured:
        # Same detections, in the same order, posed from the same telemetry: the same holes
        # (unless the flight had to give up on a pose, which reprocessing then finds).
        same_holes(f.holes, summary.holes, tol_m=0.01)
        assert f.flight_same_ids == len(f.flight_matches)


def test_all_frames_in_parallel_and_in_process_agree(
    flight: tuple[list[Path], FlightSummary], tmp_path: Path
) -> None:
    files, summary = flight
    seen: list[Progress] = []
    par = reprocess(files, tmp_path / "par", ReprocessOptions(workers=2), progress=seen.append)
    one = reprocess(files, tmp_path / "one", ReprocessOptions(workers=0))
    (a,), (b,) = par.flights, one.flights
    assert a.frames_detected == a.frames_read == summary.frames_logged
    assert a.holes == b.holes  # merged in frame order whatever the workers' timing
    # The same new records in the same order (a record may land in the next file of the
    # flight when its frame was merged after the reader had moved on).
    assert new_records(a.outputs) == new_records(b.outputs)
    # Every confirmed in-flight hole is found again, in the same place.
    confirmed = [h for h in summary.holes if h.sightings >= 2]
    assert len(a.flight_matches) == len(confirmed) >= 1
    for m in a.flight_matches:
        assert m.found is not None and m.distance_m < 0.3, m
    assert seen and seen[-1].bytes_read == seen[-1].bytes_total
    assert seen[-1].frames_done == a.frames_detected
    assert all(p.frames_done <= q.frames_done for p, q in itertools.pairwise(seen))


def test_copies_hold_every_original_record_and_read_back_indexed(
    flight: tuple[list[Path], FlightSummary], tmp_path: Path
) -> None:
    files, summary = flight
    (f,) = reprocess(files, tmp_path, ReprocessOptions(workers=0)).flights
    assert [p.name for p in f.outputs] == [p.name for p in files]
    detected: list[int] = []
    for src, out in zip(files, f.outputs, strict=True):
        old, new = messages(src), messages(out)
        for topic, msgs in old.items():
            assert new[topic] == msgs, topic  # byte for byte, same order
        added = set(new) - set(old)
        assert added <= {
            f"/reprocess/{t}"
            for t in ("detections", "detections/annotations", "holes", "holes/geojson")
        }
        records = new.get("/reprocess/detections", [])
        detected += [json.loads(d)["frame_index"] for _, _, d in records]
        info = log_info(out)  # every CRC, summary counts against the content
        assert not info.truncated and info.metadata["ground._reprocess"]["frames"] == "all"
        with open(out, "rb") as fh:  # mcap's indexed reader: summary, chunk indexes
            reader = make_reader(fh)
            counts: dict[str, int] = defaultdict(int)
            for _, channel, _ in reader.iter_messages():
                counts[channel.topic] += 1
            stats = reader.get_summary().statistics
            assert sum(counts.values()) == stats.message_count
            assert counts == {t: len(v) for t, v in new.items()}
        assert src.read_bytes()[:8] == out.read_bytes()[:8]
    assert detected == sorted(detected) and len(detected) == summary.frames_logged
    last = json.loads(messages(f.outputs[-1])["/reprocess/holes"][-1][2])["holes"]
    assert [h["id"] for h in last] == [h.id for h in f.holes]


def test_hole_files_report_and_summary(
    flight: tuple[list[Path], FlightSummary], tmp_path: Path
) -> None:
    files, _ = flight
    (f,) = reprocess(files, tmp_path, ReprocessOptions(workers=0)).flights
    kinds = dict(f.files)
    assert set(kinds) == {"gpx", "kml", "geojson", "plan", "report", "summary"}
    gpx = gpxpy.parse(kinds["gpx"].read_text())
    assert sorted(w.name for w in gpx.waypoints) == sorted(f"hole {h.id}" for h in f.confirmed)
    geo = json.loads(kinds["geojson"].read_text())
    assert len(geo["features"]) == len(f.confirmed)
    kml = kinds["kml"].read_text()
    assert kml.count("data:image/jpeg;base64,") == len(f.confirmed)  # thumbnails of best views
    page = kinds["report"].read_text()
    assert page.count("data:image/png;base64,") == 2 * len(f.confirmed)
    summary = json.loads(kinds["summary"].read_text())
    assert summary["frames_detected"] == f.frames_detected
    assert summary["confirmed"] == len(f.confirmed)
    assert json.loads((tmp_path / "summary.json").read_text())["flights"][0] == summary


def test_log_cut_off_mid_write(flight: tuple[list[Path], FlightSummary], tmp_path: Path) -> None:
    files, summary = flight
    cut = tmp_path / "crash.mcap"
    data = max(files, key=lambda p: p.stat().st_size).read_bytes()  # the part with most frames
    cut.write_bytes(data[: int(len(data) * 0.6)])
    (f,) = reprocess([cut], tmp_path / "out", ReprocessOptions(workers=0)).flights
    assert f.truncated and "crash.mcap" in f.truncated[0]
    assert 0 < f.frames_read < summary.frames_logged
    assert f.frames_detected == f.frames_read and f.holes
    info = log_info(f.outputs[0])  # the copy is a complete, valid file
    assert info.frames == f.frames_read and not info.truncated
    assert info.topics["/reprocess/detections"].count == f.frames_detected


def test_stop_keeps_what_is_done(flight: tuple[list[Path], FlightSummary], tmp_path: Path) -> None:
    files, summary = flight
    stop = threading.Event()

    def progress(p: Progress) -> None:
        if p.frames_done >= 10:
            stop.set()

    (f,) = reprocess(
        files, tmp_path, ReprocessOptions(workers=0), progress=progress, stop=stop
    ).flights
    assert f.interrupted and 10 <= f.frames_detected < summary.frames_logged
    assert f.outputs and all(not log_info(p).truncated for p in f.outputs)
    assert json.loads((tmp_path / "summary.json").read_text())["flights"][0]["interrupted"]


def test_several_flights_one_summary(
    flight: tuple[list[Path], FlightSummary], tmp_path: Path
) -> None:
    files, _ = flight
    other = tmp_path / "logs" / "second.mcap"
    other.parent.mkdir()
    shutil.copy(files[0], other)
    groups = group_flights([*files, other])
    assert groups == [tuple(files), (other,)]
    res = reprocess([*files, other], tmp_path / "out", ReprocessOptions(workers=0))
    assert [r.name for r in res.flights] == ["sortie", "second"]
    assert (tmp_path / "out" / "second" / "second.mcap").is_file()
    assert (tmp_path / "out" / "sortie" / files[0].name).is_file()
    doc = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert [d["flight"] for d in doc["flights"]] == ["sortie", "second"]


def test_bad_inputs(flight: tuple[list[Path], FlightSummary], tmp_path: Path) -> None:
    files, _ = flight
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all" * 10)
    with pytest.raises(InputError, match="not an MCAP"):
        reprocess([junk], tmp_path / "o1", ReprocessOptions(workers=0))
    with pytest.raises(InputError, match="no such file"):
        reprocess([tmp_path / "missing.mcap"], tmp_path / "o2", ReprocessOptions(workers=0))
    with pytest.raises(InputError, match="is the source log"):
        reprocess([files[0]], files[0].parent, ReprocessOptions(workers=0))
    (f,) = reprocess([files[0]], tmp_path / "o3", ReprocessOptions(workers=0)).flights
    with pytest.raises(InputError, match="reprocess the original flight log"):
        reprocess([f.outputs[0]], tmp_path / "o4", ReprocessOptions(workers=0))
    with pytest.raises(InputError):
        ReprocessOptions(workers=-1)


def test_cli(
    flight: tuple[list[Path], FlightSummary], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files, _ = flight
    out = tmp_path / "cli"
    rc = cli.main(
        [
            "reprocess",
            str(files[0]),
            "--out",
            str(out),
            "--workers",
            "0",
            "--searcher",
            "dog",
            "-f",
            "gpx",
        ]
    )
    text = capsys.readouterr()
    assert rc == 0, text.err
    assert "frames/s" in text.out and "summary:" in text.out
    doc = json.loads((out / "summary.json").read_text())["flights"][0]
    assert set(doc["files"]) == {"report", "summary"} | ({"gpx"} if doc["confirmed"] else set())
    meta = log_info(out / files[0].name).metadata["ground._reprocess"]
    assert json.loads(meta["params"])["searcher"]["name"] == "dog"
    rc = cli.main(["reprocess", str(tmp_path / "nope.mcap"), "--out", str(out)])
    assert rc == 2 and "no such file" in capsys.readouterr().err


def test_match_points() -> None:
    lat0, lon0 = 43.0, -79.0

    def at(e: float, n: float) -> tuple[float, float]:
        lat, lon, _ = pymap3d.enu2geodetic(e, n, 0.0, lat0, lon0, 0.0)
        return float(lat), float(lon)

    ref = [at(0, 0), at(5, 0), at(20, 0)]
    found = [at(5.2, 0), at(0.1, 0), at(0.3, 0)]
    m = match_points(ref, found, 1.0)
    assert [x.found for x in m] == [1, 0, None]
    assert m[0].distance_m == pytest.approx(0.1, abs=1e-6)
    assert m[1].distance_m == pytest.approx(0.2, abs=1e-6)
    assert math.isnan(m[2].distance_m)
    assert match_points([], found, 1.0) == []


def test_ctrl_c_stops_cleanly_and_keeps_what_is_done(
    flight: tuple[list[Path], FlightSummary], tmp_path: Path
) -> None:
    files, summary = flight
    out = tmp_path / "out"
    argv = [
        sys.executable,
        "-m",
        "holescan.cli",
        "reprocess",
        *map(str, files),
        "--out",
        str(out),
        "--mode",
        "paper",
        "--workers",
        "1",
    ]  # paper mode: slow frames
    proc = subprocess.Popen(
        argv,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert proc.stderr is not None
    first = proc.stderr.readline()  # the first progress line: reading has started
    assert "frames/s" in first, first
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr[-2000:]
    assert "INTERRUPTED" in stdout and "Traceback" not in stderr
    doc = json.loads((out / "summary.json").read_text())["flights"][0]
    assert doc["interrupted"] and 0 < doc["frames_detected"] < summary.frames_logged
    copies = [Path(p) for p in doc["outputs"]]
    assert copies and all(not log_info(p).truncated for p in copies)
    n = sum(
        log_info(p).topics["/reprocess/detections"].count
        for p in copies
        if "/reprocess/detections" in log_info(p).topics
    )
    assert n == doc["frames_detected"]
