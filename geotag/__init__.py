"""Geotagging (pure): detections + camera + vehicle pose -> hole positions; merging sightings."""

from holescan.geotag._announce import AnnouncePolicy, HoleNews, Told
from holescan.geotag._camera import (
    CameraMount,
    GimbalAttitude,
    dcm_from_euler,
    dcm_from_quaternion,
    rotation_ned_from_optical,
    unit_quaternion,
)
from holescan.geotag._campose import R_ENU_NED, LocalCameraPose, camera_pose_local
from holescan.geotag._confidence import (
    DEFAULT_CONFIDENCE,
    ConfidenceModel,
    HoleEvidence,
    evidence_of,
    viewpoint_of,
)
from holescan.geotag._ids import IdMap, carry_ids, same_opening_gate_m
from holescan.geotag._local import LocalFrame, local_en_m
from holescan.geotag._matching import nearest_pairs
from holescan.geotag._merge import Hole, HoleTracker, MergeParams
from holescan.geotag._pipeline import (
    BestViews,
    FrameHoles,
    HolePipeline,
    HoleView,
    PoseOf,
    crop_view,
    view_jpeg,
)
from holescan.geotag._project import (
    CIRCLE_95_PER_SIGMA,
    ErrorModel,
    HoleSighting,
    box_cut_by_border,
    geotag_detection,
    geotag_frame,
    project_to_pixel,
)
from holescan.geotag._tiers import (
    FOUND_TIERS,
    HOLE_TIERS,
    TIERS,
    VEHICLE_TIERS,
    AnnounceGate,
    HoleTier,
    Tier,
    VehicleTier,
    holes_found,
)
from holescan.geotag._types import VehiclePose

__all__ = [
    "CIRCLE_95_PER_SIGMA",
    "DEFAULT_CONFIDENCE",
    "FOUND_TIERS",
    "HOLE_TIERS",
    "R_ENU_NED",
    "TIERS",
    "VEHICLE_TIERS",
    "AnnounceGate",
    "AnnouncePolicy",
    "BestViews",
    "CameraMount",
    "ConfidenceModel",
    "ErrorModel",
    "FrameHoles",
    "GimbalAttitude",
    "Hole",
    "HoleEvidence",
    "HoleNews",
    "HolePipeline",
    "HoleSighting",
    "HoleTier",
    "HoleTracker",
    "HoleView",
    "IdMap",
    "LocalCameraPose",
    "LocalFrame",
    "MergeParams",
    "PoseOf",
    "Tier",
    "Told",
    "VehiclePose",
    "VehicleTier",
    "box_cut_by_border",
    "camera_pose_local",
    "carry_ids",
    "crop_view",
    "dcm_from_euler",
    "dcm_from_quaternion",
    "evidence_of",
    "geotag_detection",
    "geotag_frame",
    "holes_found",
    "local_en_m",
    "nearest_pairs",
    "project_to_pixel",
    "rotation_ned_from_optical",
    "same_opening_gate_m",
    "unit_quaternion",
    "view_jpeg",
    "viewpoint_of",
]
