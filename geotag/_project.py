"""Detections -> positions on the Earth (and back), with a 1-sigma horizontal error.

A detection's box centre defines a ray from the camera; the opening's rim depth
(``Detection.rim_depth_m``, axial Z) fixes the point on it. The point is rotated
optical -> NED (mount or gimbal, then the vehicle's roll/pitch/yaw), shifted by the camera's
offset on the vehicle, and converted to WGS84 with :func:`pymap3d.ned2geodetic`.

Altitudes are MSL as in :class:`VehiclePose`; pymap3d treats the vehicle's altitude as the
ellipsoidal height of the local origin. Over the few metres between camera and hole the
geoid-ellipsoid difference changes the result by micrometres, so the MSL altitude passes
through unchanged.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pymap3d

from detect import CameraIntrinsics, Detection, FeatureScores
from geotag._camera import CameraMount, FloatArray, dcm_from_euler, rotation_ned_from_optical
from geotag._types import VehiclePose
from holescan_errors import InputError

__all__ = [
    "ErrorModel",
    "HoleSighting",
    "geotag_detection",
    "geotag_frame",
    "project_to_pixel",
]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ErrorModel:
    """1-sigma error sources that make up a sighting's horizontal uncertainty.

    attitude_sigma_rad : attitude (and mount calibration) error per axis, rad; moves the
        point by ``range * angle`` (1 deg = 1.7 cm per metre of range).
    default_eph_m : GPS horizontal 1-sigma, metres, used when ``pose.eph_m`` is NaN.
    depth_noise_per_mm : Xtion axial depth noise ``sigma_Z = k * Z_mm**2`` mm
        (Khoshelham & Elberink 2012: k = 1.425e-6, 1.4 mm at 1 m, 13 mm at 3 m).
    """

    attitude_sigma_rad: float = math.radians(1.0)
    default_eph_m: float = 3.0
    depth_noise_per_mm: float = 1.425e-6


@dataclass(frozen=True)
class HoleSighting:
    """One detection placed on the Earth.

    lat_deg, lon_deg : WGS84 of the hole's opening (box centre at rim depth).
    alt_m : altitude of the opening above mean sea level, metres.
    sigma_h_m : 1-sigma horizontal uncertainty, metres (all sources below combined).
    sigma_gps_m : the GPS part of ``sigma_h_m`` (shared by sightings close in time).
    score : detector confidence in [0, 1].
    major_m, minor_m : metric axes of the opening.
    t_boot_ns : autopilot boot-clock time of the pose used, ns.
    frame_index : index of the frame it was seen in (None when unknown).
    box : (x, y, w, h) pixels in that frame.
    features : the detector's five attribute scores.
    range_m : distance camera -> opening, metres.
    off_centre : distance of the box centre from the principal point, 0 (centre) to 1
        (image corner); smaller = better view.
    """

    lat_deg: float
    lon_deg: float
    alt_m: float
    sigma_h_m: float
    score: float
    major_m: float
    minor_m: float
    t_boot_ns: int
    frame_index: int | None
    box: tuple[int, int, int, int]
    features: FeatureScores
    sigma_gps_m: float = 0.0
    range_m: float = float("nan")
    off_centre: float = 0.0


def _check_pose(pose: VehiclePose) -> None:
    values = (pose.lat_deg, pose.lon_deg, pose.alt_m, pose.roll, pose.pitch, pose.yaw)
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"pose has a non-finite position or attitude: {pose!r}")
    if not -90.0 <= pose.lat_deg <= 90.0:
        raise InputError(f"pose latitude must be in -90..90 deg, got {pose.lat_deg}")


def _offset_ned(mount: CameraMount, pose: VehiclePose) -> FloatArray:
    r_ned_body = dcm_from_euler(pose.roll, pose.pitch, pose.yaw)
    return r_ned_body @ np.asarray(mount.offset_m, dtype=np.float64)


def geotag_detection(
    det: Detection,
    camera: CameraIntrinsics,
    mount: CameraMount,
    pose: VehiclePose,
    *,
    frame_index: int | None = None,
    errors: ErrorModel | None = None,
) -> HoleSighting:
    """Place one detection on the Earth.

    Parameters
    ----------
    det : the detection; its box centre gives the ray, ``rim_depth_m`` (axial Z, metres)
        the distance along it.
    camera : intrinsics of the image the box is in.
    mount : camera mount (and gimbal attitude, if any).
    pose : vehicle pose at the frame's time.
    frame_index : frame number to record in the sighting.
    errors : error model for ``sigma_h_m`` (default :class:`ErrorModel`).

    Returns
    -------
    HoleSighting

    Raises
    ------
    InputError
        When ``rim_depth_m`` is not a positive finite number or the pose is not finite.
    """
    em = errors if errors is not None else ErrorModel()
    _check_pose(pose)
    z = det.rim_depth_m
    if not (math.isfinite(z) and z > 0):
        raise InputError(f"detection rim_depth_m must be positive metres, got {z}")
    u, v = det.centre_px
    ray = np.array([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0])
    r_ned_opt = rotation_ned_from_optical(mount, pose)
    p_ned = r_ned_opt @ (ray * z) + _offset_ned(mount, pose)
    lat, lon, alt = pymap3d.ned2geodetic(
        float(p_ned[0]), float(p_ned[1]), float(p_ned[2]), pose.lat_deg, pose.lon_deg, pose.alt_m
    )

    # 1-sigma horizontal error, independent sources added in quadrature.
    range_m = float(np.linalg.norm(p_ned))
    eph = pose.eph_m if math.isfinite(pose.eph_m) and pose.eph_m >= 0 else em.default_eph_m
    attitude = range_m * em.attitude_sigma_rad
    sigma_z_m = em.depth_noise_per_mm * (z * 1000.0) ** 2 / 1000.0
    ray_ned = r_ned_opt @ ray  # displacement per metre of Z
    depth = sigma_z_m * math.hypot(float(ray_ned[0]), float(ray_ned[1]))
    timing = abs(pose.age_ns) * 1e-9 * math.hypot(pose.vn, pose.ve)
    sigma_h = math.sqrt(eph**2 + attitude**2 + depth**2 + timing**2)

    half_diag = math.hypot(camera.width / 2.0, camera.height / 2.0)
    off_centre = min(1.0, math.hypot(u - camera.cx, v - camera.cy) / half_diag)
    return HoleSighting(
        lat_deg=float(lat),
        lon_deg=float(lon),
        alt_m=float(alt),
        sigma_h_m=sigma_h,
        score=det.score,
        major_m=det.major_m,
        minor_m=det.minor_m,
        t_boot_ns=pose.t_boot_ns,
        frame_index=frame_index,
        box=det.box,
        features=det.features,
        sigma_gps_m=eph,
        range_m=range_m,
        off_centre=off_centre,
    )


def geotag_frame(
    detections: Sequence[Detection],
    camera: CameraIntrinsics,
    mount: CameraMount,
    pose: VehiclePose,
    *,
    frame_index: int | None = None,
    errors: ErrorModel | None = None,
) -> list[HoleSighting]:
    """:func:`geotag_detection` for every detection of one frame, in order.

    Detections without a usable rim depth (NaN, <= 0) cannot be placed; they are
    skipped and counted in a debug log line.
    """
    usable = [d for d in detections if math.isfinite(d.rim_depth_m) and d.rim_depth_m > 0]
    if len(usable) < len(detections):
        _log.debug(
            "frame %s: %d of %d detections have no rim depth, not geotagged",
            frame_index,
            len(detections) - len(usable),
            len(detections),
        )
    return [
        geotag_detection(d, camera, mount, pose, frame_index=frame_index, errors=errors)
        for d in usable
    ]


def project_to_pixel(
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    camera: CameraIntrinsics,
    mount: CameraMount,
    pose: VehiclePose,
) -> tuple[float, float]:
    """Pixel ``(u, v)`` where a point on the Earth appears (inverse of :func:`geotag_detection`).

    Parameters
    ----------
    lat_deg, lon_deg : WGS84 degrees; alt_m : metres above mean sea level.
    camera, mount, pose : as for :func:`geotag_detection`.

    Returns
    -------
    (u, v) : float pixels (may lie outside the image).

    Raises
    ------
    InputError
        When the point is behind the camera (axial depth <= 0).
    """
    _check_pose(pose)
    n, e, d = pymap3d.geodetic2ned(lat_deg, lon_deg, alt_m, pose.lat_deg, pose.lon_deg, pose.alt_m)
    p_ned = np.array([float(n), float(e), float(d)]) - _offset_ned(mount, pose)
    p_opt = rotation_ned_from_optical(mount, pose).T @ p_ned
    if p_opt[2] <= 1e-9:
        raise InputError(
            f"point ({lat_deg}, {lon_deg}, {alt_m} m) is behind the camera "
            f"(axial depth {p_opt[2]:.3f} m)"
        )
    u = camera.fx * p_opt[0] / p_opt[2] + camera.cx
    v = camera.fy * p_opt[1] / p_opt[2] + camera.cy
    return (float(u), float(v))
