"""Camera geometry: where the camera sits on the vehicle and which way it looks.

Frames (all right-handed):

* **optical**: x right in the image, y down in the image, z along the optical axis
  (as :class:`detect.CameraIntrinsics`).
* **camera FRD**: x along the optical axis, y image right, z image down. Mount and gimbal
  angles are given for this frame, so ``roll = pitch = yaw = 0`` is a camera looking along
  the vehicle's nose with the image upright, and ``pitch = -90 deg`` looks straight down
  with the image top towards the nose (MAVLink gimbal convention: pitch up is positive).
* **body FRD**: x forward (nose), y right, z down (MAVLink ATTITUDE).
* **NED**: north, east, down at the vehicle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from holescan.errors import InputError
from holescan.geotag._types import VehiclePose

__all__ = [
    "CameraMount",
    "GimbalAttitude",
    "dcm_from_euler",
    "dcm_from_quaternion",
    "rotation_ned_from_optical",
]

Matrix3 = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]
FloatArray = npt.NDArray[np.float64]

# Columns: the optical axes (x right, y down, z forward) expressed in camera FRD.
_FRD_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

# MAVLink GIMBAL_DEVICE_FLAGS bits that say which frame the attitude quaternion is in.
_YAW_LOCK = 16
_YAW_IN_VEHICLE_FRAME = 32
_YAW_IN_EARTH_FRAME = 64


def dcm_from_euler(roll: float, pitch: float, yaw: float) -> FloatArray:
    """Rotation matrix of ZYX (yaw, then pitch, then roll) Euler angles.

    Parameters
    ----------
    roll, pitch, yaw : float, radians (aerospace convention, as MAVLink ATTITUDE).

    Returns
    -------
    (3, 3) float64 ndarray ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``: maps vectors of the
    rotated frame into the reference frame (for a vehicle: NED <- body FRD).
    """
    return np.asarray(Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix(), np.float64)


def unit_quaternion(
    q_wxyz: tuple[float, float, float, float],
) -> tuple[float, float, float, float]:
    """The quaternion ``(w, x, y, z)`` scaled to unit length: the project's one normaliser
    (the MAVLink adapter's ATTITUDE_QUATERNION, the camera and gimbal rotations).

    Raises :class:`InputError` unless it is 4 finite numbers, not all (nearly) zero.

    >>> unit_quaternion((2.0, 0.0, 0.0, 0.0))
    (1.0, 0.0, 0.0, 0.0)
    """
    q = np.asarray(q_wxyz, dtype=np.float64)
    n = float(np.linalg.norm(q)) if q.shape == (4,) else math.nan
    if not math.isfinite(n) or n < 1e-9:
        raise InputError(f"quaternion must be 4 finite numbers, not all zero; got {q_wxyz!r}")
    w, x, y, z = (float(v) for v in q / n)
    return (w, x, y, z)


def dcm_from_quaternion(q_wxyz: tuple[float, float, float, float]) -> FloatArray:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)`` (Hamilton, as MAVLink).

    The quaternion is normalised first (:func:`unit_quaternion`); a zero quaternion raises
    :class:`InputError`. Returns a (3, 3) float64 ndarray mapping the rotated frame into
    the reference frame.
    """
    q = unit_quaternion(q_wxyz)
    return np.asarray(Rotation.from_quat(q, scalar_first=True).as_matrix(), np.float64)


def _as_matrix3(m: FloatArray) -> Matrix3:
    r = [tuple(float(v) for v in row) for row in m]
    return (r[0], r[1], r[2])  # type: ignore[return-value]


@dataclass(frozen=True)
class GimbalAttitude:
    """Camera attitude reported by a gimbal (MAVLink GIMBAL_DEVICE_ATTITUDE_STATUS).

    q_wxyz : unit quaternion (w, x, y, z) rotating the camera FRD frame into ``frame``.
    frame : what the quaternion is relative to:
        ``"earth"``: NED (roll, pitch and yaw relative to the horizon and north);
        ``"vehicle"``: roll and pitch relative to the horizon, yaw relative to the
        vehicle's heading (MAVLink's "vehicle frame": NED turned by the vehicle's yaw);
        ``"body"``: relative to the vehicle's body FRD (an unstabilised, moving mount).
    """

    q_wxyz: tuple[float, float, float, float]
    frame: Literal["earth", "vehicle", "body"] = "vehicle"

    def __post_init__(self) -> None:
        if self.frame not in ("earth", "vehicle", "body"):
            raise InputError(
                f"gimbal frame must be 'earth', 'vehicle' or 'body', not {self.frame!r}"
            )
        dcm_from_quaternion(self.q_wxyz)  # validates

    @classmethod
    def from_mavlink(cls, q: tuple[float, float, float, float], flags: int) -> GimbalAttitude:
        """From GIMBAL_DEVICE_ATTITUDE_STATUS ``q`` and ``flags``.

        YAW_IN_EARTH_FRAME (64) -> ``"earth"``; YAW_IN_VEHICLE_FRAME (32) -> ``"vehicle"``;
        neither: YAW_LOCK (16) -> ``"earth"``, else ``"vehicle"`` (the message's rules).
        """
        if flags & _YAW_IN_EARTH_FRAME:
            frame: Literal["earth", "vehicle", "body"] = "earth"
        elif flags & _YAW_IN_VEHICLE_FRAME:
            frame = "vehicle"
        else:
            frame = "earth" if flags & _YAW_LOCK else "vehicle"
        return cls((float(q[0]), float(q[1]), float(q[2]), float(q[3])), frame)

    @classmethod
    def from_euler_deg(
        cls,
        roll_deg: float,
        pitch_deg: float,
        yaw_deg: float,
        frame: Literal["earth", "vehicle", "body"] = "vehicle",
    ) -> GimbalAttitude:
        """From ZYX Euler angles of the camera FRD frame, degrees (pitch -90 = down)."""
        r, p, y = (math.radians(a) / 2 for a in (roll_deg, pitch_deg, yaw_deg))
        cr, sr, cp, sp, cy, sy = (
            math.cos(r),
            math.sin(r),
            math.cos(p),
            math.sin(p),
            math.cos(y),
            math.sin(y),
        )
        q = (
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        )
        return cls(q, frame)


def _nadir() -> Matrix3:
    return _as_matrix3(dcm_from_euler(0.0, -math.pi / 2, 0.0) @ _FRD_FROM_OPTICAL)


@dataclass(frozen=True)
class CameraMount:
    """How the camera is fixed to the vehicle.

    rotation : 3x3 rotation body FRD <- optical (rows of floats). The default looks straight
        down with the image top towards the nose (image right = vehicle right).
    offset_m : (x, y, z) position of the camera's optical centre in body FRD, metres.
    gimbal : when set, the gimbal's reported attitude replaces ``rotation``.

    Use :meth:`from_euler_deg` for a fixed mount given as angles and :meth:`with_gimbal`
    for each new gimbal report.
    """

    rotation: Matrix3 = field(default_factory=_nadir)
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gimbal: GimbalAttitude | None = None

    def __post_init__(self) -> None:
        r = np.asarray(self.rotation, dtype=np.float64)
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise InputError("mount rotation must be a finite 3x3 matrix")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise InputError(
                "mount rotation must be a proper rotation (orthonormal, det +1); "
                "build it with CameraMount.from_euler_deg"
            )
        if len(self.offset_m) != 3 or not all(math.isfinite(v) for v in self.offset_m):
            raise InputError(
                f"mount offset must be 3 finite metres (x, y, z), got {self.offset_m!r}"
            )

    @classmethod
    def from_euler_deg(
        cls,
        roll_deg: float = 0.0,
        pitch_deg: float = -90.0,
        yaw_deg: float = 0.0,
        offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> CameraMount:
        """A fixed mount from ZYX angles of the camera FRD frame relative to body, degrees.

        ``(0, -90, 0)`` (the default) looks straight down with the image top towards the
        nose; ``(0, -45, 0)`` looks forward and down at 45 deg; ``(0, 0, 90)`` looks right.
        """
        r = dcm_from_euler(math.radians(roll_deg), math.radians(pitch_deg), math.radians(yaw_deg))
        return cls(_as_matrix3(r @ _FRD_FROM_OPTICAL), offset_m)

    def with_gimbal(self, gimbal: GimbalAttitude | None) -> CameraMount:
        """This mount with the gimbal's latest attitude (``None`` = back to the fixed rotation)."""
        return replace(self, gimbal=gimbal)


def rotation_ned_from_optical(mount: CameraMount, pose: VehiclePose) -> FloatArray:
    """Rotation NED <- optical for this mount on a vehicle in ``pose``.

    Returns a (3, 3) float64 ndarray: ``ray_ned = R @ ray_optical``.
    """
    r_ned_body = dcm_from_euler(pose.roll, pose.pitch, pose.yaw)
    g = mount.gimbal
    r: FloatArray
    if g is None:
        r = r_ned_body @ np.asarray(mount.rotation, dtype=np.float64)
        return r
    r_frd: FloatArray = dcm_from_quaternion(g.q_wxyz) @ _FRD_FROM_OPTICAL
    if g.frame == "earth":
        r = r_frd
    elif g.frame == "vehicle":
        r = dcm_from_euler(0.0, 0.0, pose.yaw) @ r_frd
    else:
        r = r_ned_body @ r_frd
    return r
