"""The one MAVLink adapter: MAVLink units -> SI records, converted once (live link and log
replay use the same functions)."""

from __future__ import annotations

import math
from typing import Any

from holescan.errors import InputError
from holescan.geotag import unit_quaternion
from holescan.link._connection import mavlink
from holescan.link._posebuffer import AttitudeSample, quat_from_euler
from holescan.link._posevalidity import GpsFix, NavStatus, PositionSample

__all__ = [
    "TelemetrySample",
    "attitude_from_attitude",
    "attitude_from_quaternion",
    "gps_from_gps_raw_int",
    "home_from_home_position",
    "is_autopilot_heartbeat",
    "nav_from_ekf_status",
    "position_from_global_position_int",
    "telemetry_sample",
]

_NS_PER_MS = 1_000_000


def position_from_global_position_int(msg: Any) -> PositionSample:
    """GLOBAL_POSITION_INT (ms, degE7, mm, cm/s) -> :class:`PositionSample` (ns, deg, m, m/s)."""
    return PositionSample(
        t_boot_ns=int(msg.time_boot_ms) * _NS_PER_MS,
        lat_deg=msg.lat * 1e-7,
        lon_deg=msg.lon * 1e-7,
        alt_m=msg.alt * 1e-3,
        rel_alt_m=msg.relative_alt * 1e-3,
        vn=msg.vx * 1e-2,
        ve=msg.vy * 1e-2,
        vd=msg.vz * 1e-2,
    )


def home_from_home_position(msg: Any) -> tuple[float, float, float]:
    """HOME_POSITION (degE7, mm MSL) -> (lat_deg, lon_deg, alt_m MSL)."""
    return (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)


def attitude_from_attitude(msg: Any) -> AttitudeSample:
    """ATTITUDE (ms, rad, rad/s) -> :class:`AttitudeSample`."""
    return AttitudeSample(
        t_boot_ns=int(msg.time_boot_ms) * _NS_PER_MS,
        quat_wxyz=quat_from_euler(msg.roll, msg.pitch, msg.yaw),
        rate_frd=(float(msg.rollspeed), float(msg.pitchspeed), float(msg.yawspeed)),
    )


def attitude_from_quaternion(msg: Any) -> AttitudeSample:
    """ATTITUDE_QUATERNION (ms, q1..q4 = w, x, y, z) -> :class:`AttitudeSample`."""
    q = (float(msg.q1), float(msg.q2), float(msg.q3), float(msg.q4))
    try:
        unit = unit_quaternion(q)
    except InputError as err:
        raise ValueError(f"ATTITUDE_QUATERNION: {err}") from err
    return AttitudeSample(
        t_boot_ns=int(msg.time_boot_ms) * _NS_PER_MS,
        quat_wxyz=unit,
        rate_frd=(float(msg.rollspeed), float(msg.pitchspeed), float(msg.yawspeed)),
    )


def gps_from_gps_raw_int(msg: Any, t_boot_ns: int) -> GpsFix:
    """GPS_RAW_INT (degE7, mm, HDOP*100, h_acc mm) -> :class:`GpsFix`.

    ``t_boot_ns`` is supplied by the caller: GPS_RAW_INT's ``time_usec`` may be Unix or boot
    time depending on the autopilot.
    """
    h_acc = getattr(msg, "h_acc", 0)
    v_acc = getattr(msg, "v_acc", 0)
    return GpsFix(
        t_boot_ns=t_boot_ns,
        fix_type=int(msg.fix_type),
        satellites=-1 if msg.satellites_visible == 255 else int(msg.satellites_visible),
        hdop=math.nan if msg.eph == 65535 else msg.eph / 100.0,
        h_acc_m=h_acc * 1e-3 if h_acc else math.nan,
        v_acc_m=v_acc * 1e-3 if v_acc else math.nan,
        lat_deg=msg.lat * 1e-7,
        lon_deg=msg.lon * 1e-7,
        alt_m=msg.alt * 1e-3,
    )


# ArduPilot's EKF_STATUS_FLAGS and PX4's ESTIMATOR_STATUS_FLAGS share the low bits.
_POS_HORIZ_ABS = {
    "EKF_STATUS_REPORT": mavlink.EKF_POS_HORIZ_ABS,
    "ESTIMATOR_STATUS": mavlink.ESTIMATOR_POS_HORIZ_ABS,
}
_NO_POSITION = {  # constant-position mode (no aiding) or a GPS glitch
    "EKF_STATUS_REPORT": mavlink.EKF_CONST_POS_MODE | mavlink.EKF_GPS_GLITCHING,
    "ESTIMATOR_STATUS": mavlink.ESTIMATOR_CONST_POS_MODE | mavlink.ESTIMATOR_GPS_GLITCH,
}


def nav_from_ekf_status(msg: Any, t_boot_ns: int) -> NavStatus:
    """EKF_STATUS_REPORT (ArduPilot) or ESTIMATOR_STATUS (PX4) -> :class:`NavStatus`.

    A horizontal position is there when POS_HORIZ_ABS is set, the estimator is not in
    constant-position mode (no aiding: it holds its last position) and no GPS glitch is
    flagged. ``t_boot_ns`` : when it was received, on the autopilot's clock (neither message
    says when it was true in a form common to both).
    """
    mtype = msg.get_type()
    flags = int(msg.flags)
    ok = bool(flags & _POS_HORIZ_ABS[mtype]) and not flags & _NO_POSITION[mtype]
    return NavStatus(t_boot_ns=t_boot_ns, horizontal_ok=ok, flags=flags, source=mtype)


TelemetrySample = PositionSample | AttitudeSample | GpsFix | NavStatus
"""What a message from the autopilot adds to a :class:`~link._posebuffer.PoseBuffer`."""


def telemetry_sample(msg: Any, gps_t_boot_ns: int) -> TelemetrySample | None:
    """The SI sample a parsed MAVLink message carries, or None for messages that carry none.

    The one message -> sample decoder: the live link (:class:`Telemetry`) and log replay
    (:class:`link.TelemetryReplay`) both call it. ``gps_t_boot_ns`` : the autopilot boot
    time to stamp a GPS_RAW_INT or an estimator status with (see
    :func:`gps_from_gps_raw_int`). Raises ``ValueError`` for an ATTITUDE_QUATERNION with a
    zero quaternion.
    """
    mtype = msg.get_type()
    if mtype == "GLOBAL_POSITION_INT":
        return position_from_global_position_int(msg)
    if mtype == "ATTITUDE":
        return attitude_from_attitude(msg)
    if mtype == "ATTITUDE_QUATERNION":
        return attitude_from_quaternion(msg)
    if mtype == "GPS_RAW_INT":
        return gps_from_gps_raw_int(msg, gps_t_boot_ns)
    if mtype in _NO_POSITION:
        return nav_from_ekf_status(msg, gps_t_boot_ns)
    return None


def is_autopilot_heartbeat(msg: Any) -> bool:
    """A HEARTBEAT of a real autopilot (not of a GCS or companion: MAV_AUTOPILOT_INVALID)."""
    return bool(msg.get_type() == "HEARTBEAT" and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID)
