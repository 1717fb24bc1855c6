"""The default detector on small synthetic scenes with known answers."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from skimage.morphology import reconstruction

from holescan.detect import DEFAULT, DOG, CameraIntrinsics, Detection, detect_holes
from holescan.detect._boxes import refine_box
from holescan.detect._default import basin_depth, block_depth, opening_axes
from holescan.detect._measure import ReadBox
from holescan.detect._regions import basin_depths, components
from holescan.detect._suppress import near_cut, toward_cut
from holescan.errors import InputError

CAM = CameraIntrinsics.xtion()
F = CAM.fx


def scene(
    z0: float = 2.8,
    holes: tuple[tuple[float, float, float, float, float], ...] = (),
    seed: int = 0,
    noise: bool = True,
    range_m: float = 4.0,
) -> tuple[np.ndarray, np.ndarray, list[tuple[float, float, float, float]]]:
    """Flat floor at ``z0`` with rectangular holes (u, v centre px, w, h metres, floor z m).

    Holes whose floor is beyond ``range_m`` are dark inside (a void at dawn).
    """
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    z = np.full((480, 640), z0)
    boxes = []
    rgb = np.full((480, 640, 3), 100, np.uint8)
    for cu, cv, wm, hm, zf in holes:
        w, h = wm * F / z0, hm * F / z0
        m = (np.abs(u - cu) < w / 2) & (np.abs(v - cv) < h / 2)
        z[m] = zf
        if zf > range_m:
            rgb[m] = 25
        boxes.append((cu - w / 2, cv - h / 2, w, h))
    if noise:
        z = z + rng.normal(0, 1, z.shape) * 1.425e-6 * (z * 1000) ** 2 / 1000
    depth = np.round(z * 1000).astype(np.uint16)
    depth[z > range_m] = 0
    return rgb, depth, boxes


def iou(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    ix = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    return ix * iy / (a[2] * a[3] + b[2] * b[3] - ix * iy)


def top(dets: list[Detection]) -> Detection:
    assert dets, "expected a detection"
    return dets[0]


def test_flat_floor_has_no_hole() -> None:
    rgb, depth, _ = scene()
    assert detect_holes(rgb, depth, CAM) == []


def test_deep_hole_with_visible_floor() -> None:
    rgb, depth, boxes = scene(holes=((320, 240, 1.0, 0.6, 3.8),))
    d = top(detect_holes(rgb, depth, CAM))
    assert iou(d.box, boxes[0]) > 0.85
    assert d.depth_rel_m == pytest.approx(1.0, abs=0.05)
    assert d.rim_depth_m == pytest.approx(2.8, abs=0.02)
    assert not d.beyond_range
    # Major: axis of the ellipse with a 1.0 x 0.6 rectangle's moments (side * 4 / sqrt(12));
    # minor: the passable width, the diameter of the largest disk inside (0.6 m).
    assert d.major_m == pytest.approx(1.0 * 4 / np.sqrt(12), rel=0.06)
    assert d.minor_m == pytest.approx(0.6, rel=0.08)
    assert d.features.width == 1.0
    assert d.features.depth == pytest.approx((1.0 - 0.2) / (1.951 - 0.2), abs=0.03)


def test_hole_beyond_range_is_a_hole_not_noise() -> None:
    rgb, depth, boxes = scene(holes=((250, 200, 0.9, 0.7, 6.0),))
    d = top(detect_holes(rgb, depth, CAM))
    assert d.beyond_range
    assert iou(d.box, boxes[0]) > 0.85
    assert d.depth_rel_m >= 4.0 - 2.8 - 0.05  # at least down to the sensor's range


def test_small_hole_and_shallow_dip_score_low() -> None:
    rgb, depth, _ = scene(holes=((150, 150, 0.2, 0.2, 4.5), (450, 300, 1.2, 1.0, 2.95)))
    for d in detect_holes(rgb, depth, CAM):
        assert d.score < 0.2, d.explain()


def test_dog_finds_a_hole_too_small_for_a_person() -> None:
    rgb, depth, _ = scene(holes=((320, 240, 0.4, 0.3, 4.5),))
    human = detect_holes(rgb, depth, CAM)
    dog = detect_holes(rgb, depth, CAM, DEFAULT.with_searcher(DOG))
    assert all(d.features.width < 0.5 for d in human)
    assert top(dog).features.width > 0.9


def test_two_holes_found_separately_and_ranked_by_depth() -> None:
    rgb, depth, boxes = scene(holes=((180, 240, 0.8, 0.8, 3.3), (460, 240, 0.8, 0.8, 5.0)))
    dets = [d for d in detect_holes(rgb, depth, CAM) if d.score > 0.3]
    assert len(dets) == 2
    assert iou(dets[0].box, boxes[1]) > 0.8  # the deeper one first
    assert iou(dets[1].box, boxes[0]) > 0.8


def test_hole_cut_by_border_is_found_when_its_rim_is_mostly_seen() -> None:
    # 80 % of the opening in view: no pit (it spills over the border) but a no-reading
    # blob with a valid rim on three sides.
    rgb, depth, boxes = scene(holes=((40, 240, 0.5, 0.8, 5.0),))
    d = top(detect_holes(rgb, depth, CAM))
    clipped = (0.0, boxes[0][1], boxes[0][0] + boxes[0][2], boxes[0][3])
    assert iou(d.box, clipped) > 0.8


def test_basin_cut_by_the_border_is_closed_there_not_spilled() -> None:
    z = np.full((40, 50), 2.0, np.float32)
    z[10:20, 0:10] = 2.7  # a pit the left border cuts
    spilled, _, _ = basin_depth(z)
    closed, _, _ = basin_depth(z, closed_border=True)
    assert float(spilled[15, 3]) == pytest.approx(0.0, abs=1e-6)
    assert float(closed[15, 3]) == pytest.approx(0.7, abs=1e-5)
    assert float(closed[30, 30]) == pytest.approx(0.0, abs=1e-6)  # the floor stays a floor


def test_a_cut_basin_with_sloping_walls_is_closed_at_its_rim_not_its_shoulder() -> None:
    # A pit 0.5 m deep the left border cuts, its walls sloping down over 6 rows each side:
    # bridged over its deep part only, it would drain at a shoulder 0.25 m below the rim
    # and read half as deep.
    z = np.full((60, 50), 2.0, np.float32)
    z[18:42, 0:12] = 2.5
    for i in range(6):
        z[18 + i, 0:12] = z[41 - i, 0:12] = 2.0 + 0.5 * (i + 1) / 7
    closed, _, _ = basin_depth(z, closed_border=True)
    assert float(closed[30, 3]) == pytest.approx(0.5, abs=1e-5)
    assert float(closed[30, 30]) == pytest.approx(0.0, abs=1e-6)


def test_a_shallow_stretch_beside_a_cut_dip_is_not_closed_far_beyond_it() -> None:
    # A depression 0.1 m deep along 30 rows of the left border, a dip 0.5 m deep and 4 rows
    # long at its end: the dip's bridge takes in the stretch's 2 rows next to it (half the
    # dip's length), not the whole stretch, which still drains at the border.
    z = np.full((60, 50), 2.0, np.float32)
    z[5:35, 0:20] = 2.1
    z[35:39, 0:4] = 2.5
    closed, _, _ = basin_depth(z, closed_border=True)
    assert float(closed[37, 1]) == pytest.approx(0.4, abs=1e-5)  # spills into the stretch
    assert float(closed[10, 5]) == pytest.approx(0.0, abs=1e-6)  # bridged whole: 0.1


def test_a_bridged_basin_spreading_away_from_the_cut_is_no_hole_running_to_it() -> None:
    # A hole whose box comes within 2 work px of the left side of the read area (60 x 40):
    # a bridged basin holding it runs on to that side; reaching beyond it elsewhere by its
    # walls (2 px), it is that hole; spreading below and to the right of it by more than
    # its ring, walls and a quarter of its size, a depression around the hole.
    inner = ReadBox((2, 10, 20, 25), (60, 40), False, True)
    hole = ReadBox((0, 8, 24, 29), (60, 40), True, True)
    depression = ReadBox((0, 8, 40, 38), (60, 40), True, True)
    assert near_cut(inner, hole, 6) and toward_cut(inner, hole, 6)
    assert near_cut(inner, depression, 6) and not toward_cut(inner, depression, 6)


@pytest.mark.parametrize("seed", range(8))
def test_both_basin_views_at_once_equal_each_computed_alone(seed: int) -> None:
    # Rough tilted terrain with pits, some cut by the border (a lake in the closed view
    # only), some of them unread, and unread specks: basin_depths derives the spilled view
    # from the closed one, and must give both exactly as two full reconstructions do.
    rng = np.random.default_rng(seed)
    hh, ww = 60, 80
    vv, uu = np.mgrid[0:hh, 0:ww]
    z = (2.0 + 0.01 * vv + 0.004 * uu + 0.02 * rng.standard_normal((hh, ww))).astype(np.float32)
    for _ in range(6):
        cy, cx, r = rng.integers(0, hh), rng.integers(0, ww), rng.integers(3, 12)
        pit = (vv - cy) ** 2 + (uu - cx) ** 2 < r * r
        z[pit] += rng.uniform(0.3, 1.5)
        if rng.random() < 0.4:
            z[pit & (rng.random((hh, ww)) < 0.7)] = np.nan
    z[rng.random((hh, ww)) < 0.02] = np.nan
    both = basin_depths(z)
    spilled, invalid, z_far = basin_depth(z)
    closed, _, _ = basin_depth(z, closed_border=True)
    assert np.array_equal(both.spilled, spilled)
    assert np.array_equal(both.invalid, invalid) and both.z_far == z_far
    if np.array_equal(closed, spilled):
        assert both.closed is None
    else:
        assert both.closed is not None and np.array_equal(both.closed, closed)


@pytest.mark.parametrize("seed", range(6))
def test_basin_depth_is_skimage_reconstruction(seed: int) -> None:
    # basin_depth fills by its own iterated erosion (float32): the same pit, every value,
    # as skimage's reconstruction by erosion of the heights from the border, in float64.
    rng = np.random.default_rng(seed)
    hh, ww = 50, 70
    vv, uu = np.mgrid[0:hh, 0:ww]
    z = (2.0 + 0.01 * vv + 0.02 * rng.standard_normal((hh, ww))).astype(np.float32)
    for _ in range(8):
        cy, cx, r = rng.integers(0, hh), rng.integers(0, ww), rng.integers(2, 14)
        z[(vv - cy) ** 2 + (uu - cx) ** 2 < r * r] += rng.uniform(0.05, 1.5)
    z[rng.random((hh, ww)) < 0.05] = np.nan
    pit, invalid, _ = basin_depth(z)
    height = -z.astype(np.float64)
    height[invalid] = -(float(np.nanmax(z)) + 3.0)  # any level below every reading
    marker = height.copy()
    marker[1:-1, 1:-1] = height.max()
    expect = reconstruction(marker, height, method="erosion") - height
    expect[invalid & (expect > 0)] = np.inf
    assert np.array_equal(pit, expect)
    assert (pit[~invalid] > 0.04).any()  # there are basins


def test_components_label_as_opencv_default() -> None:
    # components() asks OpenCV for its BBDT labelling: the same labels, numbering and stats
    # as the default, on blobs, noise, boxes and odd sizes.
    rng = np.random.default_rng(3)
    for i in range(400):
        hh, ww = int(rng.integers(1, 130)), int(rng.integers(1, 170))
        if i % 3 == 0:
            mask = rng.random((hh, ww)) < rng.random()
        elif i % 3 == 1:
            noise = rng.random((hh, ww)).astype(np.float32)
            mask = cv2.GaussianBlur(noise, (0, 0), float(rng.uniform(0.5, 5.0))) > 0.5
        else:
            mask = np.zeros((hh, ww), bool)
            for _ in range(int(rng.integers(0, 10))):
                y, x, r = (
                    int(rng.integers(0, hh)),
                    int(rng.integers(0, ww)),
                    int(rng.integers(1, 20)),
                )
                mask[max(0, y - r) : y + r, max(0, x - r) : x + r] = True
        n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
        got = components(mask)
        assert got[0] == n and np.array_equal(got[1], lab) and np.array_equal(got[2], stats)


def _banded(depth: np.ndarray, ltrb: tuple[int, int, int, int]) -> np.ndarray:
    """A registered structured-light frame's unread border bands."""
    left, top, right, bottom = ltrb
    out = depth.copy()
    out[:, :left], out[:top], out[:, 640 - right :], out[480 - bottom :] = 0, 0, 0, 0
    return out


