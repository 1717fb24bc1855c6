"""A naive baseline for comparison: threshold depth against the frame's median.

Pixels deeper than the median depth by ``offset_m`` (or with no reading) form connected
components; each component larger than ``min_px`` is a detection scored by its mean
relative depth. No size, shape or brightness reasoning: it is the yardstick docs/detector.md
compares the paper's method and the default detector against.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._scores import ramp
from holescan.detect._types import CameraIntrinsics, Detection, FeatureScores
from holescan.detect._validate import check_frame


def detect_baseline(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    offset_m: float = 0.3,
    min_px: int = 400,
) -> list[Detection]:
    """Boxes around everything ``offset_m`` deeper than the median depth (see module doc)."""
    check_frame(rgb, depth, camera)
    z = depth.astype(np.float32) * camera.depth_unit_m
    valid = depth > 0
    median = float(np.median(z[valid]))
    far = float(z[valid].max())
    rel = np.where(valid, z - median, far - median)
    mask = ((rel > offset_m) | ~valid).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    dets = []
    for i in range(1, n):
        x, y, w, h, area = (int(v) for v in stats[i])
        if area < min_px:
            continue
        d = float(rel[labels == i].mean())
        sd = ramp(d, 0.2, 1.951)
        dets.append(
            Detection(
                box=(x, y, w, h),
                score=sd,
                features=FeatureScores(sd, 0.0, 0.0, 0.0, 0.0),
                depth_rel_m=d,
                major_m=0.0,
                minor_m=0.0,
                rim_depth_m=median,
                beyond_range=False,
            )
        )
    return sorted(dets, key=lambda d: -d.score)
