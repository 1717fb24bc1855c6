"""The camera's pose in local metres: where its optical centre is and which way it looks.

One function turns what geotagging takes for a frame (mount, vehicle pose) into a rigid
transform ENU <- optical in a :class:`LocalFrame`, for code that draws every pixel of a
frame into local metres (the rubble map) rather than one detection at a time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holescan.errors import InputError
from holescan.geotag._camera import (
    CameraMount,
    FloatArray,
    dcm_from_euler,
    rotation_ned_from_optical,
)
from holescan.geotag._local import LocalFrame
from holescan.geotag._types import VehiclePose

__all__ = ["R_ENU_NED", "LocalCameraPose", "camera_pose_local"]

#: ENU <- NED (swap north and east, flip down).
R_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True, eq=False)
class LocalCameraPose:
    """A camera's pose in a local east/north/up frame.

    rotation : (3, 3) float64 ndarray, ENU <- optical (columns: the image's x right, y down
        and optical axis written in east/north/up).
    position_m : (3,) float64 ndarray, the optical centre in east/north/up metres.
    """

    rotation: FloatArray
    position_m: FloatArray

    def __post_init__(self) -> None:
        r = np.array(self.rotation, dtype=np.float64)
        p = np.array(self.position_m, dtype=np.float64).reshape(-1)
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise InputError("camera rotation must be a finite 3x3 matrix (ENU <- optical)")
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise InputError("camera rotation must be a proper rotation (orthonormal, det +1)")
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError(f"camera position must be 3 finite metres, got {self.position_m!r}")
        r.flags.writeable = False
        p.flags.writeable = False
        object.__setattr__(self, "rotation", r)
        object.__setattr__(self, "position_m", p)


def camera_pose_local(frame: LocalFrame, mount: CameraMount, pose: VehiclePose) -> LocalCameraPose:
    """The camera's pose in ``frame`` for a vehicle ``pose`` (mount offset and gimbal included).

    Parameters
    ----------
    frame : the local east/north/up frame the result is in.
    mount : how the camera sits on the vehicle (and its gimbal's attitude, if any).
    pose : the vehicle's pose at the frame's time (altitude MSL, taken as the ellipsoid
        height as in :func:`geotag_detection`).

    Returns
    -------
    LocalCameraPose
    """
    r_ned_opt = rotation_ned_from_optical(mount, pose)
    offset_ned = dcm_from_euler(pose.roll, pose.pitch, pose.yaw) @ np.asarray(
        mount.offset_m, dtype=np.float64
    )
    e, n, u = frame.to_enu(pose.lat_deg, pose.lon_deg, pose.alt_m)
    position = np.array([float(e), float(n), float(u)]) + R_ENU_NED @ offset_ned
    return LocalCameraPose(R_ENU_NED @ r_ned_opt, position)
