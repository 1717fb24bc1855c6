"""Medians and percentiles of 1-D arrays: numpy's values, without numpy's per-call overhead.

``np.median`` and ``np.percentile`` spend 30-90 us a call on bookkeeping (axes, weights,
methods, NaN checks), and the default detector asks for several per candidate region. These
take the same partition and the same interpolation (``np.percentile``'s default "linear"
method, its rounding included), so they give the same value in the array's dtype:
``tests/detect/test_order_stats.py`` compares them with numpy over random arrays. Inputs
are non-empty and free of NaN (the detector's readings).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["median", "percentile"]


def median(values: npt.NDArray[np.floating[Any]]) -> np.floating[Any]:
    """``np.median(values)`` of a non-empty 1-D array without NaN.

    >>> float(median(np.array([3.0, 1.0, 2.0]))), float(median(np.array([4.0, 1.0, 2.0, 3.0])))
    (2.0, 2.5)
    """
    k = values.size // 2
    if values.size % 2:
        return np.partition(values, k)[k]  # type: ignore[no-any-return]
    return np.mean(np.partition(values, (k - 1, k))[k - 1 : k + 1])


def percentile(values: npt.NDArray[np.floating[Any]], q: float) -> np.floating[Any]:
    """``np.percentile(values, q)`` (linear interpolation) of a non-empty 1-D array without NaN.

    >>> float(percentile(np.array([1.0, 2.0, 3.0, 4.0]), 90))
    3.7
    """
    at = (values.size - 1) * (q / 100)
    if at >= values.size - 1:
        return np.partition(values, values.size - 1)[-1]  # type: ignore[no-any-return]
    lo = math.floor(at)
    part = np.partition(values, (lo, lo + 1))
    below, above = part[lo], part[lo + 1]
    gamma = at - lo
    step = above - below
    # numpy's lerp: from the nearer end, so that gamma 1 gives the upper value exactly.
    return (above - step * (1 - gamma)) if gamma >= 0.5 else (below + step * gamma)  # type: ignore[no-any-return]
