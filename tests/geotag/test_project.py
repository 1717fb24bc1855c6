"""Geotagging: pixel -> geo -> pixel round trips and known values from pymap3d's own paths."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pymap3d
import pytest

from holescan.detect import CameraIntrinsics, Detection, FeatureScores
from holescan.errors import InputError
from holescan.geotag import (
    CameraMount,
    ErrorModel,
    GimbalAttitude,
    VehiclePose,
    dcm_from_euler,
    dcm_from_quaternion,
    geotag_detection,
    geotag_frame,
    project_to_pixel,
)

CAM = CameraIntrinsics.xtion()
FEATURES = FeatureScores(0.9, 0.8, 0.7, 0.6, 0.5)
LAT0, LON0, ALT0 = 43.6532, -79.3832, 112.0  # Toronto, MSL


def pose(
    roll_deg: float = 0.0, pitch_deg: float = 0.0, yaw_deg: float = 0.0, **kw: float
) -> VehiclePose:
    args: dict[str, float] = {"eph_m": 1.0}
    args.update(kw)
    return VehiclePose(
        t_boot_ns=123_000_000,
        lat_deg=LAT0,
        lon_deg=LON0,
        alt_m=ALT0,
        rel_alt_m=4.0,
        roll=math.radians(roll_deg),
        pitch=math.radians(pitch_deg),
        yaw=math.radians(yaw_deg),
        **args,  # type: ignore[arg-type]
    )


def detection_at(u: float, v: float, z_m: float, size: int = 40, score: float = 0.7) -> Detection:
    """A detection whose box centre (Detection.centre_px) is exactly (u, v)."""
    x = u + 0.5 - size / 2.0
    y = v + 0.5 - size / 2.0
    assert x == int(x), "pick u so the box corner is integral"
    assert y == int(y), "pick v so the box corner is integral"
    det = Detection((int(x), int(y), size, size), score, FEATURES, 0.8, 0.7, 0.4, z_m)
    assert det.centre_px == (u, v)
    return det


def test_default_mount_looks_down_with_image_top_to_the_nose() -> None:
    r = np.asarray(CameraMount().rotation)
    np.testing.assert_allclose(r @ [0, 0, 1], [0, 0, 1], atol=1e-12)  # optical axis = body down
    np.testing.assert_allclose(r @ [0, -1, 0], [1, 0, 0], atol=1e-12)  # image up = nose
    np.testing.assert_allclose(r @ [1, 0, 0], [0, 1, 0], atol=1e-12)  # image right = right
    np.testing.assert_allclose(r, np.asarray(CameraMount.from_euler_deg(0, -90, 0).rotation))


def test_gimbal_euler_quaternion_matches_dcm() -> None:
    g = GimbalAttitude.from_euler_deg(10.0, -35.0, 120.0, "body")
    np.testing.assert_allclose(
        dcm_from_quaternion(g.q_wxyz), dcm_from_euler(*np.radians([10.0, -35.0, 120.0])), atol=1e-12
    )


@pytest.mark.parametrize(
    ("flags", "frame"),
    [(64, "earth"), (32, "vehicle"), (16, "earth"), (0, "vehicle"), (16 | 32, "vehicle")],
)
def test_gimbal_frame_from_mavlink_flags(flags: int, frame: str) -> None:
    assert GimbalAttitude.from_mavlink((1.0, 0.0, 0.0, 0.0), flags).frame == frame


MOUNTS = {
    "nadir": CameraMount(),
    "forward45": CameraMount.from_euler_deg(0.0, -45.0, 0.0, offset_m=(0.15, 0.0, 0.05)),
    "skewed": CameraMount.from_euler_deg(7.0, -62.0, 25.0, offset_m=(0.1, -0.05, 0.08)),
    "gimbal-earth": CameraMount().with_gimbal(GimbalAttitude.from_euler_deg(0, -70, 200, "earth")),
    "gimbal-vehicle": CameraMount(offset_m=(0.0, 0.0, 0.1)).with_gimbal(
        GimbalAttitude.from_euler_deg(3, -50, -30, "vehicle")
    ),
    "gimbal-body": CameraMount().with_gimbal(GimbalAttitude.from_euler_deg(-4, -80, 10, "body")),
}
POSES = [(0.0, 0.0, 0.0), (8.0, -5.0, 37.0), (-12.0, 10.0, -150.0), (3.0, 20.0, 270.0)]


@pytest.mark.parametrize("mount_name", sorted(MOUNTS))
@pytest.mark.parametrize("attitude", POSES)
def test_pixel_geo_pixel_round_trip(mount_name: str, attitude: tuple[float, float, float]) -> None:
    mount = MOUNTS[mount_name]
    p = pose(*attitude)
    rng = np.random.default_rng(7)
    for _ in range(25):
        u = float(rng.integers(20, 620)) - 0.5  # box of 40 px with integral corner
        v = float(rng.integers(20, 460)) - 0.5
        z = float(rng.uniform(0.8, 3.5))
        s = geotag_detection(detection_at(u, v, z), CAM, mount, p, frame_index=4)
        uu, vv = project_to_pixel(s.lat_deg, s.lon_deg, s.alt_m, CAM, mount, p)
        assert uu == pytest.approx(u, abs=1e-4)
        assert vv == pytest.approx(v, abs=1e-4)


def _aer_expected(az_deg: float, el_deg: float, srange: float) -> tuple[float, float, float]:
    lat, lon, alt = pymap3d.aer2geodetic(az_deg, el_deg, srange, LAT0, LON0, ALT0)
    return float(lat), float(lon), float(alt)


def _assert_at(s_lat: float, s_lon: float, s_alt: float, exp: tuple[float, float, float]) -> None:
    assert s_lat == pytest.approx(exp[0], abs=1e-9)  # 0.1 mm
    assert s_lon == pytest.approx(exp[1], abs=1e-9)
    assert s_alt == pytest.approx(exp[2], abs=1e-6)


@pytest.mark.parametrize("yaw_deg", [0.0, 33.0, -120.0])
@pytest.mark.parametrize("tilt_deg", [30.0, 45.0, 70.0])
@pytest.mark.parametrize(("u", "v"), [(319.5, 239.5), (99.5, 399.5), (599.5, 59.5)])
def test_tilted_camera_matches_aer2geodetic(
    yaw_deg: float, tilt_deg: float, u: float, v: float
) -> None:
    """Camera pitched down by ``tilt`` on a level vehicle: azimuth/elevation by hand trig."""
    z = 2.5
    s = geotag_detection(
        detection_at(u, v, z), CAM, CameraMount.from_euler_deg(0, -tilt_deg, 0), pose(0, 0, yaw_deg)
    )
    xn, yn = (u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy  # right, down per metre of Z
    t = math.radians(tilt_deg)
    forward = z * (math.cos(t) - yn * math.sin(t))
    right = z * xn
    down = z * (math.sin(t) + yn * math.cos(t))
    az = yaw_deg + math.degrees(math.atan2(right, forward))
    el = -math.degrees(math.atan2(down, math.hypot(forward, right)))
    _assert_at(
        s.lat_deg, s.lon_deg, s.alt_m, _aer_expected(az, el, z * math.sqrt(1 + xn**2 + yn**2))
    )


@pytest.mark.parametrize("yaw_deg", [0.0, 75.0, 200.0])
@pytest.mark.parametrize("angle_deg", [5.0, 20.0])
def test_nadir_camera_with_vehicle_roll_or_pitch(yaw_deg: float, angle_deg: float) -> None:
    z = 3.0
    centre = detection_at(319.5, 239.5, z)
    # Right wing down: the belly (and the camera) looks to the left of the heading.
    s = geotag_detection(centre, CAM, CameraMount(), pose(angle_deg, 0, yaw_deg))
    _assert_at(s.lat_deg, s.lon_deg, s.alt_m, _aer_expected(yaw_deg - 90, -(90 - angle_deg), z))
    # Nose up: the belly turns forward, the camera looks ahead.
    s = geotag_detection(centre, CAM, CameraMount(), pose(0, angle_deg, yaw_deg))
    _assert_at(s.lat_deg, s.lon_deg, s.alt_m, _aer_expected(yaw_deg, -(90 - angle_deg), z))


def test_gimbal_attitude_overrides_mount() -> None:
    z = 2.0
    centre = detection_at(319.5, 239.5, z)
    fixed = CameraMount.from_euler_deg(0, -10, 90)  # ignored once the gimbal reports
    earth = fixed.with_gimbal(GimbalAttitude.from_euler_deg(0, -60, 45, "earth"))
    s = geotag_detection(centre, CAM, earth, pose(10, -7, 300))
    _assert_at(s.lat_deg, s.lon_deg, s.alt_m, _aer_expected(45, -60, z))
    vehicle = fixed.with_gimbal(GimbalAttitude.from_euler_deg(0, -60, 20, "vehicle"))
    s = geotag_detection(centre, CAM, vehicle, pose(10, -7, 30))
    _assert_at(s.lat_deg, s.lon_deg, s.alt_m, _aer_expected(50, -60, z))


def test_mount_offset_moves_the_hole() -> None:
    z = 2.0
    mount = CameraMount(offset_m=(0.3, -0.1, 0.05))  # forward, left, below the GPS origin
    s = geotag_detection(detection_at(319.5, 239.5, z), CAM, mount, pose(0, 0, 90))
    # Heading east: forward = east, left = north.
    lat, lon, alt = pymap3d.enu2geodetic(0.3, 0.1, -(z + 0.05), LAT0, LON0, ALT0)
    _assert_at(s.lat_deg, s.lon_deg, s.alt_m, (float(lat), float(lon), float(alt)))


def test_sighting_record_and_uncertainty() -> None:
    det = detection_at(319.5, 239.5, 3.0, score=0.82)
    em = ErrorModel(attitude_sigma_rad=math.radians(1.0))
    s = geotag_detection(det, CAM, CameraMount(), pose(eph_m=2.0), frame_index=17, errors=em)
    assert (s.score, s.major_m, s.minor_m, s.frame_index, s.box) == (0.82, 0.7, 0.4, 17, det.box)
    assert s.features == FEATURES
    assert s.t_boot_ns == 123_000_000
    assert s.range_m == pytest.approx(3.0)
    assert s.off_centre == pytest.approx(0.0)
    # Nadir, image centre: depth noise is vertical; GPS 2 m and 1 deg at 3 m (5.2 cm).
    assert s.sigma_gps_m == 2.0
    assert s.sigma_h_m == pytest.approx(math.hypot(2.0, 3.0 * math.radians(1.0)), rel=1e-12)
    # Pose 100 ms old at 5 m/s horizontal adds 0.5 m; unknown eph uses the default.
    moving = pose(vn=3.0, ve=4.0, vd=1.0, age_ns=100_000_000, eph_m=math.nan)
    s = geotag_detection(det, CAM, CameraMount(), moving, errors=ErrorModel(default_eph_m=1.5))
    assert s.sigma_gps_m == 1.5
    assert s.sigma_h_m == pytest.approx(math.sqrt(1.5**2 + (3.0 * math.radians(1)) ** 2 + 0.25))


def test_depth_noise_enters_for_oblique_rays() -> None:
    det = detection_at(319.5, 239.5, 3.0)
    em = ErrorModel(attitude_sigma_rad=0.0)
    s = geotag_detection(det, CAM, CameraMount.from_euler_deg(0, 0, 0), pose(eph_m=0.0), errors=em)
    assert s.sigma_h_m == pytest.approx(1.425e-6 * 3000.0**2 / 1000.0)  # 12.8 mm at 3 m


def test_invalid_inputs_raise_input_error() -> None:
    with pytest.raises(InputError, match="rim_depth_m"):
        geotag_detection(detection_at(319.5, 239.5, float("nan")), CAM, CameraMount(), pose())
    with pytest.raises(InputError, match="behind the camera"):
        project_to_pixel(LAT0, LON0, ALT0 + 5.0, CAM, CameraMount(), pose())
    with pytest.raises(InputError, match="proper rotation"):
        CameraMount(rotation=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, -1.0)))
    with pytest.raises(InputError, match="quaternion"):
        GimbalAttitude((0.0, 0.0, 0.0, 0.0))
    with pytest.raises(InputError, match="non-finite"):
        geotag_detection(
            detection_at(319.5, 239.5, 2.0), CAM, CameraMount(), pose(yaw_deg=math.nan)
        )


def test_geotag_frame_skips_detections_without_depth() -> None:
    dets = [
        detection_at(319.5, 239.5, 2.0),
        detection_at(99.5, 99.5, 0.0),
        detection_at(199.5, 99.5, 1.5),
    ]
    out = geotag_frame(dets, CAM, CameraMount(), pose(), frame_index=9)
    assert [s.box for s in out] == [dets[0].box, dets[2].box]
    assert all(s.frame_index == 9 for s in out)


def opening_detection(
    centre: tuple[float, float, float],
    normal: tuple[float, float, float] = (0.0, 0.0, -1.0),
    rim_seen: float = 1.0,
    major: float = 0.8,
) -> Detection:
    """A detection whose box sits off the opening (as in an oblique view)."""
    det = detection_at(399.5, 299.5, centre[2])
    return replace(det, major_m=major, opening_m=centre, rim_normal=normal, rim_seen=rim_seen)


def test_opening_centre_places_the_hole_not_the_box() -> None:
    """The sighting is at the opening's centre on its rim plane, wherever the box is."""
    em = ErrorModel(attitude_sigma_rad=0.0)
    det = opening_detection((0.5, -0.3, 3.0))
    s = geotag_detection(det, CAM, CameraMount(), pose(yaw_deg=90.0, eph_m=0.0), errors=em)
    # Heading east, nadir mount: optical x (image right) = south, optical y (down) = west.
    lat, lon, alt = pymap3d.ned2geodetic(-0.5, 0.3, 3.0, LAT0, LON0, ALT0)
    _assert_at(s.lat_deg, s.lon_deg, s.alt_m, (float(lat), float(lon), float(alt)))
    view = math.degrees(math.atan(math.hypot(0.5, 0.3) / 3.0))
    assert s.view_angle_deg == pytest.approx(view)
    assert s.rim_seen == 1.0
    expected = math.hypot(
        em.opening_base_m, em.opening_oblique * 0.8 * math.tan(math.radians(view))
    )
    assert s.sigma_opening_m == pytest.approx(expected)
    assert s.sigma_h_m > s.sigma_opening_m  # depth noise on top


