"""p_hole: the calibrated probability, its fit, and its evaluation."""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest

from holescan.detect import GroundTruthBox, ScoredBox, evaluate_detections, p_hole_of_score
from holescan.detect._calibration import logistic
from holescan.detect._calibration_table import P_HOLE_LOGISTIC
from holescan.ground import brier_score, calibration_outcomes

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from calibrate import isotonic, platt


def test_p_hole_is_monotone_bounded_and_never_certain() -> None:
    assert P_HOLE_LOGISTIC[0] > 0
    scores = np.linspace(-0.5, 1.5, 401)
    p = [p_hole_of_score(float(s)) for s in scores]
    assert all(b >= a for a, b in itertools.pairwise(p))
    assert min(p) == pytest.approx(0.01) and max(p) == pytest.approx(0.99)


def test_logistic_by_hand() -> None:
    assert logistic((2.0, -1.0), 0.5) == pytest.approx(0.5)
    assert logistic((2.0, -1.0), 1.0) == pytest.approx(1 / (1 + np.exp(-1.0)))


def test_platt_recovers_a_known_logistic() -> None:
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, 20000)
    y = (rng.uniform(0, 1, x.size) < 1 / (1 + np.exp(-(8.0 * x - 3.0)))).astype(float)
    a, b = platt(x, y)
    assert a == pytest.approx(8.0, rel=0.1)
    assert b == pytest.approx(-3.0, rel=0.1)


def test_isotonic_pools_adjacent_violators() -> None:
    bx, bp, bn = isotonic(np.array([0.1, 0.2, 0.3, 0.4]), np.array([0, 1, 0, 1]))
    assert list(bp) == [0.0, 0.5, 1.0]
    assert list(bn) == [1, 2, 1]
    assert bx[1] == pytest.approx(0.25)


def test_calibration_outcomes_and_brier_score() -> None:
    gt = [GroundTruthBox(1, (0, 0, 10, 10)), GroundTruthBox(2, (0, 0, 10, 10))]
    dets = [
        ScoredBox(1, (0, 0, 10, 10), 0.9),  # true
        ScoredBox(1, (50, 50, 10, 10), 0.8),  # false
        ScoredBox(2, (1, 0, 10, 10), 0.3),  # true
    ]
    result = evaluate_detections(dets, gt, "iou")
    p, is_true = calibration_outcomes(result)
    assert list(is_true) == [1.0, 0.0, 1.0]
    assert list(p) == [p_hole_of_score(s) for s in (0.9, 0.8, 0.3)]
    assert brier_score(np.array([1.0, 0.0]), np.array([1.0, 0.0])) == 0.0
    assert brier_score(np.array([0.5, 0.5]), np.array([1.0, 0.0])) == pytest.approx(0.25)
