"""Waypoint files: every writer read back, by our readers and by the formats' own parsers."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import gpxpy
import pytest

from holescan.errors import InputError
from holescan.missions import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_RETURN_TO_LAUNCH,
    MAV_CMD_NAV_TAKEOFF,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_MISSION,
    Area,
    Waypoint,
    read_area,
    read_geojson,
    read_gpx,
    read_kml,
    read_plan,
    read_waypoints,
    read_wpl,
    write_geojson,
    write_gpx,
    write_kml,
    write_plan,
    write_waypoints,
    write_wpl,
)

HOME = Waypoint(43.71234567, 10.40123456, 12.5, name="home", frame=MAV_FRAME_GLOBAL)


def _mission() -> list[Waypoint]:
    return [
        Waypoint(43.71234567, 10.40123456, 2.5, name="takeoff", command=MAV_CMD_NAV_TAKEOFF,
                 params=(0.0, 0.0, 0.0, float("nan"))),
        Waypoint(0.0, 0.0, 0.0, name="speed", command=MAV_CMD_DO_CHANGE_SPEED,
                 frame=MAV_FRAME_MISSION, params=(1.0, 0.65, -1.0, 0.0)),
        Waypoint(43.712345678, 10.401234567, 2.5, name="L01 start", params=(0, 0, 0, 70.0)),
        Waypoint(43.712987654, 10.402876543, 2.5, name="L01 end", params=(0, 0, 0, 70.0)),
        Waypoint(-0.000000123, -179.999999876, 3.0, name="L02 start", params=(0, 0, 0, 250.0)),
        Waypoint(0.0, 0.0, 0.0, name="rtl", command=MAV_CMD_NAV_RETURN_TO_LAUNCH,
                 frame=MAV_FRAME_MISSION),
    ]  # fmt: skip


def _holes() -> list[Waypoint]:
    return [
        Waypoint(43.7120001, 10.4010002, 0.0, name="hole 1", description="score 0.81 <dark>",
                 properties={"score": 0.81, "major_m": 0.9, "minor_m": 0.5, "frames": [3, 4]}),
        Waypoint(43.7120101, 10.4010302, 0.0, name="hole 2 & co", description="",
                 properties={"score": 0.42, "beyond_range": True}),
    ]  # fmt: skip


def _same_params(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return all(
        (math.isnan(x) and math.isnan(y)) or x == pytest.approx(y)
        for x, y in zip(a, b, strict=False)
    )


def _assert_same_mission(got: list[Waypoint], want: list[Waypoint], tol_deg: float) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert (g.command, g.frame, g.autocontinue) == (w.command, w.frame, w.autocontinue)
        assert _same_params(g.params, w.params)
        if w.has_position:
            assert g.lat_deg == pytest.approx(w.lat_deg, abs=tol_deg)
            assert g.lon_deg == pytest.approx(w.lon_deg, abs=tol_deg)
            assert g.alt_m == pytest.approx(w.alt_m, abs=1e-6)


def test_wpl_layout_and_round_trip(tmp_path: Path) -> None:
    path = write_wpl(tmp_path / "m.waypoints", _mission(), HOME)
    lines = path.read_text().splitlines()
    assert lines[0] == "QGC WPL 110"
    rows = [ln.split("\t") for ln in lines[1:]]
    assert all(len(r) == 12 for r in rows)
    assert [int(r[0]) for r in rows] == list(range(7))
    # Line 0 is home: CURRENT 1, frame 0 (AMSL), NAV_WAYPOINT.
    assert rows[0][1:4] == ["1", "0", "16"]
    assert float(rows[0][10]) == pytest.approx(12.5)
    # Survey waypoints: frame 3 (relative altitude), command 16, >= 7 decimals.
    assert rows[3][1:4] == ["0", "3", "16"]
    assert len(rows[3][8].split(".")[1]) >= 7
    assert len(rows[3][9].split(".")[1]) >= 7
    assert rows[2][3] == "178"
    assert float(rows[2][5]) == pytest.approx(0.65)
    home, items = read_wpl(path)
    assert (home.lat_deg, home.lon_deg, home.alt_m) == pytest.approx(
        (43.71234567, 10.40123456, 12.5)
    )
    _assert_same_mission(items, _mission(), tol_deg=1e-8)


def test_plan_is_qgc_json_and_round_trips(tmp_path: Path) -> None:
    fence = ((43.71, 10.40), (43.72, 10.40), (43.72, 10.41))
    path = write_plan(tmp_path / "m.plan", _mission(), HOME, fence=fence)
    doc = json.loads(path.read_text())
    assert doc["fileType"] == "Plan"
    assert doc["version"] == 1
    mission = doc["mission"]
    assert mission["version"] == 2
    assert mission["plannedHomePosition"] == pytest.approx([43.71234567, 10.40123456, 12.5])
    items = mission["items"]
    assert [i["doJumpId"] for i in items] == list(range(1, 7))
    assert all(i["type"] == "SimpleItem" and len(i["params"]) == 7 for i in items)
    wp = items[2]
    assert wp["command"] == 16
    assert wp["frame"] == 3
    assert wp["AltitudeMode"] == 1
    assert wp["Altitude"] == 2.5
    assert wp["AMSLAltAboveTerrain"] is None
    assert wp["params"][4:] == [43.71234568, 10.40123457, 2.5]
    assert items[0]["params"][3] is None  # NaN yaw is JSON null, as QGC writes it
    assert "Altitude" not in items[1]  # DO_CHANGE_SPEED has no position
    assert doc["geoFence"]["polygons"][0]["polygon"][1] == [43.72, 10.40]
    home, back = read_plan(path)
    assert home.alt_m == 12.5
    _assert_same_mission(back, _mission(), tol_deg=1e-8)


def test_plan_reader_refuses_complex_items(tmp_path: Path) -> None:
    path = write_plan(tmp_path / "m.plan", _mission(), HOME)
    doc = json.loads(path.read_text())
    doc["mission"]["items"].append({"type": "ComplexItem", "complexItemType": "survey"})
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="ComplexItem"):
        read_plan(path)


def test_geojson_points_carry_properties(tmp_path: Path) -> None:
    path = write_geojson(tmp_path / "holes.geojson", _holes(), path_name=None)
    doc = json.loads(path.read_text())
    assert doc["type"] == "FeatureCollection"
    first = doc["features"][0]
    assert first["geometry"]["coordinates"][:2] == [10.4010002, 43.7120001]  # lon, lat
    assert first["properties"]["score"] == 0.81
    assert first["properties"]["frames"] == [3, 4]
    back = read_geojson(path)
    assert [w.name for w in back] == ["hole 1", "hole 2 & co"]
    assert back[0].properties == {"score": 0.81, "major_m": 0.9, "minor_m": 0.5, "frames": [3, 4]}
    assert back[1].properties["beyond_range"] is True
    assert back[0].description == "score 0.81 <dark>"


def test_geojson_path_line_skips_items_without_position(tmp_path: Path) -> None:
    path = write_geojson(tmp_path / "m.geojson", _mission(), path_name="survey")
    doc = json.loads(path.read_text())
    line = doc["features"][0]
    assert line["geometry"]["type"] == "LineString"
    assert len(line["geometry"]["coordinates"]) == 4  # takeoff + 3 waypoints
    assert len(read_geojson(path)) == 4


def test_kml_is_valid_xml_and_round_trips(tmp_path: Path) -> None:
    area = Area(((43.71, 10.40), (43.72, 10.40), (43.72, 10.41)))
    path = write_kml(tmp_path / "h.kml", _holes(), path_name="holes", area=area)
    root = ET.parse(path).getroot()
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    names = [e.text for e in root.iterfind(".//k:Placemark/k:name", ns)]
    assert names == ["area", "holes", "hole 1", "hole 2 & co"]
    coords = root.find(".//k:Point/k:coordinates", ns)
    assert coords is not None
    assert coords.text is not None
    assert coords.text.startswith("10.40100020,43.71200010")
    back = read_kml(path)
    assert [w.name for w in back] == ["hole 1", "hole 2 & co"]
    assert back[0].properties["major_m"] == 0.9
    assert back[0].description == "score 0.81 <dark>"
    assert back[1].lat_deg == pytest.approx(43.7120101, abs=1e-9)
    # The area polygon in the same file reads back as the area.
    assert read_area(path) == area


def test_gpx_waypoints_and_route(tmp_path: Path) -> None:
    holes = [*_holes(), Waypoint(43.7, 10.4, 35.0, name="cp", frame=MAV_FRAME_GLOBAL)]
    path = write_gpx(tmp_path / "h.gpx", holes, route_name="walk")
    gpx = gpxpy.parse(path.read_text())
    assert [p.name for p in gpx.waypoints] == ["hole 1", "hole 2 & co", "cp"]
    assert gpx.waypoints[0].elevation is None  # relative altitude is not an elevation
    assert gpx.waypoints[2].elevation == 35.0
    assert len(gpx.routes) == 1
    assert len(gpx.routes[0].points) == 3
    back = read_gpx(path)
    assert back[0].lat_deg == pytest.approx(43.7120001, abs=1e-9)
    assert back[0].description == "score 0.81 <dark>"
    assert back[2].frame == MAV_FRAME_GLOBAL
    assert back[2].alt_m == 35.0


@pytest.mark.parametrize("suffix", [".plan", ".waypoints", ".kml", ".geojson", ".gpx"])
def test_dispatch_by_extension(tmp_path: Path, suffix: str) -> None:
    path = write_waypoints(tmp_path / f"m{suffix}", _mission(), HOME)
    back = read_waypoints(path)
    want = (
        _mission()
        if suffix in {".plan", ".waypoints"}
        else [w for w in _mission() if w.has_position]
    )
    assert len(back) == len(want)
    for g, w in zip(back, want, strict=True):
        assert (g.lat_deg, g.lon_deg) == pytest.approx((w.lat_deg, w.lon_deg), abs=1e-8)


def test_unknown_extension_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="unknown waypoint file type"):
        write_waypoints(tmp_path / "m.xyz", _mission(), HOME)


def test_waypoint_validates_coordinates() -> None:
    with pytest.raises(InputError, match="latitude"):
        Waypoint(91.0, 0.0, 1.0)
    with pytest.raises(InputError, match="longitude"):
        Waypoint(0.0, 200.0, 1.0)
    Waypoint(0.0, 0.0, 0.0, frame=MAV_FRAME_MISSION)  # no position: nothing to check


def test_read_area_from_every_source(tmp_path: Path) -> None:
    ring = [[10.40, 43.71], [10.41, 43.71], [10.41, 43.72], [10.40, 43.72], [10.40, 43.71]]
    hole = [[10.403, 43.713], [10.404, 43.713], [10.404, 43.714], [10.403, 43.713]]
    point = {"type": "Point", "coordinates": [0, 0]}
    polygon = {"type": "Polygon", "coordinates": [ring, hole]}
    fc = {
        "type": "FeatureCollection",
        "features": [
            {"type": "Feature", "properties": {}, "geometry": g} for g in (point, polygon)
        ],
    }
    (tmp_path / "a.geojson").write_text(json.dumps(fc))
    area = read_area(tmp_path / "a.geojson")
    assert area.outer == ((43.71, 10.40), (43.71, 10.41), (43.72, 10.41), (43.72, 10.40))
    assert len(area.holes) == 1
    assert area.holes[0][0] == (43.713, 10.403)
    (tmp_path / "a.txt").write_text("# lat,lon\n43.71, 10.40\n43.71 10.41\n43.72,10.41\n")
    assert read_area(tmp_path / "a.txt").outer == ((43.71, 10.40), (43.71, 10.41), (43.72, 10.41))
    assert read_area("43.71,10.40; 43.71,10.41; 43.72,10.41").outer[2] == (43.72, 10.41)


def test_read_area_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found"):
        read_area(tmp_path / "missing.geojson")
    two = {
        "type": "MultiPolygon",
        "coordinates": [[[[0, 0], [1, 0], [1, 1]]], [[[2, 2], [3, 2], [3, 3]]]],
    }
    (tmp_path / "two.geojson").write_text(json.dumps(two))
    with pytest.raises(InputError, match="2 polygons"):
        read_area(tmp_path / "two.geojson")
    (tmp_path / "pt.geojson").write_text(json.dumps({"type": "Point", "coordinates": [0, 0]}))
    with pytest.raises(InputError, match="no Polygon"):
        read_area(tmp_path / "pt.geojson")
    (tmp_path / "bad.geojson").write_text("{not json")
    with pytest.raises(InputError, match="not JSON"):
        read_area(tmp_path / "bad.geojson")
    (tmp_path / "bad.kml").write_text("<kml><Document>")
    with pytest.raises(InputError, match="not valid KML"):
        read_area(tmp_path / "bad.kml")
    with pytest.raises(InputError, match="lat,lon"):
        read_area("43.7,10.4,5; 43.8,10.4")
