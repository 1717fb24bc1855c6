"""Photometric evidence for regions without depth readings (the paper's Sb/Sc, made relative).

A region the Xtion gives no reading for is either depth beyond the sensor's range (a void:
the floor of a deep hole) or a surface the infrared pattern does not return from (sheet
metal, a puddle, specular plastic, a black wet stain). Depth cannot tell them apart; the
colour image can. Seen at dawn, a void is *darker than the rubble around it*: little sky
light reaches down a shaft. A returning-nothing surface is usually as bright as its
surroundings or brighter (it reflects the sky or the low sun), and often carries specular
highlights.

Absolute thresholds (the paper's Y < 0.274) fail under dawn exposure changes: a whole frame
can be dark, tinted or unevenly lit (vignetting, one side in the sun). Every measure here is
therefore *relative*: a pixel's luminance over the local luminance of the readable rubble
around it (normalised convolution over pixels that have depth, so the void's own darkness
does not lower its reference). 1 = as bright as the rubble nearby, 0.3 = a third as bright.
Scaling the whole frame (exposure) or one colour channel's gain (tint on luminance) leaves it
unchanged.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._scores import ramp

# Reference: Gaussian over readable pixels, sigma in work pixels (x4 at full resolution),
# wide enough to reach across the largest hole to its rim.
REFERENCE_SIGMA_PX = 12.0
# Evidence ramps from 1 (a void) at VOID_RATIO to 0 (a surface) at SURFACE_RATIO.
VOID_RATIO = 0.6
SURFACE_RATIO = 1.0


def relative_luminance(
    y: npt.NDArray[np.float64], readable: npt.NDArray[np.bool_]
) -> npt.NDArray[np.float64]:
    """Luminance over the local luminance of readable rubble, per pixel.

    y : (h, w) luminance in [0, 1]; readable : (h, w) pixels with a depth reading.

    Examples
    --------
    >>> y = np.full((40, 40), 0.5); y[15:25, 15:25] = 0.1
    >>> readable = np.ones((40, 40), bool); readable[15:25, 15:25] = False
    >>> rel = relative_luminance(y, readable)
    >>> round(float(rel[20, 20]), 2), round(float(rel[2, 2]), 2)
    (0.2, 1.0)
    >>> round(float(relative_luminance(3 * y, readable)[20, 20]), 2)  # exposure x3
    0.2
    """
    w = readable.astype(np.float32)
    num = cv2.GaussianBlur((y * w).astype(np.float32), (0, 0), REFERENCE_SIGMA_PX)
    den = cv2.GaussianBlur(w, (0, 0), REFERENCE_SIGMA_PX)
    ref = num / np.maximum(den, 1e-6)
    global_ref = float(np.mean(y[readable])) if readable.any() else float(np.mean(y))
    ref = np.where(den > 0.02, ref, global_ref)
    return (y / np.maximum(ref, 1e-3)).astype(np.float64)


def void_evidence(rel_in: float) -> float:
    """1 when a no-reading region looks like a void (dark against its rubble), 0 a surface.

    rel_in : median relative luminance (:func:`relative_luminance`) of its no-reading pixels.
    """
    return 1.0 - ramp(rel_in, VOID_RATIO, SURFACE_RATIO)
