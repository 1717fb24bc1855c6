"""Survey planning: coverage of the polygon by the camera footprints, margins, bounds, errors."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
import shapely
from shapely.geometry import Point, Polygon

from holescan import cli
from holescan.errors import InputError
from holescan.missions import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_RETURN_TO_LAUNCH,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    XTION,
    Area,
    SurveyParams,
    SurveyPlan,
    plan_survey,
)


def _area(
    lat0: float,
    lon0: float,
    enu: list[tuple[float, float]],
    holes: list[list[tuple[float, float]]] = (),
) -> Area:  # type: ignore[assignment]
    """A polygon given in metres east/north of (lat0, lon0)."""

    def ring(pts: list[tuple[float, float]]) -> tuple[tuple[float, float], ...]:
        e, n = np.array(pts, dtype=float).T
        lat, lon, _ = pymap3d.enu2geodetic(e, n, 0.0, lat0, lon0, 0.0)
        lon = (np.asarray(lon) + 180.0) % 360.0 - 180.0
        return tuple((float(a), float(b)) for a, b in zip(lat, lon, strict=True))

    return Area(ring(enu), tuple(ring(h) for h in holes))


def _rotated_rect(w: float, h: float, deg: float) -> list[tuple[float, float]]:
    r = math.radians(deg)
    pts = [(-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2)]
    return [(x * math.cos(r) - y * math.sin(r), x * math.sin(r) + y * math.cos(r)) for x, y in pts]


def _star(r_out: float, r_in: float, n: int = 5) -> list[tuple[float, float]]:
    pts = []
    for k in range(2 * n):
        r = r_out if k % 2 == 0 else r_in
        a = math.pi / 2 + k * math.pi / n
        pts.append((r * math.cos(a), r * math.sin(a)))
    return pts


AREAS = {
    # convex
    "rectangle": _area(47.0, 8.0, _rotated_rect(40, 25, 20)),
    "pentagon": _area(-33.9, 151.2, [(0, 0), (30, -5), (42, 18), (20, 35), (-6, 20)]),
    # concave
    "L-shape": _area(43.7, 10.4, [(0, 0), (40, 0), (40, 12), (14, 12), (14, 35), (0, 35)]),
    "U-shape": _area(
        35.0, 139.0, [(0, 0), (36, 0), (36, 30), (26, 30), (26, 9), (10, 9), (10, 30), (0, 30)]
    ),
    "star": _area(51.5, -0.1, _star(22, 9)),
    "with-hole": _area(40.0, -105.0, _rotated_rect(36, 30, -10), [_rotated_rect(10, 8, 30)]),
    # across the UTM zone 31/32 edge (6 deg E) and the antimeridian (zone 60/1)
    "utm-edge": _area(47.0, 6.0, _rotated_rect(38, 22, 35)),
    "antimeridian": _area(-17.0, 180.0, [(-20, -12), (18, -15), (22, 10), (0, 22), (-17, 9)]),
}  # fmt: skip


def _local(area: Area) -> tuple[float, float]:
    """The test's own local frame: the polygon's first vertex (not the planner's)."""
    return area.outer[0]


def _enu(lat: float, lon: float, origin: tuple[float, float]) -> tuple[float, float]:
    e, n, _ = pymap3d.geodetic2enu(lat, lon, 0.0, origin[0], origin[1], 0.0)
    return float(e), float(n)


def _polygon(area: Area, origin: tuple[float, float]) -> Polygon:
    return Polygon(
        [_enu(a, b, origin) for a, b in area.outer],
        [[_enu(a, b, origin) for a, b in h] for h in area.holes],
    )


def _footprints(plan: SurveyPlan, origin: tuple[float, float], step_m: float) -> object:
    """Union of the camera footprints of frames every ``step_m`` along each line.

    At 30 fps and ~0.65 m/s real frames are 2 cm apart; sampling fewer frames gives a
    lower bound of the covered area.
    """
    across, along = XTION.footprint_m(plan.params.altitude_m)
    rects = []
    for start, end in plan.lines:
        (x0, y0), (x1, y1) = (
            _enu(start.lat_deg, start.lon_deg, origin),
            _enu(end.lat_deg, end.lon_deg, origin),
        )
        length = math.hypot(x1 - x0, y1 - y0)
        ux, uy = ((x1 - x0) / length, (y1 - y0) / length) if length > 0 else (1.0, 0.0)
        vx, vy = -uy, ux  # across-track: the image's wide axis
        for t in np.linspace(0.0, 1.0, max(2, math.ceil(length / step_m) + 1)):
            cx, cy = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
            corners = [
                (
                    cx + sa * ux * along / 2 + sb * vx * across / 2,
                    cy + sa * uy * along / 2 + sb * vy * across / 2,
                )
                for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))
            ]
            rects.append(Polygon(corners))
    return shapely.union_all(rects)


