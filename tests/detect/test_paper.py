"""Paper mode (Kong et al. 2015): feature scores on tiny scenes with known answers, and
the whole pipeline (ERS + scoring) on synthetic floors with a pit."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from holescan.detect import PAPER, CameraIntrinsics, Detection, detect_holes
from holescan.detect._paper import INVALID_DEPTH_M, detect_paper, paper_superpixels, score_regions
from holescan.errors import InputError

# A 80 x 60 camera with f = 100 px: a pixel at depth Z spans Z / 100 metres.
CAM = CameraIntrinsics(width=80, height=60, fx=100.0, fy=100.0, cx=39.5, cy=29.5)
ROWS, COLS = slice(20, 32), slice(30, 50)  # the pit: 12 rows x 20 columns
HUMAN = PAPER.searcher


def _scene(
    floor_mm: int = 1500, pit_mm: int = 2500, floor_grey: int = 120, pit_grey: int = 40
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat floor (label 0) with a rectangular pit (label 1); returns labels, rgb, depth."""
    labels = np.zeros((60, 80), np.int32)
    labels[ROWS, COLS] = 1
    depth = np.full((60, 80), floor_mm, np.uint16)
    depth[ROWS, COLS] = pit_mm
    rgb = np.full((60, 80, 3), floor_grey, np.uint8)
    rgb[ROWS, COLS] = pit_grey
    return labels, rgb, depth


def _only(detections: list[Detection]) -> Detection:
    assert len(detections) == 1
    return detections[0]


def _ramp(x: float, lo: float, hi: float) -> float:
    return min(1.0, max(0.0, (x - lo) / (hi - lo)))


def _grid_axis(n: int, pitch: float) -> float:
    """Moment-ellipse axis of ``n`` evenly spaced samples: 4 standard deviations."""
    return 4.0 * pitch * math.sqrt((n * n - 1) / 12.0)


def test_depth_score_from_known_depth_difference() -> None:
    det = _only(score_regions(*_scene(), CAM))
    assert det.depth_rel_m == pytest.approx(1.0)
    assert det.features.depth == pytest.approx((1.0 - 0.200) / (1.951 - 0.200))
    assert det.rim_depth_m == pytest.approx(1.5)
    assert det.beyond_range is False
    assert det.box == (30, 20, 20, 12)


def test_depth_score_saturates_and_vanishes_at_the_thresholds() -> None:
    deep = _only(score_regions(*_scene(floor_mm=1000, pit_mm=3200), CAM))
    shallow = _only(score_regions(*_scene(floor_mm=1000, pit_mm=1150), CAM))
    assert deep.features.depth == 1.0
    assert shallow.features.depth == 0.0
    assert shallow.depth_rel_m == pytest.approx(0.15)


def test_width_and_fill_from_known_metric_size() -> None:
    det = _only(score_regions(*_scene(), CAM))
    pitch = 2.5 / CAM.fx  # pit floor at 2.5 m
    major, minor = _grid_axis(20, pitch), _grid_axis(12, pitch)
    assert det.major_m == pytest.approx(major, rel=1e-9)
    assert det.minor_m == pytest.approx(minor, rel=1e-9)
    expected_width = min(
        _ramp(major, 0.5 * HUMAN.major_m, HUMAN.major_m),
        _ramp(minor, 0.5 * HUMAN.minor_m, HUMAN.minor_m),
    )
    assert 0.0 < expected_width < 1.0
    assert det.features.width == pytest.approx(expected_width, rel=1e-9)
    # region area (240 pixels of pitch^2) over the axes' box
    assert det.features.fill == pytest.approx(240 * pitch**2 / (major * minor), rel=1e-9)


def test_width_score_is_one_for_a_man_sized_opening() -> None:
    det = _only(score_regions(*_scene(floor_mm=3000, pit_mm=4000), CAM))
    assert det.major_m > HUMAN.major_m
    assert det.minor_m > HUMAN.minor_m
    assert det.features.width == 1.0


