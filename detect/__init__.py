"""Access-hole detection in one registered RGB-D frame (pure: arrays in, records out).

Two modes share one feature framework (depth, width, fill, darkness, contrast):
``PAPER`` reproduces Kong et al. (JFR 2015); ``DEFAULT`` is holescan's faster, more
accurate detector.
"""

from holescan.detect._baseline import detect_baseline
from holescan.detect._calibration import logistic, p_hole_of_score
from holescan.detect._default import basin_labels, box_iou
from holescan.detect._detector import detect_holes
from holescan.detect._ers import ers_superpixels
from holescan.detect._evaluate import (
    GroundTruthBox,
    PRResult,
    ScoredBox,
    evaluate_detections,
    match_image,
)
from holescan.detect._frame import Frame, FrameSource
from holescan.detect._options import DefaultOptions
from holescan.detect._paper import detect_paper, paper_superpixels
from holescan.detect._regions import BAND_MAX_PX, unread_bands
from holescan.detect._scores import combined_score, luminance, ramp
from holescan.detect._surface import PLANE_VERDICTS, PlaneVerdict, plane_verdict
from holescan.detect._types import (
    DEFAULT,
    DOG,
    HUMAN,
    PAPER,
    ROBOT,
    SEARCHERS,
    CameraIntrinsics,
    Detection,
    DetectParams,
    FeatureScores,
    Mode,
    Searcher,
)

__all__ = [
    "BAND_MAX_PX",
    "DEFAULT",
    "DOG",
    "HUMAN",
    "PAPER",
    "PLANE_VERDICTS",
    "ROBOT",
    "SEARCHERS",
    "CameraIntrinsics",
    "DefaultOptions",
    "DetectParams",
    "Detection",
    "FeatureScores",
    "Frame",
    "FrameSource",
    "GroundTruthBox",
    "Mode",
    "PRResult",
    "PlaneVerdict",
    "ScoredBox",
    "Searcher",
    "basin_labels",
    "box_iou",
    "combined_score",
    "detect_baseline",
    "detect_holes",
    "detect_paper",
    "ers_superpixels",
    "evaluate_detections",
    "logistic",
    "luminance",
    "match_image",
    "p_hole_of_score",
    "paper_superpixels",
    "plane_verdict",
    "ramp",
    "unread_bands",
]
