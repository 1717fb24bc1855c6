"""The simulator's world and camera: determinism, depth statistics, ground-truth boxes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holescan.detect import CameraIntrinsics
from holescan.sim import CameraPose, Conditions, make_world, render
from holescan.sim._camera_model import project_points

CAM = CameraIntrinsics.xtion()


@pytest.fixture(scope="module")
def world():  # type: ignore[no-untyped-def]
    return make_world(
        3,
        (8.0, 8.0),
        n_access_holes=2,
        n_small_holes=2,
        n_cracks=1,
        n_depressions=1,
        n_stains=1,
        n_shadows=1,
    )


def test_world_is_deterministic(world) -> None:  # type: ignore[no-untyped-def]
    again = make_world(
        3,
        (8.0, 8.0),
        n_access_holes=2,
        n_small_holes=2,
        n_cracks=1,
        n_depressions=1,
        n_stains=1,
        n_shadows=1,
    )
    assert np.array_equal(world.height, again.height)
    assert np.array_equal(world.albedo, again.albedo)
    assert [h.centre_xy for h in world.holes] == [h.centre_xy for h in again.holes]
    assert len(world.access_holes) == 2
    for h in world.access_holes:
        assert h.major_m >= 0.6 and h.minor_m >= 0.35 and h.floor_depth_m >= 0.7


def test_flat_ground_depth_and_noise() -> None:
    flat = make_world(
        1,
        (6.0, 6.0),
        n_access_holes=0,
        n_small_holes=0,
        n_cracks=0,
        n_depressions=0,
        n_stains=0,
        n_shadows=0,
        slabs_per_m2=0.0,
        debris_per_m2=0.0,
    )
    cx, cy = 3.0, 3.0
    ground = float(flat.height_at([[cx, cy]])[0])
    pose = CameraPose.looking_down(cx, cy, ground + 3.0)
    rng = np.random.default_rng(0)
    _, depth, boxes = render(flat, pose, CAM, rng, Conditions(dropout_fraction=0.0))
    centre = depth[200:280, 280:360].astype(float)
    valid = centre[centre > 0]
    assert valid.size > 0.9 * centre.size
    assert np.median(valid) == pytest.approx(3000, abs=60)  # gentle undulation only
    # Axial noise of the Xtion at 3 m: 1.425e-6 * 3000^2 = 12.8 mm (plus quantisation).
    resid = valid - np.median(valid)
    assert 6.0 < float(np.std(resid - np.mean(resid))) < 60.0
    assert boxes == ()


def test_ground_truth_box_is_the_projected_opening(world) -> None:  # type: ignore[no-untyped-def]
    hole = world.access_holes[0]
    cx, cy = hole.centre_xy
    pose = CameraPose.looking_down(cx, cy, hole.rim_z + 2.5, yaw=0.3)
    rgb, depth, boxes = render(world, pose, CAM, np.random.default_rng(1), Conditions())
    mine = [b for b in boxes if b.hole_id == hole.id]
    assert len(mine) == 1 and not mine[0].iscrowd
    uv, _ = project_points(CAM, pose, hole.opening_xyz())
    x, y, w, h = mine[0].box
    # Boxes use pixel edges (pixel i spans [i, i + 1)): half a pixel beyond the centres.
    assert x == pytest.approx(uv[:, 0].min() + 0.5, abs=0.6)
    assert x + w == pytest.approx(uv[:, 0].max() + 0.5, abs=0.6)
    assert y == pytest.approx(uv[:, 1].min() + 0.5, abs=0.6)
    assert y + h == pytest.approx(uv[:, 1].max() + 0.5, abs=0.6)
    # The opening is dark and deep: median depth inside the box beyond the rim by > 0.5 m.
    x, y, w, h = (int(v) for v in mine[0].box)
    inner = depth[y + h // 3 : y + 2 * h // 3, x + w // 3 : x + 2 * w // 3]
    assert (inner == 0).mean() > 0.5 or np.median(inner[inner > 0]) > 2500 + 500
    assert rgb[y + h // 2, x + w // 2].mean() < np.median(rgb)


def test_tilted_view_marks_cut_holes_as_crowd(world) -> None:  # type: ignore[no-untyped-def]
    hole = world.access_holes[0]
    cx, cy = hole.centre_xy
    # Camera offset so the hole sits across the image's left border.
    pose = CameraPose.looking_down(cx + 0.75, cy, hole.rim_z + 2.0, tilt=math.radians(5))
    _, _, boxes = render(world, pose, CAM, np.random.default_rng(2), Conditions())
    mine = [b for b in boxes if b.hole_id == hole.id]
    assert mine and mine[0].iscrowd and mine[0].box[0] == pytest.approx(0.0, abs=1e-6)


# --- renderer exactness and Xtion artefacts (B) ------------------------------------------


def _flat_world(size_m: float = 6.0, step: bool = False):  # type: ignore[no-untyped-def]
    """A perfectly flat field at z = 0 (optionally a 0.5 m high block in the middle)."""
    from holescan.sim import RubbleWorld

    n = round(size_m / 0.02) + 1
    height = np.zeros((n, n), np.float32)
    if step:
        c = n // 2
        height[c - 25 : c + 26, c - 25 : c + 26] = 0.5  # 1 m x 1 m, 0.5 m high
    albedo = np.full((n, n, 3), 0.4, np.float32)
    return RubbleWorld(0, 0.02, height, albedo, albedo.copy(), (), 0.0, 0.3)


def test_rasteriser_and_ray_caster_agree(world) -> None:  # type: ignore[no-untyped-def]
    from holescan.sim import render_exact
    from holescan.sim._render import raycast_view

    cam = CAM.scaled(0.5)
    hole = world.access_holes[1]
    pose = CameraPose.looking_down(
        hole.centre_xy[0] + 0.4, hole.centre_xy[1], hole.rim_z + 2.2, yaw=0.7, tilt=0.2
    )
    d_r, rad_r = render_exact(world, pose, cam)
    d_c, rad_c = raycast_view(world, pose, cam)
    both = (d_r > 0) & (d_c > 0)
    assert both.mean() > 0.999
    assert float(np.abs(d_r - d_c)[both].max()) < 1e-4  # metres: the same exact surface
    assert float(np.abs(rad_r - rad_c)[both].max()) < 1e-3
    # Deep floors are there (beyond the sensor's 4 m) and the rim is at the expected range.
    assert d_r.max() > 4.0


def test_exact_depth_of_a_flat_field_is_the_plane() -> None:
    from holescan.sim import render_exact

    flat = _flat_world()
    tilt = math.radians(10.0)
    pose = CameraPose.looking_down(3.0, 3.0, 2.0, yaw=0.4, tilt=tilt, tilt_heading=1.0)
    depth, _ = render_exact(flat, pose, CAM)
    # Axial depth of the plane z = 0: Z(u, v) = h / (n . ray) with n the world's up axis.
    u, v = np.meshgrid(np.arange(CAM.width), np.arange(CAM.height))
    rays = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones(u.shape)], -1)
    down = rays @ pose.rotation.T  # world direction of each ray with unit axial length
    expected = 2.0 / -down[..., 2]
    assert np.abs(depth - expected).max() < 1e-5


def test_depth_noise_matches_the_xtion_model() -> None:
    # The basic depth model (the structured-light one has its own tests).
    flat = _flat_world()
    pose = CameraPose.looking_down(3.0, 3.0, 3.0)
    cond = Conditions(dropout_fraction=0.0, structured_light=False)
    _, depth, _ = render(flat, pose, CAM, np.random.default_rng(5), cond)
    valid = depth[depth > 0].astype(float)
    assert valid.size > 0.99 * depth.size  # flat ground at 3 m: no shadows, all in range
    # Nadir over a plane: the axial depth is 3000 mm at every pixel.
    resid = depth[depth > 0].astype(float) - 3000.0
    sigma = 1.425e-6 * 3000.0**2  # 12.8 mm, noise and disparity quantisation together
    assert abs(float(resid.mean())) < 2.0
    assert float(resid.std()) == pytest.approx(sigma, rel=0.15)
    # Disparity is quantised (1/8 px): only a few dozen distinct depths around 3 m.
    assert len(np.unique(valid)) < 40
    # Nothing beyond the 4 m range is read.
    far = CameraPose.looking_down(3.0, 3.0, 4.3)
    _, depth_far, _ = render(flat, far, CAM, np.random.default_rng(5), cond)
    assert not depth_far.any()


def test_projector_shadow_falls_left_of_a_raised_block() -> None:
    from holescan.sim import render_exact

    block = _flat_world(step=True)
    pose = CameraPose.looking_down(3.0, 3.0, 3.0)  # north up, east (+x) to the right
    exact, _ = render_exact(block, pose, CAM)
    cond = Conditions(dropout_fraction=0.0, structured_light=False)  # the basic model
    _, depth, _ = render(block, pose, CAM, np.random.default_rng(0), cond)
    rows = slice(200, 280)
    cols = np.flatnonzero(np.any(exact[rows] < 2.75, axis=0))  # the block's top
    left_edge, right_edge = int(cols[0]), int(cols[-1])
    # Shadow width = f b (1/Z_near - 1/Z_far) = 570.3 * 0.075 * (1/2.5 - 1/3) = 2.9 px.
    left = (depth[rows, left_edge - 6 : left_edge] == 0).mean(axis=0)
    right = (depth[rows, right_edge + 1 : right_edge + 7] == 0).mean(axis=0)
    assert 2 <= int((left > 0.9).sum()) <= 4
    assert right.max() < 0.05


def test_render_is_reproducible_from_the_generator(world) -> None:  # type: ignore[no-untyped-def]
    hole = world.access_holes[0]
    pose = CameraPose.looking_down(hole.centre_xy[0], hole.centre_xy[1], hole.rim_z + 3.0)
    a = render(world, pose, CAM, np.random.default_rng(9))
    b = render(world, pose, CAM, np.random.default_rng(9))
    c = render(world, pose, CAM, np.random.default_rng(10))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2]
    assert not np.array_equal(a[1], c[1])
    # Dawn light: a dim image, and the hole's interior (image centre) darker still.
    y = a[0].astype(float).mean(axis=2) / 255.0
    assert 0.1 < float(y.mean()) < 0.45
    assert float(y[230:250, 310:330].mean()) < 0.5 * float(y.mean())


def test_rays_from_above_hit_the_ground_below() -> None:
    from holescan.sim._raycast import cast_rays

    flat = _flat_world(step=True)
    origins = np.array([[3, 3, 5], [1, 1, 5], [1.2, 3, 3], [1, 3, 3], [-1, 3, 5]], float)
    dirs = [[0.0, 0, -1], [0.0, 0, -1], [1.0, 0, -1], [1.0, 0, -1.25], [0.0, 0, -1]]
    t, _ = cast_rays(flat.height, flat.radiance, flat.pyramid, flat.cell_m, origins, dirs)
    assert t[0] == pytest.approx(4.5)  # the block's top
    assert t[1] == pytest.approx(5.0)  # the ground
    assert t[2] == pytest.approx(3.0 * math.sqrt(2))  # 45 deg, just over the block's corner
    assert t[3] == pytest.approx(2.0 * math.hypot(1.0, 1.25))  # lands on the block's top
    assert np.isnan(t[4])  # off the field