@pytest.mark.parametrize("floor_m", [3.7, 5.0])  # a read floor 0.9 m down; a void
def test_hole_running_under_the_unread_band_is_cut_not_open(floor_m: float) -> None:
    # The opening runs from u = 527 to past the frame's edge; the right band (36 px) hides
    # its last 77 px: its rim there is unknown, its box runs to the frame's edge.
    rgb, depth, boxes = scene(holes=((610, 250, 0.6, 0.8, floor_m),))
    depth = _banded(depth, (4, 10, 36, 8))
    d = top(detect_holes(rgb, depth, CAM))
    x, y, _, h = boxes[0]
    clipped = (x, y, 640.0 - x, h)
    assert d.border_cut and d.box[0] + d.box[2] == 640
    assert iou(d.box, clipped) > 0.75
    assert d.p_hole is not None and d.p_hole > 0.5  # its width is not the visible part's
    assert d.rim_seen is not None and d.rim_seen < 0.9
    inside = top(detect_holes(*scene(holes=((320, 250, 0.6, 0.8, floor_m),))[:2], CAM))
    assert not inside.border_cut


def _px_hole(
    x0: int, y0: int, x1: int, y1: int, floor_m: float, z0: float = 2.8
) -> tuple[float, float, float, float, float]:
    """A :func:`scene` hole given by its pixel box on a floor at ``z0``."""
    return ((x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) * z0 / F, (y1 - y0) * z0 / F, floor_m)