def test_darkness_and_contrast_from_known_luminance() -> None:
    det = _only(score_regions(*_scene(floor_grey=120, pit_grey=40), CAM))
    y_pit, y_floor = 40 / 255, 120 / 255
    assert det.features.darkness == pytest.approx(1.0 - y_pit / 0.274, rel=1e-5)
    assert det.features.contrast == pytest.approx((y_floor - y_pit) / (0.267 + 0.091), rel=1e-5)
    bright = _only(score_regions(*_scene(floor_grey=200, pit_grey=180), CAM))
    assert bright.features.darkness == 0.0
    assert bright.features.contrast == pytest.approx((20 / 255) / 0.358, rel=1e-5)
    lighter_than_rim = _only(score_regions(*_scene(floor_grey=40, pit_grey=60), CAM))
    assert lighter_than_rim.features.contrast == 0.0


def test_score_is_the_weighted_sum_of_the_features() -> None:
    det = _only(score_regions(*_scene(), CAM))
    assert det.score == pytest.approx(sum(det.features.as_tuple()) / 5.0)
    depth_only = replace(PAPER, weights=(1.0, 0.0, 0.0, 0.0, 0.0), bias=0.1)
    det2 = _only(score_regions(*_scene(), CAM, depth_only))
    assert det2.score == pytest.approx(det.features.depth + 0.1)
    clipped = replace(PAPER, weights=(1.0, 1.0, 1.0, 1.0, 1.0))
    assert _only(score_regions(*_scene(), CAM, clipped)).score == 1.0


def test_candidate_on_the_border_scores_zero_but_is_reported() -> None:
    labels, rgb, depth = _scene()
    labels[:] = 0
    labels[20:32, 0:20] = 1
    depth[:] = 1500
    depth[20:32, 0:20] = 2500
    det = _only(score_regions(labels, rgb, depth, CAM))
    assert det.score == 0.0
    assert det.features.depth > 0.0
    assert det.box == (0, 20, 20, 12)


def test_only_local_depth_maxima_are_candidates() -> None:
    labels, rgb, depth = _scene(floor_mm=2000, pit_mm=1500)  # a raised block
    # the block is no candidate; the floor around it is (deeper than its one neighbour)
    # but touches the border
    floor = _only(score_regions(labels, rgb, depth, CAM))
    assert floor.box == (0, 0, 80, 60)
    assert floor.score == 0.0
    labels, rgb, depth = _scene(floor_mm=2000, pit_mm=2000)  # level: not deeper
    assert score_regions(labels, rgb, depth, CAM) == []


def test_depth_difference_is_the_smallest_to_any_neighbour() -> None:
    labels, rgb, depth = _scene(pit_mm=3000)
    labels[:, 40:] = np.where(labels[:, 40:] == 1, 1, 2)  # right half: a second floor
    depth[:, 40:] = np.where(labels[:, 40:] == 1, 3000, 2500)
    det = _only(score_regions(labels, rgb, depth, CAM))
    assert det.depth_rel_m == pytest.approx(0.5)
    # rim: the valid readings of both neighbouring floors, pixel-weighted
    left, right = labels == 0, labels == 2
    rim = (1.5 * left.sum() + 2.5 * right.sum()) / (left.sum() + right.sum())
    assert det.rim_depth_m == pytest.approx(rim)


def test_pit_without_depth_readings_is_beyond_range() -> None:
    labels, rgb, depth = _scene(floor_mm=2000)
    depth[ROWS, COLS] = 0
    det = _only(score_regions(labels, rgb, depth, CAM))
    assert det.beyond_range is True
    assert det.depth_rel_m == pytest.approx(INVALID_DEPTH_M - 2.0)
    assert det.features.depth == 1.0
    # measured at the rim, 2 m away
    assert det.major_m == pytest.approx(_grid_axis(20, 2.0 / CAM.fx), rel=1e-9)
    assert det.minor_m == pytest.approx(_grid_axis(12, 2.0 / CAM.fx), rel=1e-9)


