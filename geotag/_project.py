"""Detections -> positions on the Earth (and back), with a horizontal error (68 % radius).

The point is the opening's centre on its rim plane as the detector measured it
(``Detection.opening_m``, camera frame): not the box centre, which an oblique view moves
toward the camera. Detections without it (paper mode, the baseline, logs from before) use
the box centre's ray at the rim depth (``Detection.rim_depth_m``, axial Z). The point is rotated
optical -> NED (mount or gimbal, then the vehicle's roll/pitch/yaw), shifted by the camera's
offset on the vehicle, and converted to WGS84 in the pose's :class:`LocalFrame`.

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

from holescan.detect import CameraIntrinsics, Detection, FeatureScores, PlaneVerdict, plane_verdict
from holescan.errors import InputError
from holescan.geotag._camera import (
    CameraMount,
    FloatArray,
    dcm_from_euler,
    rotation_ned_from_optical,
)
from holescan.geotag._local import LocalFrame
from holescan.geotag._types import VehiclePose

__all__ = [
    "CIRCLE_95_PER_SIGMA",
    "ErrorModel",
    "HoleSighting",
    "box_cut_by_border",
    "geotag_detection",
    "geotag_frame",
    "project_to_pixel",
]

_log = logging.getLogger(__name__)

#: ``sigma_h_m`` is the radius holding 68 % of horizontal errors; for a circular 2-D normal
#: the 95 % radius is 2.448 / 1.510 = 1.621 times that (per-axis sigma: 1.510 and 2.448).
CIRCLE_95_PER_SIGMA = math.sqrt(math.log(0.05) / math.log(0.32))


@dataclass(frozen=True)
class ErrorModel:
    """Error sources that make up a sighting's horizontal uncertainty.

    ``sigma_h_m`` is the radius that holds about 68 % of a sighting's horizontal errors;
    the sources below are independent and added in quadrature.

    attitude_sigma_rad : roll/pitch (and mount calibration) error, rad; moves the point by
        ``range * angle`` (1 deg = 1.7 cm per metre of range).
    default_eph_m : GPS horizontal 1-sigma, metres, used when ``pose.eph_m`` is NaN.
    depth_noise_per_mm : Xtion axial depth noise ``sigma_Z = k * Z_mm**2`` mm
        (Khoshelham & Elberink 2012: k = 1.425e-6, 1.4 mm at 1 m, 13 mm at 3 m).
    opening_base_m, opening_oblique, opening_unseen : where the detector put the opening's
        centre (:attr:`detect.Detection.opening_m`): ``hypot(opening_base_m, opening_oblique
        * major * tan(view angle), opening_unseen * major * (1 - rim_seen))``; the view
        angle is the line of sight's angle to the rim plane's normal. Calibrated with
        ``benchmarks/bench_geotag.py`` so that 68 % of sightings fall within it.
    cut_unseen : an opening the frame's border or an unread band cuts
        (:attr:`detect.Detection.border_cut`) has at least this fraction of its major axis
        unseen (how far it runs on beyond the cut is unknown; its centre, placed on the
        circle through the rim it shows, was 0.12-0.18 m off in the median in the simulated
        sortie of ``tests/geotag/test_sim_accuracy.py``, against 0.03-0.04 m uncut).
    box_oblique : detections without an opening centre (paper mode, older logs) are placed
        at their box centre, which moves toward the camera as the view turns oblique:
        ``hypot(opening_base_m, box_oblique * major * tan(view angle))``.
    """

    attitude_sigma_rad: float = math.radians(1.0)
    default_eph_m: float = 3.0
    depth_noise_per_mm: float = 1.425e-6
    opening_base_m: float = 0.018
    opening_oblique: float = 0.03
    opening_unseen: float = 0.5
    cut_unseen: float = 0.5
    box_oblique: float = 0.35

    def __post_init__(self) -> None:
        deg = math.degrees(self.attitude_sigma_rad)
        if not 0.0 <= deg <= 10.0:
            raise InputError(f"attitude_sigma_deg must be in 0-10 degrees, got {deg:g}")


@dataclass(frozen=True)
class HoleSighting:
    """One detection placed on the Earth.

    lat_deg, lon_deg : WGS84 of the hole's opening: its centre on the rim plane
        (:attr:`detect.Detection.opening_m`), or for detections without one the box centre
        at rim depth.
    alt_m : altitude of the opening above mean sea level, metres.
    sigma_h_m : horizontal uncertainty, metres: the radius that holds about 68 % of the
        errors (all sources below combined; :class:`ErrorModel`).
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
    sigma_opening_m : the part of ``sigma_h_m`` from where the detector put the opening's
        centre in the image (view angle, rim seen).
    view_angle_deg : angle between the line of sight and the rim plane's normal, degrees
        (without a rim plane: the ray's angle off the optical axis, the camera taken to
        face the ground as on a survey).
    rim_seen : fraction of the opening's rim the sensor saw (NaN: not measured).
    cut_by_border : the box touches the image border (the opening may go on beyond it: its
        size and centre are those of the part in view).
    inside_on_plane, inside_behind : the detection's rim-plane reading
        (:attr:`detect.Detection.inside_on_plane`, ``inside_behind``); NaN when not
        measured. :attr:`plane` is its verdict, which the tracker counts over viewpoints.
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
    sigma_opening_m: float = 0.0
    view_angle_deg: float = float("nan")
    rim_seen: float = float("nan")
    cut_by_border: bool = False
    inside_on_plane: float = float("nan")
    inside_behind: float = float("nan")

    @property
    def plane(self) -> PlaneVerdict | None:
        """What this view read inside an opening without readings, against its rim's plane
        (:func:`detect.plane_verdict`: ``surface``, ``behind``, ``unread``, ``mixed``);
        None when not measured."""
        return plane_verdict(self.inside_on_plane, self.inside_behind)


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
    r_ned_opt = rotation_ned_from_optical(mount, pose)
    centre = _opening_centre(det)
    if centre is not None:
        p_opt = centre
        normal_ned = r_ned_opt @ np.asarray(det.rim_normal, dtype=np.float64)
    else:  # no opening measured: the box centre at rim depth, the ground facing the camera
        p_opt = np.array([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0]) * z
        normal_ned = r_ned_opt @ np.array([0.0, 0.0, -1.0])
    los_ned = r_ned_opt @ p_opt
    p_ned = los_ned + _offset_ned(mount, pose)
    lat, lon, alt = LocalFrame(pose.lat_deg, pose.lon_deg, pose.alt_m).ned_to_geodetic(
        float(p_ned[0]), float(p_ned[1]), float(p_ned[2])
    )

    # Horizontal error: independent sources added in quadrature.
    range_m = float(np.linalg.norm(p_ned))
    eph = pose.eph_m if math.isfinite(pose.eph_m) and pose.eph_m >= 0 else em.default_eph_m
    attitude = range_m * em.attitude_sigma_rad
    z_los = float(p_opt[2])
    sigma_z_m = em.depth_noise_per_mm * (z_los * 1000.0) ** 2 / 1000.0
    ray_ned = los_ned / z_los  # displacement per metre of Z
    depth = sigma_z_m * math.hypot(float(ray_ned[0]), float(ray_ned[1]))
    timing = abs(pose.age_ns) * 1e-9 * math.hypot(pose.vn, pose.ve)
    cos_view = abs(float(normal_ned @ los_ned)) / max(float(np.linalg.norm(los_ned)), 1e-9)
    view = math.acos(min(1.0, cos_view))
    opening = _opening_sigma(det, view, centre is not None, em)
    sigma_h = math.sqrt(eph**2 + attitude**2 + depth**2 + timing**2 + opening**2)

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
        sigma_opening_m=opening,
        view_angle_deg=math.degrees(view),
        rim_seen=float(det.rim_seen) if det.rim_seen is not None else math.nan,
        cut_by_border=box_cut_by_border(det.box, camera.width, camera.height),
        inside_on_plane=_nan_if_none(det.inside_on_plane),
        inside_behind=_nan_if_none(det.inside_behind),
    )