@pytest.mark.parametrize("name", list(AREAS))
def test_footprints_cover_the_polygon_and_waypoints_stay_near(name: str) -> None:
    area = AREAS[name]
    plan = plan_survey(area)
    origin = _local(area)
    poly = _polygon(area, origin)
    covered = _footprints(plan, origin, step_m=0.25)
    coverage = poly.intersection(covered).area / poly.area
    assert coverage >= 0.99, f"{name}: {coverage:.4f} covered"
    assert plan.area_m2 == pytest.approx(poly.area, rel=1e-3)
    for w in plan.path:
        assert poly.distance(Point(_enu(w.lat_deg, w.lon_deg, origin))) <= plan.turn_margin_m + 1e-3
        assert -180.0 <= w.lon_deg <= 180.0


def test_zone_edge_and_antimeridian_plan_like_anywhere_else() -> None:
    shape = _rotated_rect(38, 22, 35)
    across_edge = plan_survey(_area(47.0, 6.0, shape))
    mid_zone = plan_survey(_area(47.0, 9.0, shape))
    assert len(across_edge.lines) == len(mid_zone.lines)
    assert across_edge.heading_deg == pytest.approx(mid_zone.heading_deg)
    assert across_edge.distance_m == pytest.approx(mid_zone.distance_m, rel=1e-3)
    lons = [w.lon_deg for w in across_edge.path]
    assert min(lons) < 6.0 < max(lons)
    anti = plan_survey(AREAS["antimeridian"])
    lons = [w.lon_deg for w in anti.path]
    assert min(lons) < -179.9
    assert max(lons) > 179.9
    assert anti.distance_m < 2000.0


def test_spacing_speed_and_items_follow_the_sensor() -> None:
    params = SurveyParams(altitude_m=2.5, relief_m=0.5, side_overlap=0.3)
    plan = plan_survey(AREAS["rectangle"], params)
    across = 2 * 2.5 * math.tan(math.radians(29.0))
    along = 2 * 2.5 * math.tan(math.radians(22.5))
    assert plan.footprint_m == pytest.approx((across, along))
    assert plan.line_spacing_m == pytest.approx(0.7 * across)
    # Frames on the nearest rubble (2.0 m away): blur <= 2 px during a 10 ms exposure,
    # consecutive frames at 30 fps overlap by >= 80 %.
    f_px = 240 / math.tan(math.radians(22.5))
    assert plan.speed_m_s * 0.010 * f_px / 2.0 <= 2.0
    along_top = 2 * 2.0 * math.tan(math.radians(22.5))
    assert plan.speed_m_s / 30.0 <= 0.2 * along_top
    assert plan.speed_m_s > 0.5  # not needlessly slow
    assert plan.duration_s > plan.distance_m / plan.speed_m_s
    items = plan.mission_items()
    assert items[0].command == MAV_CMD_NAV_TAKEOFF
    assert items[0].alt_m == 2.5
    assert items[1].command == MAV_CMD_DO_CHANGE_SPEED
    assert items[1].params[1] == plan.speed_m_s
    assert items[-1].command == MAV_CMD_NAV_RETURN_TO_LAUNCH
    nav = items[2:-1]
    assert len(nav) == 2 * len(plan.lines)
    assert {(w.command, w.frame, w.alt_m) for w in nav} == {
        (MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, 2.5)
    }
    # Lines alternate direction (boustrophedon); yaw points along the travel.
    yaws = [w.params[3] for w in nav[::2]]
    assert all(abs(((a - b) % 360.0) - 180.0) < 1e-6 for a, b in itertools.pairwise(yaws))


