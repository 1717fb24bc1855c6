"""Geotagging (pure): detections + camera + vehicle pose -> hole positions; merging sightings."""

from holescan.geotag._camera import (
    CameraMount,
    GimbalAttitude,
    dcm_from_euler,
    dcm_from_quaternion,
    rotation_ned_from_optical,
)
from holescan.geotag._campose import R_ENU_NED, LocalCameraPose, camera_pose_local
from holescan.geotag._local import LocalFrame, local_en_m
from holescan.geotag._matching import nearest_pairs
from holescan.geotag._merge import AnnounceGate, Hole, HoleTracker, MergeParams
from holescan.geotag._project import (
    CIRCLE_95_PER_SIGMA,
    ErrorModel,
    HoleSighting,
    geotag_detection,
    geotag_frame,
    project_to_pixel,
)
from holescan.geotag._types import VehiclePose

__all__ = [
    "CIRCLE_95_PER_SIGMA",
    "R_ENU_NED",
    "AnnounceGate",
    "CameraMount",
    "ErrorModel",
    "GimbalAttitude",
    "Hole",
    "HoleSighting",
    "HoleTracker",
    "LocalCameraPose",
    "LocalFrame",
    "MergeParams",
    "VehiclePose",
    "camera_pose_local",
    "dcm_from_euler",
    "dcm_from_quaternion",
    "geotag_detection",
    "geotag_frame",
    "local_en_m",
    "nearest_pairs",
    "project_to_pixel",
    "rotation_ned_from_optical",
]
