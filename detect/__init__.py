"""Access-hole detection in one registered RGB-D frame (pure: arrays in, records out).

Two modes share one feature framework (depth, width, fill, darkness, contrast):
``PAPER`` reproduces Kong et al. (JFR 2015); ``DEFAULT`` is holescan's faster, more
accurate detector.
"""

from detect._scores import luminance, ramp
from detect._types import (
    DEFAULT,
    DOG,
    HUMAN,
    PAPER,
    ROBOT,
    SEARCHERS,
    CameraIntrinsics,
    DetectParams,
    Detection,
    FeatureScores,
    Mode,
    Searcher,
)

__all__ = [
    "DEFAULT",
    "DOG",
    "HUMAN",
    "PAPER",
    "ROBOT",
    "SEARCHERS",
    "CameraIntrinsics",
    "DetectParams",
    "Detection",
    "FeatureScores",
    "Mode",
    "Searcher",
    "luminance",
    "ramp",
]
