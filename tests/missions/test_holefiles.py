"""Hole files: every format written from Hole records and parsed back by the format's own
reader (gpxpy, ElementTree, zipfile, json, pymavlink's MAVWPLoader) and by ours."""

from __future__ import annotations

import base64
import json
import math
import os
import re
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import cv2
import gpxpy
import numpy as np
import pytest

from holescan.errors import InputError
from holescan.geotag import Hole
from holescan.missions import (
    HOLE_FORMATS,
    MAV_FRAME_GLOBAL,
    hole_mission,
    hole_points,
    rank_holes,
    read_geojson,
    read_gpx,
    read_kml,
    read_plan,
    read_wpl,
    write_hole_file,
)

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavwp

KML = {"k": "http://www.opengis.net/kml/2.2"}
T_BOOT0 = 120_000_000_000
BOOT_TO_UNIX = 1_750_000_000_000_000_000  # 2025-06-15T15:06:40Z at boot time 0
HOME = (43.71230001, 10.40120002, 20.25)


def make_hole(hid: int, score: float, sightings: int, dlat: float, dlon: float) -> Hole:
    return Hole(
        id=hid,
        lat_deg=43.71234567 + dlat,
        lon_deg=10.40123456 + dlon,
        alt_m=21.5 + hid,
        sigma_h_m=0.75 + 0.01 * hid,
        score=score,
        sightings=sightings,
        t_first_boot_ns=T_BOOT0 + hid * 1_000_000_000,
        t_last_boot_ns=T_BOOT0 + hid * 1_000_000_000 + 4_500_000_000,
        best_frame_index=100 + hid,
        best_box=(10 * hid, 20, 30, 24),
        major_m=0.6 + 0.1 * hid,
        minor_m=0.4,
    )


# Ranked by score, then sightings, then id: 3, 1, 2 (more sightings than 4), 4.
HOLES = (
    make_hole(1, 0.8123, 5, 0.0, 0.0),
    make_hole(2, 0.61, 9, 1.23e-5, -4.56e-5),
    make_hole(3, 0.9, 2, -2.00000004e-5, 7.77e-6),
    make_hole(4, 0.61, 2, 3.1e-6, 3.1e-6),
)
RANKED_IDS = [3, 1, 2, 4]


def jpeg(colour: tuple[int, int, int]) -> bytes:
    pic = np.zeros((40, 60, 3), np.uint8)
    pic[:] = colour
    ok, buf = cv2.imencode(".jpg", pic)
    assert ok
    return buf.tobytes()


THUMBS = {1: jpeg((0, 0, 255)), 3: jpeg((0, 255, 0))}  # BGR: hole 1 red, hole 3 green


def by_id() -> dict[int, Hole]:
    return {h.id: h for h in HOLES}


def test_rank_matches_the_live_mission_order() -> None:
    assert [h.id for h in rank_holes(HOLES)] == RANKED_IDS
    _, items = hole_mission(HOLES)
    assert [w.properties["hole_id"] for w in items] == RANKED_IDS
    assert [w.properties["rank"] for w in items] == [1, 2, 3, 4]


def test_points_carry_data_and_utc_times() -> None:
    pts = hole_points(HOLES, boot_to_unix_ns=BOOT_TO_UNIX)
    first = pts[0]
    assert first.name == "hole 3"
    assert first.frame == MAV_FRAME_GLOBAL
    assert first.alt_m == 24.5
    p = first.properties
    assert p["score"] == 0.9
    assert p["sightings"] == 2
    assert p["best_box"] == [30, 20, 30, 24]
    assert p["first_seen_utc"] == "2025-06-15T15:08:43.000Z"  # boot 123 s
    assert p["last_seen_utc"] == "2025-06-15T15:08:47.500Z"
    assert "first seen 2025-06-15T15:08:43.000Z" in first.description
    assert first.description.isascii()
    # Without a clock offset the times stay on the boot clock, and are said to be.
    plain = hole_points(HOLES)[0]
    assert "first_seen_utc" not in plain.properties
    assert "seen over 4.5 s" in plain.description