@pytest.mark.parametrize("floor_m", [3.7, 5.0])  # a read floor 0.9 m down; a void
@pytest.mark.parametrize("edges", [(201, 117, 341, 263), (155, 302, 421, 415)])
def test_box_is_the_openings_to_the_pixel(floor_m: float, edges: tuple[int, int, int, int]) -> None:
    # An opening whose edges lie off the 4 px work grid (pixels x0 .. x1 - 1 wide open):
    # the box is the opening's to a pixel, not its work blocks' (the blocks at its edge
    # read a few of their pixels, so they count as rim and the work grid's box is up to
    # 3 px short on each side).
    x0, y0, x1, y1 = edges
    rgb, depth, _ = scene(holes=(_px_hole(x0 - 0.5, y0 - 0.5, x1 - 0.5, y1 - 0.5, floor_m),))
    hole = depth > 3300 if floor_m < 4.0 else depth == 0
    vs, us = np.nonzero(hole)
    truth = (int(us.min()), int(vs.min()), int(us.max()) + 1, int(vs.max()) + 1)
    assert truth == edges
    bx, by, bw, bh = top(detect_holes(rgb, depth, CAM)).box
    assert max(abs(a - b) for a, b in zip((bx, by, bx + bw, by + bh), truth, strict=True)) <= 1
    grid = replace(DEFAULT, options=replace(DEFAULT.options, pixel_boxes=False))
    gx, gy, gw, gh = top(detect_holes(rgb, depth, CAM, grid)).box
    assert max(abs(a - b) for a, b in zip((gx, gy, gx + gw, gy + gh), truth, strict=True)) >= 2


