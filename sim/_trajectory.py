"""The simulated vehicle's motion: a path of local ENU waypoints flown as a periodic cubic
spline, yaw along the track, roll and pitch tilting the thrust against the acceleration."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from holescan.geotag import LocalFrame
from holescan.link import mavlink

_ABOVE_HOME = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
_ABOVE_MSL = (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT)

__all__ = ["SimPath"]

_G = 9.80665


@dataclass(frozen=True)
class SimPath:
    """Where the simulated vehicle flies.

    home_lat_deg, home_lon_deg : WGS84 home; home_alt_m : home altitude above MSL, m.
    waypoints_enu : (east, north, up) metres from home, flown as a closed loop (>= 3 points).
    speed_m_s : cruise speed, m/s.
    wobble_rad : amplitude of the roll/pitch oscillation (wind, control loop), rad.
    """

    home_lat_deg: float = 43.6532
    home_lon_deg: float = -79.3832
    home_alt_m: float = 120.0
    waypoints_enu: tuple[tuple[float, float, float], ...] = (
        (0.0, 0.0, 10.0),
        (40.0, 0.0, 10.0),
        (40.0, 20.0, 12.0),
        (0.0, 20.0, 12.0),
    )
    speed_m_s: float = 5.0
    wobble_rad: float = math.radians(1.5)

    @classmethod
    def from_waypoints(
        cls,
        home_lat_deg: float,
        home_lon_deg: float,
        home_alt_m: float,
        waypoints: Iterable[_GeoPoint],
        **kw: Any,
    ) -> SimPath:
        """A path through mission waypoints (e.g. :class:`missions.Waypoint`), as a loop.

        Altitudes are above home for MAV_FRAME_GLOBAL_RELATIVE_ALT (3, and its _INT twin 6),
        above MSL for MAV_FRAME_GLOBAL (0, 5); items without a position are skipped, and
        so are repeats of the previous point. ``kw``: the other :class:`SimPath` fields.
        """
        enu: list[tuple[float, float, float]] = []
        home = LocalFrame(home_lat_deg, home_lon_deg, home_alt_m)
        for wp in waypoints:
            frame = getattr(wp, "frame", mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT)
            if frame not in _ABOVE_HOME and frame not in _ABOVE_MSL:
                continue
            alt_msl = wp.alt_m + (home_alt_m if frame in _ABOVE_HOME else 0.0)
            e, n, u = home.to_enu(wp.lat_deg, wp.lon_deg, alt_msl)
            point = (float(e), float(n), float(u))
            if not enu or math.dist(point, enu[-1]) > 1e-3:
                enu.append(point)
        if len(enu) > 1 and math.dist(enu[0], enu[-1]) <= 1e-3:
            enu.pop()  # the loop closes by itself
        return cls(home_lat_deg, home_lon_deg, home_alt_m, tuple(enu), **kw)


class _GeoPoint(Protocol):
    @property
    def lat_deg(self) -> float: ...
    @property
    def lon_deg(self) -> float: ...
    @property
    def alt_m(self) -> float: ...


class Trajectory:
    """The path as periodic splines of time; state and attitude at any time (s)."""

    def __init__(self, path: SimPath) -> None:
        pts = np.asarray(path.waypoints_enu, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
            raise ValueError("waypoints_enu needs at least 3 (east, north, up) points")
        if not path.speed_m_s > 0:
            raise ValueError("speed_m_s must be > 0")
        loop = np.vstack([pts, pts[:1]])
        legs = np.linalg.norm(np.diff(loop, axis=0), axis=1)
        if np.any(legs < 1e-6):
            raise ValueError("consecutive waypoints must differ")
        knots = np.concatenate([[0.0], np.cumsum(legs)]) / path.speed_m_s
        self.period_s = float(knots[-1])
        self._spline = CubicSpline(knots, loop, bc_type="periodic", axis=0)
        self._wobble = path.wobble_rad
        grid = np.linspace(0.0, self.period_s, 2000)
        speed = np.linalg.norm(self._spline(grid, 1)[:, :2], axis=1)
        if speed.min() < 0.3 * path.speed_m_s:
            raise ValueError(
                "the path turns too tightly for its speed (the vehicle would stop and yaw "
                "would be undefined): spread the waypoints or add intermediate ones"
            )

    def kinematics(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ENU position (m), velocity (m/s) and acceleration (m/s^2) at time ``tau`` (s)."""
        t = tau % self.period_s
        return self._spline(t), self._spline(t, 1), self._spline(t, 2)

    def rotation(self, tau: float) -> Rotation:
        """Body (FRD) -> NED rotation at ``tau``."""
        _, v, a = self.kinematics(tau)
        yaw = math.atan2(v[0], v[1])
        thrust = np.array([a[1], a[0], -a[2] - _G])  # NED: acceleration minus gravity
        z_b = -thrust / np.linalg.norm(thrust)
        x_c = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        y_b = np.cross(z_b, x_c)
        y_b /= np.linalg.norm(y_b)
        x_b = np.cross(y_b, z_b)
        base = Rotation.from_matrix(np.column_stack([x_b, y_b, z_b]))
        y, p, r = base.as_euler("ZYX")
        w = self._wobble
        r += w * math.sin(2 * math.pi * 0.9 * tau)
        p += w * math.sin(2 * math.pi * 1.3 * tau + 1.0)
        y += 0.3 * w * math.sin(2 * math.pi * 0.4 * tau + 2.0)
        return Rotation.from_euler("ZYX", [y, p, r])

    def body_rates(self, tau: float, h: float = 1e-3) -> np.ndarray:
        """Angular velocity in the body frame (roll, pitch, yaw rate), rad/s."""
        step = self.rotation(tau - h).inv() * self.rotation(tau + h)
        return np.asarray(step.as_rotvec() / (2 * h))