def test_gpx_parses_with_gpxpy(tmp_path: Path) -> None:
    path = write_hole_file(tmp_path / "h.gpx", HOLES, "gpx", boot_to_unix_ns=BOOT_TO_UNIX)
    gpx = gpxpy.parse(path.read_text(encoding="utf-8"))
    assert [p.name for p in gpx.waypoints] == [f"hole {i}" for i in RANKED_IDS]
    holes = by_id()
    for wpt, hid in zip(gpx.waypoints, RANKED_IDS, strict=True):
        h = holes[hid]
        assert wpt.latitude == pytest.approx(h.lat_deg, abs=1e-7)
        assert wpt.longitude == pytest.approx(h.lon_deg, abs=1e-7)
        assert wpt.elevation == pytest.approx(h.alt_m)  # MSL, what GPX elevation means
        assert f"hole {hid} (announced, rank" in wpt.description
        assert f"score {h.score:.2f}" in wpt.description
        assert f"seen in {h.sightings} frames" in wpt.description
    # At least 7 decimals in the file itself.
    assert re.search(r'lat="43\.7123256\d+"', path.read_text())
    assert [w.name for w in read_gpx(path)] == [f"hole {i}" for i in RANKED_IDS]


def _placemarks(root: ET.Element) -> list[ET.Element]:
    return root.findall(".//k:Placemark", KML)


def _data(pm: ET.Element) -> dict[str, object]:
    return {
        d.get("name", ""): json.loads(d.findtext("k:value", "", KML))
        for d in pm.iterfind("k:ExtendedData/k:Data", KML)
    }


def test_kml_embeds_thumbnails_as_data_uris(tmp_path: Path) -> None:
    path = write_hole_file(tmp_path / "h.kml", HOLES, "kml", thumbnails=THUMBS)
    root = ET.parse(path).getroot()
    pms = _placemarks(root)
    holes = by_id()
    assert [pm.findtext("k:name", "", KML) for pm in pms] == [f"hole {i}" for i in RANKED_IDS]
    for pm, hid in zip(pms, RANKED_IDS, strict=True):
        h = holes[hid]
        data = _data(pm)
        assert data["hole_id"] == hid
        assert data["score"] == round(h.score, 4)
        assert data["alt_msl_m"] == h.alt_m
        lon, lat, alt = (float(v) for v in pm.findtext(".//k:coordinates", "", KML).split(","))
        assert (lat, lon) == (
            pytest.approx(h.lat_deg, abs=1e-7),
            pytest.approx(h.lon_deg, abs=1e-7),
        )
        assert alt == 0.0  # on the ground
        assert pm.findtext(".//k:altitudeMode", "", KML) == "relativeToGround"
        desc = pm.findtext("k:description", "", KML)
        match = re.search(r'<img src="data:image/jpeg;base64,([^"]+)"', desc)
        if hid in THUMBS:
            assert match is not None
            assert base64.b64decode(match.group(1)) == THUMBS[hid]
            pic = cv2.imdecode(np.frombuffer(base64.b64decode(match.group(1)), np.uint8), 1)
            assert pic.shape == (40, 60, 3)
        else:
            assert match is None
        assert f"<b>hole {hid}</b>" in desc
    back = read_kml(path)
    assert [w.properties["hole_id"] for w in back] == RANKED_IDS


def test_kmz_holds_doc_kml_and_images(tmp_path: Path) -> None:
    path = write_hole_file(tmp_path / "h.kmz", HOLES, "kmz", thumbnails=THUMBS, name="flight 7")
    with zipfile.ZipFile(path) as kmz:
        names = kmz.namelist()
        assert names[0] == "doc.kml"
        assert sorted(names[1:]) == ["images/hole_1.jpg", "images/hole_3.jpg"]
        assert kmz.read("images/hole_3.jpg") == THUMBS[3]
        root = ET.fromstring(kmz.read("doc.kml"))
    assert root.findtext(".//k:Document/k:name", "", KML) == "flight 7"
    pms = _placemarks(root)
    descs = {_data(pm)["hole_id"]: pm.findtext("k:description", "", KML) for pm in pms}
    assert '<img src="images/hole_1.jpg"' in descs[1]
    assert '<img src="images/hole_3.jpg"' in descs[3]
    assert "<img" not in descs[2]