def test_refined_box_stays_within_reach_and_the_read_area() -> None:
    # The opening runs on 30 px beyond the region it was found as: the box follows it by
    # at most ``reach``; and never into the unread band beside it.
    cam = CameraIntrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    depth = np.full((48, 64), 2000, np.uint16)
    depth[10:30, 10:50] = 0  # the opening, unread
    depth[:, 56:] = 0  # an unread band on the right
    region = np.ones((20, 10), bool)  # found as x 20 .. 29 only
    plane = (np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 2.0]))
    assert refine_box(region, (20, 10), depth, cam, plane, 4) == (16, 10, 34, 30)
    assert refine_box(region, (20, 10), depth, cam, plane, 40, (0, 0, 56, 48)) == (10, 10, 50, 30)
    depth[10:30, 10:50] = 2600  # read, 0.6 m behind the rim plane
    assert refine_box(region, (20, 10), depth, cam, plane, 40) == (10, 10, 50, 30)
    depth[10:30, 10:50] = 2010  # on the plane, within the depth noise: no opening
    assert refine_box(region, (20, 10), depth, cam, plane, 4) is None


def test_hole_in_a_depression_the_border_cuts_is_the_hole_not_the_depression() -> None:
    # A depression 0.5 m deep running into the right border, a void inside it with 30 px
    # of the depression's floor (read) between it and the border: the basin closed across
    # the border holds the void and scores higher, but it is the depression around the
    # hole, its depth measured against a rim assumed at the border.
    depression, void = _px_hole(300, 170, 640, 370, 3.3), _px_hole(330, 200, 610, 340, 5.0)
    rgb, depth, boxes = scene(holes=(depression, void))
    d = top(detect_holes(rgb, depth, CAM))
    assert not d.border_cut
    assert iou(d.box, boxes[1]) > 0.8
    by_score = replace(DEFAULT, options=replace(DEFAULT.options, seen_rim_first=False))
    assert top(detect_holes(rgb, depth, CAM, by_score)).border_cut