def test_opening_sigma_grows_with_obliqueness_and_hidden_rim() -> None:
    em = ErrorModel(attitude_sigma_rad=0.0)
    p = pose(eph_m=0.0)
    below = geotag_detection(opening_detection((0.0, 0.0, 3.0)), CAM, CameraMount(), p, errors=em)
    side = geotag_detection(opening_detection((1.5, 0.0, 3.0)), CAM, CameraMount(), p, errors=em)
    cut = geotag_detection(
        opening_detection((1.5, 0.0, 3.0), rim_seen=0.6), CAM, CameraMount(), p, errors=em
    )
    assert below.sigma_opening_m == pytest.approx(em.opening_base_m)
    assert below.sigma_opening_m < side.sigma_opening_m < cut.sigma_opening_m
    # A tilted rim plane seen straight along its normal is not oblique.
    n = np.array([-1.5, 0.0, -3.0]) / math.hypot(1.5, 3.0)
    facing = geotag_detection(
        opening_detection((1.5, 0.0, 3.0), normal=(float(n[0]), 0.0, float(n[2]))),
        CAM,
        CameraMount(),
        p,
        errors=em,
    )
    assert facing.view_angle_deg == pytest.approx(0.0, abs=1e-6)
    # Without an opening centre the box centre is used, with the box's own (larger) term.
    box = geotag_detection(
        replace(side_det := opening_detection((1.5, 0.0, 3.0)), opening_m=None),
        CAM,
        CameraMount(),
        p,
        errors=em,
    )
    assert box.box == side_det.box and box.sigma_opening_m > side.sigma_opening_m


def test_unusable_opening_centre_falls_back_to_the_box() -> None:
    for bad in ((0.1, 0.2, -3.0), (math.nan, 0.0, 3.0)):
        det = replace(opening_detection((0.1, 0.2, 3.0)), opening_m=bad)
        s = geotag_detection(det, CAM, CameraMount(), pose())
        ref = geotag_detection(replace(det, opening_m=None), CAM, CameraMount(), pose())
        assert (s.lat_deg, s.lon_deg) == (ref.lat_deg, ref.lon_deg)