def test_geojson_points_are_two_dimensional(tmp_path: Path) -> None:
    path = write_hole_file(tmp_path / "h.geojson", HOLES, "geojson")
    doc = json.loads(path.read_text())
    feats = doc["features"]
    assert [f["properties"]["hole_id"] for f in feats] == RANKED_IDS
    holes = by_id()
    for f in feats:
        h = holes[f["properties"]["hole_id"]]
        lon, lat = f["geometry"]["coordinates"]  # no ellipsoidal height claimed
        assert lat == pytest.approx(h.lat_deg, abs=1e-7)
        assert lon == pytest.approx(h.lon_deg, abs=1e-7)
        assert f["properties"]["alt_msl_m"] == h.alt_m
        assert f["properties"]["sigma_h_m"] == round(h.sigma_h_m, 3)
    back = read_geojson(path)
    assert back[0].alt_m == holes[3].alt_m
    assert back[0].properties["major_m"] == pytest.approx(0.9)


def test_plan_items_carry_hole_data(tmp_path: Path) -> None:
    path = write_hole_file(
        tmp_path / "h.plan", HOLES, "plan", home=HOME, rel_alt_m=3.0, clearance_m=2.0
    )
    doc = json.loads(path.read_text())
    mission = doc["mission"]
    assert mission["plannedHomePosition"] == [43.71230001, 10.40120002, 20.25]
    holes = by_id()
    for n, item in enumerate(mission["items"], start=1):
        data = item["holescan"]
        h = holes[data["properties"]["hole_id"]]
        assert data["properties"]["rank"] == n
        assert data["name"] == f"hole {h.id}"
        assert item["command"] == 16
        assert item["frame"] == 3
        assert item["params"][4] == pytest.approx(h.lat_deg, abs=1e-7)
        assert item["params"][5] == pytest.approx(h.lon_deg, abs=1e-7)
        # 3 m above home, raised to 2 m above the hole (holes are 2.25..5.25 m above home).
        assert item["params"][6] == pytest.approx(max(3.0, h.alt_m - HOME[2] + 2.0))
    _home, items = read_plan(path)
    assert [w.properties["hole_id"] for w in items] == RANKED_IDS
    assert items[0].description.startswith("hole 3 (announced, rank 1)")


def test_wpl_loads_in_pymavlink(tmp_path: Path) -> None:
    path = write_hole_file(tmp_path / "h.waypoints", HOLES, "wpl", home=HOME)
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(path)) == 5
    home = loader.wp(0)
    assert (home.x, home.y, home.z, home.frame) == (
        pytest.approx(HOME[0], abs=1e-7),
        pytest.approx(HOME[1], abs=1e-7),
        pytest.approx(HOME[2]),
        0,
    )
    holes = by_id()
    for seq, hid in enumerate(RANKED_IDS, start=1):
        w = loader.wp(seq)
        h = holes[hid]
        assert (w.command, w.frame) == (16, 3)
        assert w.x == pytest.approx(h.lat_deg, abs=1e-7)
        assert w.y == pytest.approx(h.lon_deg, abs=1e-7)
        assert w.z == pytest.approx(max(10.0, h.alt_m - HOME[2] + 5.0))
    # Without a known home, line 0 is the best hole at altitude 0 (as the generic writer does).
    path2 = write_hole_file(tmp_path / "h2.waypoints", HOLES, "wpl")
    home2, items2 = read_wpl(path2)
    assert home2.lat_deg == pytest.approx(holes[3].lat_deg, abs=1e-8)
    assert [w.alt_m for w in items2] == [10.0] * 4


def test_every_format_refuses_nothing_and_unknown(tmp_path: Path) -> None:
    for fmt in HOLE_FORMATS:
        with pytest.raises(InputError, match="no holes"):
            write_hole_file(tmp_path / f"x.{fmt}", [], fmt)
    with pytest.raises(InputError, match="unknown hole file format"):
        write_hole_file(tmp_path / "x.csv", HOLES, "csv")  # type: ignore[arg-type]
    dup = (*HOLES, HOLES[0])
    with pytest.raises(InputError, match="unique"):
        hole_mission(dup)


def test_nan_sizes_stay_valid_json(tmp_path: Path) -> None:
    odd = Hole(9, 1.0, 2.0, 3.0, 0.5, 0.7, 3, 0, 0, None, (0, 0, 1, 1), math.nan, math.nan)
    path = write_hole_file(tmp_path / "n.geojson", [odd], "geojson")
    props = json.loads(path.read_text())["features"][0]["properties"]
    assert props["major_m"] is None
    assert props["best_frame_index"] is None
