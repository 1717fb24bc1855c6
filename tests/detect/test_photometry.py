"""No-reading regions: a dark void is a hole, a bright no-return surface is not; cuts."""

from __future__ import annotations

import numpy as np
import pytest

from holescan.detect import DEFAULT, PAPER, CameraIntrinsics, Detection, detect_holes
from holescan.detect._photometry import relative_luminance, void_evidence

CAM = CameraIntrinsics.xtion()
F = CAM.fx


def textured_floor(seed: int = 0, level: float = 110.0) -> np.ndarray:
    """Rubble-like grey texture (blotches of +-30 grey levels) as an RGB image."""
    rng = np.random.default_rng(seed)
    import cv2

    noise = cv2.resize(rng.normal(0, 1, (30, 40)), (640, 480), interpolation=cv2.INTER_CUBIC)
    grey = np.clip(level + 30 * noise, 0, 255)
    return np.repeat(grey[..., None], 3, axis=2).astype(np.uint8)


def floor_with_unread_patch(
    patch_grey: float, z0: float = 2.8, wm: float = 1.0, hm: float = 0.7
) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]:
    """A floor at z0 with one unread rectangle (a void, or a no-return surface)."""
    v, u = np.mgrid[0:480, 0:640]
    w, h = wm * F / z0, hm * F / z0
    m = (np.abs(u - 320) < w / 2) & (np.abs(v - 240) < h / 2)
    depth = np.full((480, 640), round(z0 * 1000), np.uint16)
    depth[m] = 0
    rgb = textured_floor()
    rgb[m] = patch_grey
    return rgb, depth, (320 - w / 2, 240 - h / 2, w, h)


def score_of(dets: list[Detection]) -> float:
    return max((d.score for d in dets), default=0.0)


def test_relative_luminance_is_exposure_and_tint_invariant() -> None:
    rgb, depth, _ = floor_with_unread_patch(20)
    y = rgb[..., 1].astype(float) / 255
    readable = depth > 0
    rel = relative_luminance(y, readable)
    assert np.allclose(relative_luminance(0.25 * y, readable), rel, atol=1e-3)
    assert float(np.median(rel[~readable])) < 0.3
    assert float(np.median(rel[readable])) == pytest.approx(1.0, abs=0.1)


def test_void_evidence_ramps_from_dark_to_bright() -> None:
    assert void_evidence(0.2) == 1.0
    assert void_evidence(1.3) == 0.0
    assert 0.0 < void_evidence(0.8) < 1.0


@pytest.mark.parametrize("exposure", [1.0, 0.35])  # a normal frame and a dark dawn frame
def test_bright_no_return_surface_scores_below_a_dark_void(exposure: float) -> None:
    void_rgb, depth, _ = floor_with_unread_patch(15)
    metal_rgb, _, _ = floor_with_unread_patch(230)  # sheet metal / puddle: bright, no return
    void_rgb = (void_rgb * exposure).astype(np.uint8)
    metal_rgb = (metal_rgb * exposure).astype(np.uint8)
    void = detect_holes(void_rgb, depth, CAM)
    metal = detect_holes(metal_rgb, depth, CAM)
    assert void and void[0].relative_brightness is not None
    assert void[0].relative_brightness < 0.3
    assert score_of(void) > 0.5
    assert score_of(metal) < 0.5 * score_of(void)
    assert all(d.relative_brightness is None or d.relative_brightness > 1.0 for d in metal)


def test_tinted_light_changes_nothing() -> None:
    rgb, depth, _ = floor_with_unread_patch(15)
    tinted = (rgb * np.array([1.0, 0.8, 0.55])).astype(np.uint8)  # warm dawn cast
    a, b = detect_holes(rgb, depth, CAM), detect_holes(tinted, depth, CAM)
    assert [d.box for d in a] == [d.box for d in b]
    assert score_of(a) == pytest.approx(score_of(b), abs=0.03)


def test_hole_running_into_the_range_limit_dropout_is_cut_by_colour() -> None:
    # Floor tilting away: no reading in the top 120 rows (beyond range, brightly lit
    # rubble); a dark hole whose unread interior touches that band along its whole width.
    z0 = 2.8
    v, u = np.mgrid[0:480, 0:640]
    depth = np.where(v >= 120, 2800 + (480 - v), 0).astype(np.uint16)
    w, h = 1.0 * F / z0, 0.8 * F / z0
    hole = (np.abs(u - 320) < w / 2) & (v >= 118) & (v < 118 + h)
    depth[hole] = 0
    rgb = textured_floor()
    rgb[hole] = 15
    gt = (320 - w / 2, 118.0, w, h)
    dets = [d for d in detect_holes(rgb, depth, CAM) if d.score > 0.3]
    assert dets, "the hole is found"
    best = max(_iou(d.box, gt) for d in dets)
    assert best > 0.6


def test_hole_inside_a_broad_depression_is_boxed_alone() -> None:
    # A 2 m x 1.5 m depression 0.4 m deep holding a 0.9 m void: the box is the void's.
    z0 = 2.6
    v, u = np.mgrid[0:480, 0:640]
    depth = np.full((480, 640), z0 * 1000)
    dep = (np.abs(u - 320) < 1.0 * F / z0) & (np.abs(v - 240) < 0.75 * F / z0)
    depth[dep] += 400
    w, h = 0.9 * F / 3.0, 0.7 * F / 3.0
    hole = (np.abs(u - 300) < w / 2) & (np.abs(v - 250) < h / 2)
    depth[hole] = 0
    rgb = textured_floor()
    rgb[hole] = 15
    gt = (300 - w / 2, 250 - h / 2, w, h)
    dets = detect_holes(rgb, depth.astype(np.uint16), CAM)
    assert _iou(dets[0].box, gt) > 0.6


def test_p_hole_is_a_probability_in_default_mode_only() -> None:
    rgb, depth, _ = floor_with_unread_patch(15)
    dets = detect_holes(rgb, depth, CAM, DEFAULT)
    assert dets and all(d.p_hole is not None and 0.0 <= d.p_hole <= 1.0 for d in dets)
    assert "this frame's p_hole" in dets[0].explain()
    small = (rgb[::2, ::2].copy(), depth[::2, ::2].copy())
    paper = detect_holes(*small, CAM.scaled(0.5), PAPER)
    assert all(d.p_hole is None for d in paper)


def _iou(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    ix = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    return ix * iy / (a[2] * a[3] + b[2] * b[3] - ix * iy)
