"""The rim plane of an opening the image border cuts: terrain, not the far wall."""

from __future__ import annotations

import math

import numpy as np

from holescan.detect._geometry import fit_plane, fit_plane_ransac, terrain_plane


def _view_into_a_cut_hole(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Camera straight down on level ground 2.75 m away; a hole at x < 0 with a vertical
    far wall at x = -0.6 m that the camera sees down to 3.8 m.

    Returns (band around the visible part, its rim ring): the ring is the near rim (an arc
    of ground at the hole's edge) plus the top of the wall, two lines.
    """
    rng = np.random.default_rng(seed)
    n = lambda k: rng.normal(0.0, 0.01, k)  # noqa: E731 - depth noise, 1 cm
    # Ground beyond the near rim: a 2-D patch.
    gx, gy = rng.uniform(0.0, 0.3, 400), rng.uniform(-0.5, 0.5, 400)
    ground = np.column_stack([gx, gy, 2.75 + n(400)])
    # The far wall: x = -0.6, depth 2.8-3.8 m.
    wy, wz = rng.uniform(-0.5, 0.5, 250), rng.uniform(2.8, 3.8, 250)
    wall = np.column_stack([np.full(250, -0.6), wy, wz + n(250)])
    # Ring: the near rim (x ~ 0) and the wall a little below its top.
    ry = rng.uniform(-0.5, 0.5, 60)
    near = np.column_stack([0.02 * ry**2, ry, 2.75 + n(60)])
    top = np.column_stack([np.full(60, -0.6), ry, 3.3 + 0.3 * rng.uniform(-1, 1, 60)])
    ring = np.vstack([near, top])
    return np.vstack([ground, wall, ring]), ring


def _tilt_deg(normal: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(normal[2])))))


def test_the_ring_alone_leans_into_the_hole_the_terrain_does_not() -> None:
    around, ring = _view_into_a_cut_hole()
    assert _tilt_deg(fit_plane(ring)[0]) > 30.0  # the plane through the two lines
    plane = terrain_plane(around, ring)
    assert plane is not None
    normal, centre = plane
    assert _tilt_deg(normal) < 3.0
    assert abs(float(centre[2]) - 2.75) < 0.02


def test_terrain_that_misses_the_rim_is_not_its_plane() -> None:
    around, ring = _view_into_a_cut_hole()
    lifted = ring.copy()
    lifted[:, 2] -= 0.5  # the rim stands half a metre proud of everything around it
    assert terrain_plane(around, lifted) is None


def test_ransac_plane_is_repeatable_and_takes_all_of_a_clean_plane() -> None:
    around, _ = _view_into_a_cut_hole(seed=3)
    a, b = fit_plane_ransac(around), fit_plane_ransac(around.copy())
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    rng = np.random.default_rng(1)
    flat = np.column_stack([rng.uniform(-1, 1, 200), rng.uniform(-1, 1, 200), np.full(200, 3.0)])
    normal, _ = fit_plane_ransac(flat)
    assert _tilt_deg(normal) < 1e-6
    few = flat[:5]
    assert np.allclose(fit_plane_ransac(few)[0], fit_plane(few)[0])