def test_heading_and_home_are_honoured() -> None:
    area = AREAS["rectangle"]
    lat_h, lon_h = area.outer[2]
    plan = plan_survey(area, SurveyParams(heading_deg=0.0, home=(lat_h, lon_h)))
    assert plan.heading_deg == 0.0
    assert (plan.home.lat_deg, plan.home.lon_deg) == pytest.approx((lat_h, lon_h))
    origin = _local(area)
    home = _enu(lat_h, lon_h, origin)
    pts = [_enu(w.lat_deg, w.lon_deg, origin) for w in plan.path]
    # Of the two directions through the same lines, it starts at the end nearer home.
    assert math.dist(pts[0], home) <= math.dist(pts[-1], home)
    # Distance: home -> every waypoint in order -> home, measured in the test's own frame.
    legs = [home, *pts, home]
    assert plan.distance_m == pytest.approx(
        sum(math.dist(a, b) for a, b in itertools.pairwise(legs)), rel=1e-3
    )
    auto = plan_survey(area)
    assert auto.duration_s <= plan.duration_s + 1e-6  # the automatic heading is no worse


def test_bad_parameters_say_what_to_change() -> None:
    area = AREAS["rectangle"]
    with pytest.raises(InputError, match=r"choose 1\.30-3\.00 m"):
        plan_survey(area, SurveyParams(altitude_m=3.4))
    with pytest.raises(InputError, match="useful range"):
        plan_survey(area, SurveyParams(altitude_m=0.5, relief_m=0.0))
    with pytest.raises(InputError, match="limited by blur"):
        plan_survey(area, SurveyParams(speed_m_s=3.0))
    with pytest.raises(InputError, match="turn margin"):
        plan_survey(area, SurveyParams(turn_margin_m=0.2))
    with pytest.raises(InputError, match="side overlap"):
        plan_survey(area, SurveyParams(side_overlap=0.95))


def test_bad_polygons_are_refused() -> None:
    bowtie = _area(47.0, 8.0, [(0, 0), (30, 30), (30, 0), (0, 30)])
    with pytest.raises(InputError, match=r"intersects itself near 47\.0001"):
        plan_survey(bowtie)
    with pytest.raises(InputError, match="empty"):
        plan_survey(_area(47.0, 8.0, [(0, 0), (10, 0), (20, 0)]))
    with pytest.raises(InputError, match="at least 3 vertices"):
        plan_survey(Area(((47.0, 8.0), (47.1, 8.0))))
    with pytest.raises(InputError, match="split it"):
        plan_survey(_area(47.0, 8.0, _rotated_rect(3000, 100, 0)))


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    rc = cli.main(["plan", *argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_writes_every_format(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ring = ";".join(f"{a},{b}" for a, b in AREAS["L-shape"].outer)
    outs = [tmp_path / f"s{ext}" for ext in (".plan", ".waypoints", ".kml", ".geojson", ".gpx")]
    rc, out, _ = _cli(capsys, ring, "--date", "2024-06-21", "--tz", "Europe/Rome",
                      *(a for p in outs for a in ("--out", str(p))))  # fmt: skip
    assert rc == 0
    assert "lines at heading" in out
    assert "estimated flight" in out
    assert "dusk 2024-06-21" in out
    assert "CEST" in out
    assert all(p.stat().st_size > 0 for p in outs)


def test_cli_bad_input_one_line_nonzero(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bowtie = ";".join(
        f"{a},{b}" for a, b in _area(47.0, 8.0, [(0, 0), (30, 30), (30, 0), (0, 30)]).outer
    )
    flat = ";".join(f"{a},{b}" for a, b in _area(47.0, 8.0, [(0, 0), (10, 0), (20, 0)]).outer)
    good = ";".join(f"{a},{b}" for a, b in AREAS["rectangle"].outer)
    out = str(tmp_path / "x.plan")
    cases = [
        ([bowtie, "--out", out], "intersects itself"),
        ([flat, "--out", out], "area is empty"),
        ([good, "--altitude", "3.3", "--out", out], "useful range"),
        ([str(tmp_path / "none.geojson")], "not found"),
    ]
    for argv, text in cases:
        rc, _, err = _cli(capsys, *argv)
        assert rc != 0
        lines = err.strip().splitlines()
        assert len(lines) == 1
        assert text in lines[0]
        assert lines[0].startswith("holescan plan: error:")
    assert not (tmp_path / "x.plan").exists()


def test_cli_warns_when_the_flight_does_not_fit_a_window(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    big = ";".join(f"{a},{b}" for a, b in _area(47.0, 8.0, _rotated_rect(150, 100, 0)).outer)
    rc, out, _ = _cli(capsys, big, "--date", "2024-06-21", "--out", str(tmp_path / "big.plan"))
    assert rc == 0  # the plan is still written: split it or fly it over several windows
    assert "estimated flight" in out
    assert "longer than every window" in caplog.text
