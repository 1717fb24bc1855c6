"""The search map fused from posed frames, against the simulator's world."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from holescan.detect import CameraIntrinsics
from holescan.geotag import CameraMount, LocalCameraPose, LocalFrame, VehiclePose, camera_pose_local
from holescan.mapping import FuseParams, MapError, MapGrid, RecallTable, SearchMap, merge_layers
from holescan.sim import CameraPose, RubbleWorld, make_world, render, render_exact

CAM = CameraIntrinsics.xtion(160, 120)
FRAME = LocalFrame(47.0, 8.0, 400.0)


@pytest.fixture(scope="module")
def world():  # type: ignore[no-untyped-def]
    return make_world(3, (8.0, 8.0))


def _frames(world, xs, y=4.0, alt=3.0, yaw=0.3, cam=CAM):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(1)
    out = []
    for x in xs:
        g = float(world.height_at([[x, y]])[0])
        p = CameraPose.looking_down(x, y, g + alt, yaw=yaw, tilt=math.radians(4))
        rgb, depth, _ = render(world, p, cam, rng)
        out.append((depth, rgb, LocalCameraPose(p.rotation, p.position)))
    return out


def test_height_and_colour_lie_on_the_simulated_world(world) -> None:  # type: ignore[no-untyped-def]
    vga = CameraIntrinsics.xtion()  # the Xtion's own resolution: its depth quantisation
    m = SearchMap(MapGrid.covering(0, 0, 8, 8, 0.02), FRAME, RecallTable.uniform(0.8))
    for depth, rgb, pose in _frames(world, [3.0, 3.5, 4.0], cam=vga):
        m.add_frame(depth, rgb, vga, pose, pixel_stride=4)
    lay = m.layers()
    e, n = m.grid.centres()
    ee, nn = np.meshgrid(e, n)
    seen = np.isfinite(lay.height_m)
    assert seen.sum() > 20000
    truth = world.height_at(np.column_stack([ee[seen], nn[seen]]))
    err = lay.height_m[seen] - truth
    # The cell's height is a sample somewhere in the cell, not at its centre: rubble slopes.
    assert abs(float(np.median(err))) < 0.01
    assert float(np.percentile(np.abs(err), 75)) < 0.04
    # Every seen cell got a colour: black only where the frame itself is (noise clipped at
    # a dark spot: 60-76 of the 307k pixels of these frames, both sensor models).
    assert float((lay.rgb[seen].sum(axis=1) > 0).mean()) > 0.999
    assert np.all(lay.looks[seen] >= 1) and lay.looks.max() == 3


def test_looks_combine_as_one_minus_the_product_of_misses(world) -> None:  # type: ignore[no-untyped-def]
    frames = _frames(world, [4.0, 4.0])
    grid = MapGrid.covering(0, 0, 8, 8, 0.05)
    indep = SearchMap(grid, FRAME, RecallTable.uniform(0.5), FuseParams(independent_m=0.0))
    same = SearchMap(grid, FRAME, RecallTable.uniform(0.5))
    for depth, rgb, pose in frames:
        indep.add_frame(depth, rgb, CAM, pose)
        same.add_frame(depth, rgb, CAM, pose)
    r, c = grid.cell_of(4.0, 4.0)
    assert indep.layers().coverage[r, c] == pytest.approx(0.75, abs=1e-5)
    # Two frames from one place are one pass: no more than one look's POD.
    assert same.layers().coverage[r, c] == pytest.approx(0.5, abs=1e-5)
    assert indep.layers().looks[r, c] == 2


def test_chunks_merge_to_the_map_of_the_whole_flight(world) -> None:  # type: ignore[no-untyped-def]
    frames = _frames(world, [2.5, 3.5, 4.5, 5.5])
    grid = MapGrid.covering(0, 0, 8, 8, 0.05)
    params = FuseParams(independent_m=0.0)
    whole = SearchMap(grid, FRAME, RecallTable.uniform(0.6), params)
    parts = [SearchMap(grid, FRAME, RecallTable.uniform(0.6), params) for _ in range(2)]
    for k, (depth, rgb, pose) in enumerate(frames):
        whole.add_frame(depth, rgb, CAM, pose)
        parts[k // 2].add_frame(depth, rgb, CAM, pose)
    windows = [p.seen_window() for p in parts]
    for p, w in zip(parts, windows, strict=True):  # the same window as from the whole layers
        full = p.layers().seen_window()
        assert w is not None and full is not None and w.grid == full.grid
        np.testing.assert_array_equal(w.log_miss, full.log_miss)
        np.testing.assert_array_equal(w.rgb, full.rgb)
    assert all(w is not None and w.grid.nx < grid.nx for w in windows)
    merged = merge_layers(grid, [w for w in windows if w is not None])
    one = whole.layers()
    np.testing.assert_array_equal(merged.looks, one.looks)
    np.testing.assert_allclose(merged.coverage, one.coverage, atol=1e-5)
    np.testing.assert_array_equal(merged.rgb, one.rgb)
    np.testing.assert_array_equal(np.isnan(merged.height_m), np.isnan(one.height_m))


def test_changed_tiles_name_what_a_frame_touched(world) -> None:  # type: ignore[no-untyped-def]
    (a, b) = _frames(world, [1.5, 6.5])
    m = SearchMap(MapGrid.covering(0, 0, 8, 8, 0.05, tile_cells=32), FRAME)
    assert m.changed_tiles(0) == []
    v1 = m.add_frame(*a[:2], CAM, a[2]).version
    first = set(m.changed_tiles(0))
    m.add_frame(*b[:2], CAM, b[2])
    second = set(m.changed_tiles(v1))
    assert first and second and not first & second  # 5 m apart: footprints do not overlap
    assert set(m.changed_tiles(0)) == first | second
    assert all(m.tile_version(*t) == 2 for t in second)


def test_a_pose_from_geotag_places_the_frame(world) -> None:  # type: ignore[no-untyped-def]
    pose = VehiclePose(0, 47.0, 8.0, 403.0, 3.0, 0.0, 0.0, 0.0)
    cam_pose = camera_pose_local(FRAME, CameraMount(), pose)
    depth = np.full((CAM.height, CAM.width), 3000, np.uint16)
    rgb = np.full((CAM.height, CAM.width, 3), 90, np.uint8)
    m = SearchMap(MapGrid.covering(-3, -3, 3, 3, 0.05), FRAME, RecallTable.uniform(0.9))
    m.add_frame(depth, rgb, CAM, cam_pose)
    lay = m.layers()
    seen = lay.looks > 0
    assert np.nanmax(np.abs(lay.height_m)) < 1e-3  # 3 m below a camera at 403 m: up 0 in FRAME
    e, n = m.grid.centres()
    # A nadir Xtion at 3 m sees 58 x 45 deg: 3.33 x 2.49 m, centred under the vehicle.
    ce, cn = e[seen.any(axis=0)], n[seen.any(axis=1)]
    assert ce.max() - ce.min() == pytest.approx(2 * 3 * math.tan(math.radians(29.0)), abs=0.1)
    assert cn.max() - cn.min() == pytest.approx(2 * 3 * math.tan(math.radians(22.6)), abs=0.1)
    assert abs(ce.mean()) < 0.05 and abs(cn.mean()) < 0.05


def test_cells_behind_a_slab_are_not_looked_at() -> None:
    # A flat field with a 1 m block, seen obliquely from the west: the ground east of the
    # block is in its shadow. Truth: the simulator's exact render (a z-buffer of its own).
    n = 301
    height = np.zeros((n, n), np.float32)
    height[100:200, 150:160] = 1.0  # 0.2 m wide, 2 m long, 1 m tall, at x = 3.0-3.2 m
    albedo = np.full((n, n, 3), 0.4, np.float32)
    world = RubbleWorld(0, 0.02, height, albedo, albedo.copy(), (), 0.0, 0.5)
    cam = CameraIntrinsics.xtion(320, 240)
    pose = CameraPose.looking_down(
        1.5, 3.0, 2.5, yaw=math.pi / 2, tilt=math.radians(30), tilt_heading=math.pi / 2
    )
    rgb, depth, _ = render(world, pose, cam, np.random.default_rng(0))
    grid = MapGrid.covering(0, 0, 6, 6, 0.04)
    m = SearchMap(grid, FRAME, RecallTable.uniform(0.9))
    m.add_frame(depth, rgb, cam, LocalCameraPose(pose.rotation, pose.position))
    looks = m.layers().looks
    z, _ = render_exact(world, pose, cam)
    e, nn = grid.centres()
    ee, nnn = np.meshgrid(e, nn)
    ground = np.column_stack([ee.ravel(), nnn.ravel(), np.zeros(ee.size)])
    pc = pose.to_camera(ground)
    u = np.round(cam.fx * pc[:, 0] / pc[:, 2] + cam.cx).astype(int)
    v = np.round(cam.fy * pc[:, 1] / pc[:, 2] + cam.cy).astype(int)
    inview = (pc[:, 2] > 0) & (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
    behind = np.zeros(ee.size, bool)
    behind[inview] = z[v[inview], u[inview]] < pc[inview, 2] - 0.1  # something nearer
    behind &= ~((ee.ravel() >= 2.98) & (ee.ravel() <= 3.24))  # not the block's own cells
    # Wholly in the shadow: 2 cells from its edge (edge cells are partly seen).
    shadow = behind.reshape(grid.shape).astype(np.uint8)
    behind = cv2.erode(shadow, np.ones((5, 5), np.uint8)) > 0
    assert behind.sum() > 200  # the shadow: over 0.3 m2
    assert (looks[behind] > 0).mean() < 0.05
    # Wholly in sight within the sensor's range (3.5 m): looked at.
    zc = np.zeros(ee.size)
    zc[inview] = z[v[inview], u[inview]]
    lit = (inview & (zc > 0) & (pc[:, 2] <= 3.5)).reshape(grid.shape) & (shadow == 0)
    visible = cv2.erode(lit.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert visible.sum() > 1000
    assert (looks[visible] > 0).mean() > 0.9


def test_bad_frames_are_refused() -> None:
    m = SearchMap(MapGrid.covering(0, 0, 2, 2, 0.05), FRAME, RecallTable.uniform(0.5))
    pose = LocalCameraPose(np.eye(3), np.zeros(3))
    good_d = np.zeros((CAM.height, CAM.width), np.uint16)
    good_c = np.zeros((CAM.height, CAM.width, 3), np.uint8)
    with pytest.raises(MapError, match="depth"):
        m.add_frame(good_d.astype(np.float32), good_c, CAM, pose)  # type: ignore[arg-type]
    with pytest.raises(MapError, match="rgb"):
        m.add_frame(good_d, good_c[:-1], CAM, pose)
    with pytest.raises(MapError, match="stride"):
        m.add_frame(good_d, good_c, CAM, pose, pixel_stride=0)
    with pytest.raises(MapError):
        MapGrid.covering(0, 0, -1, 2)


def test_unread_bands_are_no_look_and_the_border_counts_less() -> None:
    # A nadir frame of flat ground with a registered Xtion's unread right band (40 px of
    # 640): the ground under the band is not looked at (before, its unread pixels counted
    # as looks into a void), and looks near the read area's edge are worth that bin.
    pose = camera_pose_local(FRAME, CameraMount(), VehiclePose(0, 47.0, 8.0, 403.0, 3.0, 0, 0, 0))
    vga = CameraIntrinsics.xtion()
    depth = np.full((vga.height, vga.width), 3000, np.uint16)
    rgb = np.full((vga.height, vga.width, 3), 90, np.uint8)
    table = RecallTable(
        np.array([0.0, 5.0]),
        np.array([0.0, 60.0]),
        np.array([[[0.3, 0.9]]]),
        np.array([[[20, 20]]]),
        {},
        np.array([0.0, 60.0, np.inf]),
    )
    grid = MapGrid.covering(-3, -3, 3, 3, 0.05)
    full, banded = SearchMap(grid, FRAME, table), SearchMap(grid, FRAME, table)
    full.add_frame(depth, rgb, vga, pose, pixel_stride=4)
    depth[:, 600:] = 0
    banded.add_frame(depth, rgb, vga, pose, pixel_stride=4)
    a, b = full.layers(), banded.layers()
    assert (b.looks > 0).sum() < 0.95 * (a.looks > 0).sum()
    assert not ((b.looks > 0) & (a.looks == 0)).any()
    cov = b.coverage[b.looks > 0]
    assert np.isclose(cov, 0.9, atol=0.01).mean() > 0.5 and np.isclose(cov, 0.3, atol=0.01).any()
    assert table.pod(2.0, 10.0, -1.0) == 0.0 and table.pod(2.0, 10.0) == pytest.approx(0.9)
