"""``p_hole``: the default detector's score mapped to a probability of a true access hole.

The raw score ranks detections well but is no probability (true holes 0.5-0.9, false ones up
to 0.5 in a simulated flight). Platt scaling, a logistic curve of "is a true access hole"
(IoU > 0.5) on the raw score fitted on a calibration split of three independently generated
sets of scenes, maps it to one. The fit is two numbers in :mod:`detect._calibration_table`
(refit with ``python benchmarks/calibrate.py``), so the flight computer needs no
scikit-learn at run time and the fit is plain to read and to diff. Probabilities are kept
within [0.01, 0.99]: nothing the detector sees makes it certain. Ranking is unchanged
(monotone map), so AP is too.
"""

from __future__ import annotations

import numpy as np

from holescan.detect._calibration_table import P_HOLE_LOGISTIC

P_MIN = 0.01


def logistic(coef: tuple[float, float], score: float) -> float:
    """``1 / (1 + exp(-(a score + b)))`` for ``coef = (a, b)``, kept within [0.01, 0.99]."""
    a, b = coef
    return float(np.clip(1.0 / (1.0 + np.exp(-(a * score + b))), P_MIN, 1.0 - P_MIN))


def p_hole_of_score(score: float) -> float:
    """Probability that a default-mode detection with raw ``score`` is a true access hole.

    Examples
    --------
    >>> p_hole_of_score(0.05) < 0.1 < 0.9 < p_hole_of_score(0.8)
    True
    """
    return logistic(P_HOLE_LOGISTIC, score)
