"""Small scoring helpers shared by both detector modes."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def ramp(x: float, low: float, high: float) -> float:
    """0 at or below ``low``, 1 at or above ``high``, linear between."""
    if high <= low:
        return 1.0 if x >= high else 0.0
    return float(min(1.0, max(0.0, (x - low) / (high - low))))


def luminance(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """Y of YUV (BT.601) in [0, 1] for an (H, W, 3) uint8 RGB image."""
    f = rgb.astype(np.float32)
    y = 0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2]
    out: npt.NDArray[np.float32] = (y / 255.0).astype(np.float32)
    return out


def darkness_score(mean_y: float, threshold: float) -> float:
    """Sb (prototype): ``1 - Y / threshold`` when ``Y <= threshold``, else 0."""
    return float(max(0.0, 1.0 - mean_y / threshold)) if threshold > 0 else 0.0


def contrast_score(region_y: float, neighbour_y: float, threshold: float) -> float:
    """Sc (prototype): (neighbours' Y - region's Y) / (threshold + 0.091), in [0, 1]."""
    return float(min(1.0, max(0.0, (neighbour_y - region_y) / (threshold + 0.091))))


def combined_score(
    sd: float, sw: float, sr: float, sb: float, sc: float, depth_exponent: float = 0.5
) -> float:
    """The default detector's score from the five attribute scores (each in [0, 1]).

    ``Sd^e * Sw * (0.35 + 0.65 Sr) * (0.85 + 0.15 max(Sb, Sc))`` with ``e`` =
    ``depth_exponent`` (0.5): geometry is necessary (no depth or no width, no hole), shape
    and light only refine it. The one place this formula is written.

    >>> round(combined_score(1.0, 1.0, 1.0, 0.0, 0.0), 2)
    0.85
    >>> combined_score(0.0, 1.0, 1.0, 1.0, 1.0)
    0.0
    """
    light = 0.85 + 0.15 * max(sb, sc)
    return float(sd**depth_exponent * sw * (0.35 + 0.65 * sr) * light)


def width_score(
    major_m: float,
    minor_m: float,
    need_major_m: float,
    need_minor_m: float,
    min_fraction: float = 0.5,
) -> float:
    """Sw: 1 when both axes reach the searcher's, 0 at ``min_fraction`` of either; linear."""
    a = ramp(major_m, min_fraction * need_major_m, need_major_m)
    b = ramp(minor_m, min_fraction * need_minor_m, need_minor_m)
    return min(a, b)