def test_hole_the_border_cuts_keeps_its_box_over_its_unread_part() -> None:
    # A hole with a read floor 0.9 m down cut by the right border, its unread middle
    # reaching to 8 px from the border: the hole is the bridged basin, box to the border.
    hole, void = _px_hole(480, 170, 640, 370, 3.7), _px_hole(500, 190, 632, 350, 5.0)
    rgb, depth, boxes = scene(holes=(hole, void))
    d = top(detect_holes(rgb, depth, CAM))
    assert d.border_cut and d.box[0] + d.box[2] == 640
    assert iou(d.box, boxes[0]) > 0.8


def test_projector_shadow_line_joining_a_hole_does_not_stretch_its_box() -> None:
    # A void with a line of no reading 4 px wide (a nearer edge's projector shadow) running
    # 200 px from its side across the floor: the same region, not a wider opening.
    rgb, depth, boxes = scene(holes=((240, 240, 0.7, 0.7, 5.0),))
    x, y, w, h = (round(v) for v in boxes[0])
    depth[y + h // 2 : y + h // 2 + 4, x + w - 2 : x + w + 200] = 0
    d = top(detect_holes(rgb, depth, CAM))
    assert iou(d.box, boxes[0]) > 0.8
    # Without the trim, the box is still the hole's: the line is as lit as the rubble,
    # no part of the void's dark box (dark_box); without both, the line stretches it.
    kept = replace(DEFAULT, options=replace(DEFAULT.options, trim_spurs=False))
    assert iou(top(detect_holes(rgb, depth, CAM, kept)).box, boxes[0]) > 0.8
    kept = replace(kept, options=replace(kept.options, dark_box=False))
    assert iou(top(detect_holes(rgb, depth, CAM, kept)).box, boxes[0]) < 0.6


@pytest.mark.parametrize("floor_m", [3.7, 5.0])  # a read floor 0.9 m down; a void
@pytest.mark.parametrize("centre", [(60, 60), (600, 430), (40, 420)])
def test_hole_in_a_corner_is_cut_there_not_open(floor_m: float, centre: tuple[int, int]) -> None:
    # Cut by two sides of the read area (a corner, bands on): its dip runs into the end of
    # both border lines, closed there at the rim on its one side.
    rgb, depth, boxes = scene(holes=((*centre, 0.7, 0.6, floor_m),))
    depth = _banded(depth, (4, 10, 36, 8))
    x, y, w, h = boxes[0]
    x0, y0 = max(x, 0.0), max(y, 0.0)
    clipped = (x0, y0, min(x + w, 640.0) - x0, min(y + h, 480.0) - y0)
    d = top(detect_holes(rgb, depth, CAM))
    assert d.border_cut and iou(d.box, clipped) > 0.85
    assert d.p_hole is not None and d.p_hole > 0.5


def test_terrain_sloping_down_into_a_corner_is_not_closed_there() -> None:
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    z = 2.2 + 0.004 * np.hypot(640 - u, 480 - v)  # 0.9 m deeper toward the top-left
    rgb = np.full((480, 640, 3), 100, np.uint8)
    depth = _banded(np.round(z * 1000).astype(np.uint16), (4, 10, 36, 8))
    assert detect_holes(rgb, depth, CAM) == []


def test_range_fade_is_not_a_hole() -> None:
    # A floor tilting away until it passes the sensor's range: no reading at the far side.
    rgb, depth, _ = scene(z0=3.0)
    v = np.mgrid[0:480, 0:640][0]
    far = 3.0 + (480 - v) * 0.004  # up to 4.9 m at the top of the image
    depth = np.where(far < 4.0, np.round(far * 1000), 0).astype(np.uint16)
    assert detect_holes(rgb, depth, CAM) == []


def test_darkness_and_contrast_explain() -> None:
    rgb, depth, boxes = scene(holes=((320, 240, 1.0, 0.8, 5.0),))
    x, y, w, h = (int(v) for v in boxes[0])
    rgb[y : y + h, x : x + w] = 10
    d = top(detect_holes(rgb, depth, CAM))
    assert d.features.darkness == pytest.approx(1 - (10 / 255) / 0.274, abs=0.05)
    assert d.features.contrast > 0.2
    assert "deep" in d.explain()


def test_block_depth_ignores_missing_readings() -> None:
    d = np.full((8, 8), 2000, np.uint16)
    d[0, 0] = 0
    d[4:, 4:] = 0
    z, frac = block_depth(d, 4, 0.001)
    assert z[0, 0] == pytest.approx(2.0)
    assert frac[0, 0] == pytest.approx(15 / 16)
    assert np.isnan(z[1, 1])


def test_basin_depth_of_a_pit_and_a_tilted_plane() -> None:
    v, u = np.mgrid[0:40, 0:50].astype(np.float32)
    plane = 2.0 + 0.01 * u + 0.02 * v
    pit, _, _ = basin_depth(plane)
    assert float(np.abs(pit).max()) < 1e-5
    plane[10:20, 10:20] += 0.7
    pit, _, _ = basin_depth(plane)
    # Below the lowest rim point (u = v = 20: 0.05 + 0.10 m farther than the centre's plane).
    assert float(pit[15, 15]) == pytest.approx(0.7 - 0.01 * 5 - 0.02 * 5, abs=1e-5)


def test_opening_axes_on_a_tilted_plane() -> None:
    # A 1 m x 1 m square on a plane tilted 30 deg about the camera's x axis, 3 m away.
    cam = CAM.scaled(0.25)
    tilt = np.deg2rad(30)
    normal = np.array([0.0, -np.sin(tilt), np.cos(tilt)])
    e1, e2 = np.array([1.0, 0, 0]), np.cross(normal, [1.0, 0, 0])
    centre = np.array([0.0, 0.0, 3.0])
    s = np.linspace(-0.5, 0.5, 60)
    a, b = np.meshgrid(s, s)
    pts = centre + a.reshape(-1, 1) * e1 + b.reshape(-1, 1) * e2
    uv = np.stack(
        [pts[:, 0] / pts[:, 2] * cam.fx + cam.cx, pts[:, 1] / pts[:, 2] * cam.fy + cam.cy]
    )
    mask = np.zeros((cam.height, cam.width), bool)
    mask[np.round(uv[1]).astype(int), np.round(uv[0]).astype(int)] = True
    big = np.linspace(-0.8, 0.8, 120)
    a2, b2 = np.meshgrid(big, big)
    keep = (np.abs(a2) > 0.55) | (np.abs(b2) > 0.55)
    rim = centre + a2[keep].reshape(-1, 1) * e1 + b2[keep].reshape(-1, 1) * e2
    ru, rv = rim[:, 0] / rim[:, 2] * cam.fx + cam.cx, rim[:, 1] / rim[:, 2] * cam.fy + cam.cy
    iv, iu = np.nonzero(mask)
    major, minor, area, _ = opening_axes(
        (iu.astype(float), iv.astype(float)), (ru, rv, rim[:, 2]), cam
    )
    assert area == pytest.approx(1.0, rel=0.1)
    side = 4 / np.sqrt(12)
    assert major == pytest.approx(side, rel=0.1)
    assert minor == pytest.approx(side, rel=0.1)


@pytest.mark.parametrize(
    ("rgb", "depth", "message"),
    [
        (np.zeros((480, 640), np.uint8), np.ones((480, 640), np.uint16), "rgb must be"),
        (np.zeros((480, 640, 3), np.float32), np.ones((480, 640), np.uint16), "uint8"),
        (np.zeros((480, 640, 3), np.uint8), np.ones((480, 640), np.uint8), "uint16"),
        (np.zeros((480, 640, 3), np.uint8), np.ones((480, 640), np.float32), "uint16"),
        (np.zeros((240, 320, 3), np.uint8), np.ones((240, 320), np.uint16), "camera"),
        (np.zeros((480, 640, 3), np.uint8), np.zeros((480, 640), np.uint16), "no reading"),
        (np.zeros((480, 640, 3), np.uint8), np.ones((480, 600), np.uint16), "differ"),
    ],
)
def test_bad_input_is_a_clear_error(rgb: np.ndarray, depth: np.ndarray, message: str) -> None:
    with pytest.raises(InputError, match=message):
        detect_holes(rgb, depth, CAM)


def test_box_of_a_void_is_its_dark_part_not_the_lit_unread_area_beside_it() -> None:
    # A void (dark inside) running into an unread area as lit as the rubble (a speckled far
    # field, a bright surface that returns nothing): one unread region, but the hole's box
    # is the dark part's.
    void, lit = _px_hole(200, 150, 330, 300, 5.0), _px_hole(330, 100, 390, 350, 5.0)
    rgb, depth, boxes = scene(holes=(void, lit))
    rgb[100:350, 330:390] = 110
    d = top(detect_holes(rgb, depth, CAM))
    assert iou(d.box, boxes[0]) > 0.95
    whole = replace(DEFAULT, options=replace(DEFAULT.options, dark_box=False))
    assert iou(top(detect_holes(rgb, depth, CAM, whole)).box, boxes[0]) < 0.5
