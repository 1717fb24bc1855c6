"""p_hole: the calibrated probability, the table it interpolates, and its evaluation."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from detect import GroundTruthBox, ScoredBox, evaluate_detections, p_hole_of_score
from detect._calibration import apply_table
from detect._calibration_table import P_HOLE_TABLE
from ground import brier_score, calibration_outcomes


def test_table_is_monotone_and_never_certain() -> None:
    xs = [k[0] for k in P_HOLE_TABLE]
    ps = [k[1] for k in P_HOLE_TABLE]
    assert xs[0] == 0.0 and xs[-1] == 1.0
    assert all(b > a for a, b in itertools.pairwise(xs))
    assert all(b >= a for a, b in itertools.pairwise(ps))
    assert min(ps) > 0.0 and max(ps) < 1.0


def test_p_hole_is_monotone_in_the_score() -> None:
    scores = np.linspace(0, 1, 201)
    p = [p_hole_of_score(float(s)) for s in scores]
    assert all(b >= a for a, b in itertools.pairwise(p))
    assert p_hole_of_score(-1.0) == p[0] and p_hole_of_score(2.0) == p[-1]


def test_apply_table_interpolates_linearly() -> None:
    table = ((0.0, 0.0), (0.5, 0.2), (1.0, 1.0))
    assert apply_table(table, 0.25) == pytest.approx(0.1)
    assert apply_table(table, 0.75) == pytest.approx(0.6)


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
