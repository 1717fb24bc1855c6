"""A survey that skips one lane, fused, against the simulator's ray-cast truth.

Truth the code under test did not produce: which cells of the world the simulator's exact
renderer saw (noise-free depth of every frame, back-projected; its range cut-off), where
the world's surface is (its height field). The map is fused from the noisy frames the
simulated Xtion delivers (dropouts, quantisation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from shapely.geometry import LineString
from shapely.ops import unary_union

from holescan.detect import CameraIntrinsics
from holescan.geotag import LocalCameraPose
from holescan.ground.searchmap import find_gaps, plan_refly
from holescan.mapping import MapGrid, MapLayers, SearchMap
from holescan.missions import SurveyParams, plan_survey
from holescan.sim import DEFAULT_ANCHOR, CameraPose, make_world, render, render_exact, world_area

CAM = CameraIntrinsics.xtion(320, 240)
ALT = 2.5
STEP_M = 0.5
THRESHOLD = 0.5
MAX_RANGE_M = 3.5  # the simulated Xtion's useful range (its depth cut-off)


@dataclass
class Flown:
    layers: MapLayers
    truth_seen: np.ndarray  # (ny, nx) bool: cells some frame's exact ray-cast saw
    lane_x: list[float]  # east of every planned line
    skipped: float  # east of the line not flown
    spacing: float
    footprint_across: float
    world_height: np.ndarray  # the world's surface at the cell centres


@pytest.fixture(scope="module")
def flown() -> Flown:
    world = make_world(5, (10.0, 8.0), n_access_holes=3)
    frame = DEFAULT_ANCHOR.frame
    params = SurveyParams(altitude_m=ALT, heading_deg=0.0)
    plan = plan_survey(world_area(world, DEFAULT_ANCHOR, 0.5), params)
    lines = []
    for a, b in plan.lines:
        (ea, na), (eb, nb) = (frame.to_en(w.lat_deg, w.lon_deg) for w in (a, b))
        lines.append((float(ea), float(na), float(eb), float(nb)))
    assert len(lines) >= 4
    skip = len(lines) // 2
    grid = MapGrid.covering(0.0, 0.0, *world.size_m, 0.04)
    m = SearchMap(grid, frame)
    seen = np.zeros(grid.shape, bool)
    rng = np.random.default_rng(3)
    for k, (ea, na, eb, nb) in enumerate(lines):
        if k == skip:
            continue
        length = math.hypot(eb - ea, nb - na)
        for t in np.arange(0.0, length + 1e-9, STEP_M):
            x, y = ea + (eb - ea) * t / length, na + (nb - na) * t / length
            pose = CameraPose.looking_down(x, y, ALT, yaw=0.0)
            rgb, depth, _ = render(world, pose, CAM, rng)
            m.add_frame(depth, rgb, CAM, LocalCameraPose(pose.rotation, pose.position))
            # Truth: the exact ray-cast of the same view, within the sensor's range.
            z, _ = render_exact(world, pose, CAM)
            v, u = np.nonzero((z > 0) & (z <= MAX_RANGE_M))
            zz = z[v, u].astype(np.float64)
            pc = np.column_stack([(u - CAM.cx) / CAM.fx * zz, (v - CAM.cy) / CAM.fy * zz, zz])
            pw = pose.to_world(pc)
            r, c = grid.cell_of(pw[:, 0], pw[:, 1])
            seen[r[r >= 0], c[r >= 0]] = True
    e, n = grid.centres()
    ee, nn = np.meshgrid(e, n)
    height = world.height_at(np.column_stack([ee.ravel(), nn.ravel()])).reshape(grid.shape)
    return Flown(
        m.layers(),
        seen,
        [ln[0] for ln in lines],
        lines[skip][0],
        plan.line_spacing_m,
        plan.footprint_m[0],
        height,
    )


def _east(f: Flown) -> np.ndarray:
    e, _n = f.layers.grid.centres()
    return np.broadcast_to(e[None, :], f.layers.grid.shape)


def _north(f: Flown) -> np.ndarray:
    _e, n = f.layers.grid.centres()
    return np.broadcast_to(n[:, None], f.layers.grid.shape)


def test_the_skipped_lane_is_a_gap(flown: Flown) -> None:
    east, north = _east(flown), _north(flown)
    inside = (north > 0.5) & (north < 7.5)
    lane = inside & (np.abs(east - flown.skipped) < flown.spacing / 2) & ~flown.truth_seen
    assert lane.sum() * 0.04**2 > 2.0  # a strip nobody saw: over 2 m2
    below = flown.layers.coverage[lane] < THRESHOLD
    print(f"skipped lane: {lane.sum()} cells never seen by the truth, {below.mean():.3f} below")
    assert below.mean() >= 0.95


def test_the_flown_lanes_are_covered(flown: Flown) -> None:
    east, north = _east(flown), _north(flown)
    inside = (north > 0.5) & (north < 7.5) & (east > 0.5) & (east < 9.5)
    near = np.zeros(east.shape, bool)
    for x in flown.lane_x:
        if x != flown.skipped:
            near |= np.abs(east - x) < flown.spacing / 2
    lanes = inside & near & flown.truth_seen
    covered = flown.layers.coverage[lanes] >= THRESHOLD
    print(f"flown lanes: {lanes.sum()} cells seen by the truth, {covered.mean():.3f} covered")
    assert covered.mean() >= 0.95


def test_the_surface_lies_where_the_world_is(flown: Flown) -> None:
    lay = flown.layers
    ok = np.isfinite(lay.height_m) & flown.truth_seen
    err = lay.height_m[ok] - flown.world_height[ok]
    p90 = np.percentile(abs(err), 90)
    print(f"height - world: median {np.median(err):+.4f} m, p90 |err| {p90:.3f} m")
    assert abs(float(np.median(err))) < 0.02


def test_the_refly_covers_the_gap(flown: Flown) -> None:
    east, north = _east(flown), _north(flown)
    from shapely.geometry import box

    report = find_gaps(flown.layers, box(0.5, 0.5, 9.5, 7.5), threshold=THRESHOLD)
    assert report.gaps and 0.4 < report.searched_fraction < 0.95
    refly = plan_refly(report.gaps, DEFAULT_ANCHOR.frame, SurveyParams(altitude_m=ALT))
    assert refly is not None
    frame = DEFAULT_ANCHOR.frame
    strips = []
    half = refly.plans[0].footprint_m[0] / 2
    for pl in refly.plans:
        for a, b in pl.lines:
            pa, pb = (frame.to_en(w.lat_deg, w.lon_deg) for w in (a, b))
            strips.append(LineString([pa, pb]).buffer(half, cap_style="flat"))
    flown_again = unary_union(strips)
    lane = (
        (north > 0.5)
        & (north < 7.5)
        & (np.abs(east - flown.skipped) < flown.spacing / 2)
        & ~flown.truth_seen
    )
    from shapely import contains_xy

    inside = contains_xy(flown_again, east[lane], north[lane])
    print(f"re-fly footprints cover {inside.mean():.3f} of the skipped lane's unseen cells")
    assert inside.mean() >= 0.95
