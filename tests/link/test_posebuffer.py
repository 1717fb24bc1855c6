"""PoseBuffer: interpolation, slerp across the +-pi yaw wrap, dead reckoning, refusals."""

from __future__ import annotations

import math

import pymap3d
import pytest
from scipy.spatial.transform import Rotation

from holescan.link import (
    AttitudeSample,
    GpsFix,
    NavStatus,
    PoseBuffer,
    PositionSample,
    quat_from_euler,
)
from holescan.link.errors import PoseInvalid, PoseUnavailable

MS = 1_000_000
S = 1_000_000_000
LAT, LON, ALT = 43.6532, -79.3832, 150.0


def _pos(t_ms: int, north_m: float = 0.0, east_m: float = 0.0, **kw: float) -> PositionSample:
    lat, lon, alt = pymap3d.ned2geodetic(north_m, east_m, 0.0, LAT, LON, ALT)
    return PositionSample(
        t_boot_ns=t_ms * MS,
        lat_deg=float(lat),
        lon_deg=float(lon),
        alt_m=float(alt),
        rel_alt_m=float(alt) - 120.0,
        vn=kw.get("vn", 0.0),
        ve=kw.get("ve", 0.0),
        vd=kw.get("vd", 0.0),
    )


def _att(t_ms: int, yaw_deg: float, roll_deg: float = 0.0, pitch_deg: float = 0.0,
         rates: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> AttitudeSample:  # fmt: skip
    q = quat_from_euler(math.radians(roll_deg), math.radians(pitch_deg), math.radians(yaw_deg))
    return AttitudeSample(t_boot_ns=t_ms * MS, quat_wxyz=q, rate_frd=rates)


def _ned(lat: float, lon: float, alt: float) -> tuple[float, float, float]:
    n, e, d = pymap3d.geodetic2ned(lat, lon, alt, LAT, LON, ALT)
    return float(n), float(e), float(d)


def test_quat_from_euler_matches_scipy() -> None:
    for r, p, y in [(0.1, -0.2, 3.0), (-1.0, 0.5, -2.9), (0.0, 0.0, math.pi)]:
        w, x, yy, z = quat_from_euler(r, p, y)
        ref = Rotation.from_euler("ZYX", [y, p, r])
        assert (Rotation.from_quat([x, yy, z, w]).inv() * ref).magnitude() < 1e-12


def test_linear_position_and_age() -> None:
    buf = PoseBuffer()
    buf.add_position(_pos(1000, 0.0, 0.0, vn=10.0))
    buf.add_position(_pos(1100, 1.0, 2.0, vn=10.0, ve=20.0))
    buf.add_attitude(_att(1000, 10.0))
    buf.add_attitude(_att(1100, 20.0))
    pose = buf.pose_at(1025 * MS)
    n, e, _ = _ned(pose.lat_deg, pose.lon_deg, pose.alt_m)
    assert n == pytest.approx(0.25, abs=1e-3)
    assert e == pytest.approx(0.5, abs=1e-3)
    assert pose.ve == pytest.approx(5.0)
    assert math.degrees(pose.yaw) == pytest.approx(12.5, abs=1e-9)
    assert pose.age_ns == 25 * MS
    assert pose.t_boot_ns == 1025 * MS
    assert math.isnan(pose.eph_m)  # no GPS fix seen


def test_slerp_across_the_yaw_wrap() -> None:
    buf = PoseBuffer()
    buf.add_position(_pos(0))
    buf.add_position(_pos(100))
    buf.add_attitude(_att(0, 179.0, roll_deg=4.0))
    buf.add_attitude(_att(100, -179.0, roll_deg=-4.0))
    mid = buf.pose_at(50 * MS)
    assert abs(math.degrees(mid.yaw)) == pytest.approx(180.0, abs=1e-6)  # not 0
    assert math.degrees(mid.roll) == pytest.approx(0.0, abs=1e-6)
    quarter = buf.pose_at(25 * MS)
    assert math.degrees(quarter.yaw) == pytest.approx(179.5, abs=1e-3)
    assert math.degrees(quarter.roll) == pytest.approx(2.0, abs=1e-3)
    three = buf.pose_at(75 * MS)
    assert math.degrees(three.yaw) == pytest.approx(-179.5, abs=1e-3)


def test_extrapolates_from_velocity_and_rates_over_a_short_gap() -> None:
    buf = PoseBuffer(max_extrapolation_ns=200 * MS)
    buf.add_position(_pos(900, vn=10.0))
    buf.add_position(_pos(1000, vn=10.0, ve=-5.0, vd=-2.0))
    buf.add_attitude(_att(1000, 90.0, rates=(0.0, 0.0, math.radians(50.0))))
    pose = buf.pose_at(1150 * MS)
    n, e, d = _ned(pose.lat_deg, pose.lon_deg, pose.alt_m)
    assert (n, e, d) == pytest.approx((1.5, -0.75, -0.3), abs=2e-3)
    assert pose.rel_alt_m == pytest.approx(30.0 + 0.3, abs=1e-6)
    assert math.degrees(pose.yaw) == pytest.approx(97.5, abs=1e-6)
    assert pose.age_ns == 150 * MS


def test_refusals() -> None:
    buf = PoseBuffer(capacity=4, max_gap_ns=500 * MS, max_extrapolation_ns=200 * MS)
    with pytest.raises(PoseUnavailable, match="no position telemetry"):
        buf.pose_at(0)
    buf.add_position(_pos(0))
    with pytest.raises(PoseUnavailable, match="no attitude telemetry"):
        buf.pose_at(0)
    buf.add_attitude(_att(0, 0.0))
    buf.add_position(_pos(600))  # a 0.6 s hole in the position stream
    buf.add_attitude(_att(600, 0.0))
    with pytest.raises(PoseUnavailable, match=r"position samples .* 0\.600 s apart"):
        buf.pose_at(300 * MS)
    buf.pose_at(600 * MS)  # exactly on a sample: fine
    buf.pose_at(800 * MS)  # 0.2 s past the newest: extrapolated
    with pytest.raises(PoseUnavailable, match=r"newest position sample is 0\.201 s old"):
        buf.pose_at(801 * MS)
    for k in range(1, 10):  # push the oldest samples out of the 4-deep buffer
        buf.add_position(_pos(600 + 100 * k))
        buf.add_attitude(_att(600 + 100 * k, 0.0))
    with pytest.raises(PoseUnavailable, match="older than the oldest"):
        buf.pose_at(1000 * MS)
    buf.pose_at(1200 * MS)


def test_duplicates_dropped_and_reboot_clears() -> None:
    buf = PoseBuffer()
    assert buf.add_position(_pos(5000))
    assert not buf.add_position(_pos(5000))  # same stamp again (e.g. two routes)
    assert not buf.add_position(_pos(4990))  # late
    assert buf.n_rejected == 2
    buf.add_attitude(_att(5000, 0.0))
    assert buf.newest_t_boot_ns == 5000 * MS
    assert buf.add_position(_pos(100))  # boot clock restarted: a new flight
    assert buf.n_reboots == 1
    with pytest.raises(PoseUnavailable, match="no attitude"):
        buf.pose_at(100 * MS)


def test_longitude_interpolates_across_the_antimeridian() -> None:
    buf = PoseBuffer(max_gap_ns=2 * S)  # 43 m in 1 s: fast, but no jump
    buf.add_position(PositionSample(0, -16.0, 179.9999, 10.0, 0.0, 0.0, 0.0, 0.0))
    buf.add_position(PositionSample(1000 * MS, -16.0, -179.9997, 10.0, 0.0, 0.0, 0.0, 0.0))
    buf.add_attitude(_att(0, 0.0))
    buf.add_attitude(_att(1000, 0.0))
    assert buf.pose_at(100 * MS).lon_deg == pytest.approx(179.99994, abs=1e-9)
    assert buf.pose_at(750 * MS).lon_deg == pytest.approx(-179.9998, abs=1e-9)


def test_gps_accuracy_attached() -> None:
    buf = PoseBuffer()
    for t_ms in (0, 400, 800):
        buf.add_position(_pos(t_ms))
        buf.add_attitude(_att(t_ms, 0.0))
    fix = GpsFix(100 * MS, 3, 12, 0.8, 1.5, 2.5, LAT, LON, ALT)
    buf.add_gps(GpsFix(0, 1, 3, math.nan, math.nan, math.nan, 0.0, 0.0, 0.0))  # no fix yet
    buf.add_gps(fix)
    with pytest.raises(PoseInvalid, match="no 3-D GPS fix"):  # no fix: no pose at all
        buf.pose_at(50 * MS)
    assert buf.pose_at(500 * MS).eph_m == 1.5
    assert buf.latest_gps() == fix


# -- poses the autopilot does not have (issue 20) -----------------------------------------


def _filled(t_ms: range, **pos: float) -> PoseBuffer:
    buf = PoseBuffer()
    for t in t_ms:
        buf.add_position(_pos(t, **pos))
        buf.add_attitude(_att(t, 0.0))
    return buf


def _fix(t_ms: int, fix_type: int) -> GpsFix:
    return GpsFix(t_ms * MS, fix_type, 12, 0.8, 1.5, 2.5, LAT, LON, ALT)


def test_null_island_positions_are_no_pose() -> None:
    buf = PoseBuffer()
    for t in range(0, 1000, 100):  # ArduPilot before its EKF has an origin: zeros
        buf.add_position(PositionSample(t * MS, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        buf.add_attitude(_att(t, 0.0))
    with pytest.raises(PoseInvalid, match="no position yet"):
        buf.pose_at(450 * MS)
    for t in range(1000, 2000, 100):  # the origin is set: real positions
        buf.add_position(_pos(t))
        buf.add_attitude(_att(t, 0.0))
    with pytest.raises(PoseInvalid, match="no position yet"):  # between 0/0 and the real one
        buf.pose_at(950 * MS)
    assert buf.pose_at(1450 * MS).lat_deg == pytest.approx(LAT)  # no jump from 0/0
    assert buf.validity.n_jumps == 0


def test_gps_fix_governs_the_poses_after_it() -> None:
    buf = _filled(range(0, 3000, 100))
    buf.add_gps(_fix(0, 1))  # no fix at boot
    buf.add_gps(_fix(1000, 3))  # 3-D fix from 1 s
    buf.add_gps(_fix(2000, 2))  # 2-D only from 2 s
    for t_ms, ok in ((500, False), (1500, True), (2500, False)):
        if ok:
            buf.pose_at(t_ms * MS)
        else:
            with pytest.raises(PoseInvalid, match="fix_type"):
                buf.pose_at(t_ms * MS)
    later = _filled(range(0, 6000, 100))
    later.add_gps(_fix(0, 3))  # GPS_RAW_INT stopped coming: no longer trusted
    later.pose_at(2000 * MS)
    with pytest.raises(PoseInvalid, match=r"no GPS_RAW_INT for 5\.0 s"):
        later.pose_at(5000 * MS)


def test_estimator_without_horizontal_position_is_no_pose() -> None:
    buf = _filled(range(0, 3000, 100))
    buf.add_gps(_fix(0, 3))  # the receiver has a fix, the EKF does not use it yet
    buf.add_nav(NavStatus(0, False, 0x0025, "EKF_STATUS_REPORT"))
    buf.add_nav(NavStatus(1000 * MS, True, 0x033F, "EKF_STATUS_REPORT"))
    with pytest.raises(PoseInvalid, match=r"no horizontal position .*0x25"):
        buf.pose_at(500 * MS)
    assert buf.pose_at(1500 * MS).lat_deg == pytest.approx(LAT)


def test_a_position_jump_is_refused_until_the_new_track_lasted() -> None:
    buf = PoseBuffer()
    for t in range(0, 6000, 100):
        north = 0.0 if t < 2000 else 60.0  # an EKF reset 60 m away at 2 s
        buf.add_position(_pos(t, north_m=north))
        buf.add_attitude(_att(t, 0.0))
    assert buf.validity.n_jumps == 1
    buf.pose_at(1850 * MS)  # before the jump
    for t_ms in (1950, 2000, 3500, 3950):
        with pytest.raises(PoseInvalid, match=r"jumped 60\.0 m"):
            buf.pose_at(t_ms * MS)
    n, _, _ = _ned(*(lambda p: (p.lat_deg, p.lon_deg, p.alt_m))(buf.pose_at(4050 * MS)))
    assert n == pytest.approx(60.0, abs=0.01)
    # A fast but possible flight (20 m/s) is no jump.
    fast = PoseBuffer()
    for t in range(0, 2000, 100):
        fast.add_position(_pos(t, north_m=0.02 * t, vn=20.0))
    assert fast.validity.n_jumps == 0


def test_telemetry_replay_applies_the_same_rules() -> None:
    """Reprocessing poses frames through TelemetryReplay: a logged boot without a fix gives
    no pose there, as in flight."""
    from holescan.link import TelemetryReplay, mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    hb = mav.heartbeat_encode(2, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4).pack(mav)
    replay = TelemetryReplay()
    replay.feed(hb)
    lat, lon = round(LAT * 1e7), round(LON * 1e7)
    for t in range(0, 4000, 100):
        fixed = t >= 2000
        gp = mav.global_position_int_encode(
            t, lat if fixed else 0, lon if fixed else 0, 150_000 if fixed else 0, 3000, 0, 0, 0, 0
        )
        replay.feed(gp.pack(mav))
        replay.feed(mav.attitude_encode(t, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0).pack(mav))
        gps = mav.gps_raw_int_encode(
            t * 1000, 3 if fixed else 1, lat if fixed else 0, lon if fixed else 0, 0, 80,
            120, 0, 0, 12,
        )  # fmt: skip
        replay.feed(gps.pack(mav))
    assert replay.pose_at(1000 * MS) is None
    pose = replay.pose_at(3000 * MS)
    assert pose is not None and pose.lat_deg == pytest.approx(LAT)
