"""A bag's vehicle pose as the MAVLink telemetry a holescan flight log holds.

A bag poses its frames when it has a GNSS fix (``sensor_msgs/NavSatFix``) and an attitude
(``sensor_msgs/Imu`` orientation), such as MAVROS records them
(``/mavros/global_position/global``, ``/mavros/imu/data``). Both are turned into the
packets an autopilot would have sent (HEARTBEAT, HOME_POSITION at the first fix,
GLOBAL_POSITION_INT, GPS_RAW_INT, ATTITUDE_QUATERNION) on a boot clock that starts 1 s
before the bag's first message, so reprocessing poses the frames through the same telemetry
decoder as a flight's.

Conventions (REP 103 / 145, as MAVROS publishes): orientation of the body (x forward,
y left, z up) in ENU; it becomes MAVLink's body (x forward, y right, z down) in NED.
NavSatFix altitude is passed on as it is (REP 145: above the WGS 84 ellipsoid; MAVLink's
``alt`` is above mean sea level): only the height above the first fix (``relative_alt``)
and the horizontal position matter to where a hole is placed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from scipy.spatial.transform import Rotation

from holescan.link import mavlink

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader

__all__ = ["BagTelemetry", "enu_flu_to_ned_frd", "read_bag_telemetry"]

NAVSATFIX: Final = "sensor_msgs/msg/NavSatFix"
IMU: Final = "sensor_msgs/msg/Imu"
MAVROS_FIX: Final = "/mavros/global_position/global"
MAVROS_IMU: Final = "/mavros/imu/data"
_ENU_TO_NED: Final = Rotation.from_matrix([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_FRD_TO_FLU: Final = Rotation.from_matrix([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
_FIX_TYPE: Final = {-1: 1, 0: 3, 1: 4, 2: 6}  # NavSatStatus -> GPS_FIX_TYPE (none, 3D, DGPS, RTK)


def enu_flu_to_ned_frd(q_xyzw: tuple[float, float, float, float]) -> tuple[float, ...]:
    """ROS orientation (body FLU in ENU, x y z w) -> MAVLink's (body FRD in NED, w x y z).

    Examples
    --------
    >>> [round(float(v), 6) + 0.0 for v in enu_flu_to_ned_frd((0.0, 0.0, 0.0, 1.0))]  # level, east
    [0.707107, 0.0, 0.0, 0.707107]
    """
    r = _ENU_TO_NED * Rotation.from_quat(q_xyzw) * _FRD_TO_FLU
    x, y, z, w = r.as_quat()
    return (float(w), float(x), float(y), float(z)) if w >= 0 else (-w, -x, -y, -z)


@dataclass(frozen=True)
class BagTelemetry:
    """Packets in time order: ``(t_unix_ns, packet)``; ``boot_unix_ns`` is the Unix time of
    boot-clock zero (a frame at ``t`` is at boot time ``t - boot_unix_ns``)."""

    fix_topic: str
    imu_topic: str
    packets: tuple[tuple[int, bytes], ...]
    boot_unix_ns: int
    fixes: int
    attitudes: int
    skipped: int


def _stamp(msg: Any, t_bag: int) -> int:
    from holescan.ground.recordings.rosbag import stamp_ns

    return stamp_ns(msg, t_bag)


def _pick(reader: AnyReader, msgtype: str, preferred: str) -> str | None:
    topics = sorted({c.topic for c in reader.connections if c.msgtype == msgtype})
    return preferred if preferred in topics else (topics[0] if topics else None)


def read_bag_telemetry(reader: AnyReader, first_ns: int) -> BagTelemetry | None:
    """The telemetry of an open bag, or None without both a NavSatFix and an Imu topic.
    ``first_ns``: the earliest time the frames use (the boot clock starts 1 s before it
    or the first telemetry message, whichever is earlier)."""
    fix_topic = _pick(reader, NAVSATFIX, MAVROS_FIX)
    imu_topic = _pick(reader, IMU, MAVROS_IMU)
    if fix_topic is None or imu_topic is None:
        return None
    conns = [c for c in reader.connections if c.topic in (fix_topic, imu_topic)]
    samples: list[tuple[int, str, Any]] = []
    skipped = 0
    for conn, t_bag, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        kind = "fix" if conn.topic == fix_topic else "imu"
        if (kind == "fix" and _valid_fix(msg)) or (kind == "imu" and _valid_attitude(msg)):
            samples.append((_stamp(msg, t_bag), kind, msg))
        else:
            skipped += 1
    fixes = [s for s in samples if s[1] == "fix"]
    if not fixes or len(fixes) == len(samples):
        return None
    samples.sort(key=lambda s: s[0])
    boot = min(first_ns, samples[0][0]) - 1_000_000_000
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    home = fixes[0][2]  # the first fix is home (as an autopilot sets it at arming)
    home_alt_m = float(home.altitude)
    packets = [
        (
            boot,
            mav.heartbeat_encode(
                mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4
            ).pack(mav),
        )
    ]
    home_msg = mav.home_position_encode(
        round(float(home.latitude) * 1e7),
        round(float(home.longitude) * 1e7),
        round(home_alt_m * 1000),
        0.0,
        0.0,
        0.0,
        (1.0, 0.0, 0.0, 0.0),
        0.0,
        0.0,
        0.0,
    )
    packets.append((boot, home_msg.pack(mav)))
    for t, kind, msg in samples:
        ms = (t - boot) // 1_000_000
        if kind == "imu":
            o = msg.orientation
            q = enu_flu_to_ned_frd((float(o.x), float(o.y), float(o.z), float(o.w)))
            packets.append((t, mav.attitude_quaternion_encode(ms, *q, 0.0, 0.0, 0.0).pack(mav)))
            continue
        lat, lon, alt = float(msg.latitude), float(msg.longitude), float(msg.altitude)
        lat_e7, lon_e7 = round(lat * 1e7), round(lon * 1e7)
        alt_mm, rel_mm = round(alt * 1000), round((alt - home_alt_m) * 1000)
        pos = mav.global_position_int_encode(ms, lat_e7, lon_e7, alt_mm, rel_mm, 0, 0, 0, 65535)
        cov = np.asarray(msg.position_covariance, dtype=np.float64)
        known = int(msg.position_covariance_type) > 0 and cov.size == 9 and cov[0] >= 0
        h_acc = round(math.sqrt(max(cov[0], cov[4])) * 1000) if known else 0
        fix_type = _FIX_TYPE.get(int(msg.status.status), 1)
        gps = mav.gps_raw_int_encode(
            (t - boot) // 1000,
            fix_type,
            lat_e7,
            lon_e7,
            alt_mm,
            65535,
            65535,
            65535,
            65535,
            255,
            0,
            min(h_acc, 2**32 - 1),
        )
        packets.append((t, pos.pack(mav)))
        packets.append((t, gps.pack(mav)))
    return BagTelemetry(
        fix_topic=fix_topic,
        imu_topic=imu_topic,
        packets=tuple(packets),
        boot_unix_ns=boot,
        fixes=len(fixes),
        attitudes=len(samples) - len(fixes),
        skipped=skipped,
    )


def _valid_fix(msg: Any) -> bool:
    """A fix with finite, in-range coordinates (a NO_FIX status is kept: it says no fix)."""
    try:
        lat, lon, alt = float(msg.latitude), float(msg.longitude), float(msg.altitude)
    except (TypeError, ValueError):
        return False
    return (
        all(math.isfinite(v) for v in (lat, lon, alt))
        and -90.0 <= lat <= 90.0
        and -180.0 <= lon <= 180.0
        and -1000.0 <= alt <= 20000.0
    )


def _valid_attitude(msg: Any) -> bool:
    """An orientation that is a unit quaternion (REP 145: covariance[0] = -1 means none)."""
    o = msg.orientation
    q = np.array([o.x, o.y, o.z, o.w], dtype=np.float64)
    cov = np.asarray(msg.orientation_covariance, dtype=np.float64)
    if cov.size and cov[0] == -1:
        return False
    return bool(np.all(np.isfinite(q)) and abs(float(np.linalg.norm(q)) - 1.0) < 1e-3)
