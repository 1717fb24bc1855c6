"""Records geotagging takes and returns: vehicle pose, camera mount."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class VehiclePose:
    """Vehicle state at one instant, on the autopilot's clock.

    t_boot_ns : autopilot boot-clock time, ns.
    lat_deg, lon_deg : WGS84; alt_m : altitude above mean sea level (as MAVLink's
        GLOBAL_POSITION_INT.alt); rel_alt_m : above home.
    roll, pitch, yaw : rad, body frame FRD relative to NED (MAVLink ATTITUDE).
    vn, ve, vd : velocity in NED, m/s.
    eph_m : 1-sigma horizontal GPS accuracy, metres (NaN when unknown).
    age_ns : time between this pose and the nearest telemetry sample used to make it.
    """

    t_boot_ns: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    rel_alt_m: float
    roll: float
    pitch: float
    yaw: float
    vn: float = 0.0
    ve: float = 0.0
    vd: float = 0.0
    eph_m: float = float("nan")
    age_ns: int = 0
