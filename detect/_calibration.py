"""``p_hole``: the default detector's score mapped to a probability of a true access hole.

The raw score ranks detections well but is no probability (true holes 0.5-0.9, false ones up
to 0.5 in a simulated flight). Isotonic regression of "is a true access hole" (IoU > 0.5)
on the raw score, fitted on a calibration split of three independently generated sets of
scenes, gives a monotone table of knots; ``p_hole`` interpolates it linearly. The table is a
few numbers in :mod:`detect._calibration_table` (refit with ``python
benchmarks/calibrate.py``), so the flight computer needs no scikit-learn at run time and the
fit is plain to read and to diff. Ranking is unchanged (monotone map), so AP is too.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from detect._calibration_table import P_HOLE_TABLE


def apply_table(table: Sequence[tuple[float, float]], score: float) -> float:
    """Piecewise-linear interpolation of ``table`` knots ``(score, p)`` at ``score``."""
    xs = [k[0] for k in table]
    ps = [k[1] for k in table]
    return float(np.clip(np.interp(score, xs, ps), 0.0, 1.0))


def p_hole_of_score(score: float) -> float:
    """Probability that a default-mode detection with raw ``score`` is a true access hole."""
    return apply_table(P_HOLE_TABLE, score)