def _nan_if_none(v: float | None) -> float:
    return math.nan if v is None else float(v)


def box_cut_by_border(box: tuple[int, int, int, int], width: int, height: int) -> bool:
    """True when ``box`` (x, y, w, h pixels) reaches within 2 px of the image's border.

    Examples
    --------
    >>> box_cut_by_border((0, 100, 50, 40), 640, 480), box_cut_by_border((5, 5, 50, 40), 640, 480)
    (True, False)
    """
    x, y, w, h = box
    return x <= 1 or y <= 1 or x + w >= width - 1 or y + h >= height - 1


def _opening_centre(det: Detection) -> FloatArray | None:
    """The detection's opening centre (optical frame, m), or None to use the box centre."""
    if det.opening_m is None or det.rim_normal is None:
        return None
    c = np.asarray(det.opening_m, dtype=np.float64)
    n = np.asarray(det.rim_normal, dtype=np.float64)
    if c.shape != (3,) or n.shape != (3,) or not (np.isfinite(c).all() and np.isfinite(n).all()):
        return None
    if c[2] <= 0 or not 0.5 < float(np.linalg.norm(n)) < 1.5:
        return None
    return c


def _opening_sigma(det: Detection, view_rad: float, measured: bool, em: ErrorModel) -> float:
    """How far the detector's idea of the opening's centre may be off, metres (68 %)."""
    major = det.major_m if math.isfinite(det.major_m) and det.major_m > 0 else 0.0
    oblique = major * math.tan(min(view_rad, math.radians(80.0)))
    if not measured:
        return math.hypot(em.opening_base_m, em.box_oblique * oblique) if oblique > 0 else 0.0
    seen = det.rim_seen if det.rim_seen is not None and math.isfinite(det.rim_seen) else 1.0
    unseen = major * (1.0 - min(max(seen, 0.0), 1.0))
    if det.border_cut:  # its rim beyond the frame's border or band is unknown, not seen
        unseen = max(unseen, em.cut_unseen * major)
    return math.hypot(em.opening_base_m, em.opening_oblique * oblique, em.opening_unseen * unseen)


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
    n, e, d = LocalFrame(pose.lat_deg, pose.lon_deg, pose.alt_m).to_ned(lat_deg, lon_deg, alt_m)
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
