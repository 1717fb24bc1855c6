"""The simulator's world and camera: determinism, depth statistics, ground-truth boxes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from capture.sim import CameraPose, Conditions, make_world, render
from capture.sim._camera_model import project_points
from detect import CameraIntrinsics

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