def test_outliers_beyond_three_sigma_do_not_stretch_the_ellipse() -> None:
    labels, rgb, depth = _scene()
    clean = _only(score_regions(labels, rgb, depth, CAM))
    depth[25, 40] = 9000  # one flying pixel far behind the pit floor
    noisy = _only(score_regions(labels, rgb, depth, CAM))
    assert noisy.major_m == pytest.approx(clean.major_m, rel=0.02)
    assert noisy.minor_m == pytest.approx(clean.minor_m, rel=0.02)


def _floor_with_pit(unread_pit: bool = False) -> tuple[np.ndarray, np.ndarray, CameraIntrinsics]:
    """120 x 160 Xtion frame: tilted noisy floor ~2 m, dark 40 x 50 px pit 1.5 m deeper."""
    rng = np.random.default_rng(11)
    v, _ = np.mgrid[0:120, 0:160]
    depth_mm = 2000.0 + 2.0 * (v - 60) + rng.normal(0.0, 4.0, v.shape)
    depth_mm[40:80, 60:110] += 1500.0
    depth = depth_mm.astype(np.uint16)
    if unread_pit:
        depth[40:80, 60:110] = 0
    rgb = np.clip(rng.normal(150, 15, (120, 160, 3)), 0, 255).astype(np.uint8)
    rgb[40:80, 60:110] //= 5
    return rgb, depth, CameraIntrinsics.xtion(160, 120)


def _iou(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> float:
    ix = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    inter = ix * iy
    return inter / (a[2] * a[3] + b[2] * b[3] - inter)


@pytest.mark.parametrize("unread_pit", [False, True])
def test_detect_paper_finds_a_big_deep_pit(unread_pit: bool) -> None:
    rgb, depth, cam = _floor_with_pit(unread_pit)
    detections = detect_paper(rgb, depth, cam, PAPER)
    best = detections[0]
    assert _iou(best.box, (60, 40, 50, 40)) >= 0.9
    assert best.score > 0.6
    assert best.beyond_range is unread_pit
    assert best.features.width == 1.0  # ~1 m x 0.8 m at 3.5 m
    assert best.features.darkness > 0.5
    assert best.features.contrast > 0.9
    assert best.rim_depth_m == pytest.approx(2.0, abs=0.1)
    if not unread_pit:
        assert best.depth_rel_m == pytest.approx(1.5, abs=0.1)
    assert all(d.score <= best.score for d in detections)
    assert detect_holes(rgb, depth, cam, PAPER) == detections


def test_paper_superpixels_rescale_depth_to_grey() -> None:
    _, depth, _ = _floor_with_pit()
    labels = paper_superpixels(depth, replace(PAPER, superpixels=13))
    assert np.array_equal(np.unique(labels), np.arange(13))
    # the pit's step is a superpixel boundary
    pit = np.zeros(labels.shape, bool)
    pit[40:80, 60:110] = True
    assert not set(np.unique(labels[pit])) & set(np.unique(labels[~pit]))


def test_bad_input_raises_input_error() -> None:
    rgb, depth, cam = _floor_with_pit()
    with pytest.raises(InputError, match="uint16"):
        detect_paper(rgb, depth.astype(np.float32), cam)
    with pytest.raises(InputError, match="uint8"):
        detect_paper(rgb.astype(np.uint16), depth, cam)
    with pytest.raises(InputError, match="camera size"):
        detect_paper(rgb, depth, CameraIntrinsics.xtion(320, 240))
    with pytest.raises(InputError, match="no reading"):
        detect_paper(rgb, np.zeros_like(depth), cam)
    with pytest.raises(InputError, match="between 1 and"):
        detect_paper(rgb, depth, cam, replace(PAPER, superpixels=0))
