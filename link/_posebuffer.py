"""Vehicle pose at an arbitrary instant from buffered telemetry samples (pure).

Position (GLOBAL_POSITION_INT) is interpolated linearly between the two samples that bracket
the requested time, or dead-reckoned from the newest sample's velocity over a short gap.
Attitude (ATTITUDE / ATTITUDE_QUATERNION) is slerped (shortest arc, so yaw wrapping through
+-pi is harmless), or propagated with the newest body rates over a short gap. A pose is
refused (:class:`PoseUnavailable`) when the bracketing samples are too far apart, when the
newest sample is too old, or when the time is older than the buffer holds; and refused as
:class:`PoseInvalid` when the autopilot does not have the position it reports (no 3-D GPS
fix, an estimator without a horizontal position, lat = lon = 0, a jump: see
:mod:`link._posevalidity`).
"""

from __future__ import annotations

import bisect
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from holescan.geotag import LocalFrame, VehiclePose
from holescan.link._posevalidity import GpsFix, NavStatus, PoseValidity, PositionSample
from holescan.link.errors import PoseUnavailable

__all__ = [
    "AttitudeSample",
    "PoseBuffer",
    "quat_from_euler",
]


@dataclass(frozen=True)
class AttitudeSample:
    """One ATTITUDE / ATTITUDE_QUATERNION.

    t_boot_ns : autopilot boot time, ns.
    quat_wxyz : rotation body (FRD) -> NED as a unit quaternion (w, x, y, z).
    rate_frd : body angular rates (roll, pitch, yaw speed), rad/s.
    """

    t_boot_ns: int
    quat_wxyz: tuple[float, float, float, float]
    rate_frd: tuple[float, float, float] = (0.0, 0.0, 0.0)


def quat_from_euler(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """MAVLink Euler angles (rad; yaw-pitch-roll, body FRD to NED) -> (w, x, y, z)."""
    return _wxyz(Rotation.from_euler("ZYX", [yaw, pitch, roll]))


def _rotation(q: tuple[float, float, float, float]) -> Rotation:
    return Rotation.from_quat(q, scalar_first=True)


S = TypeVar("S", PositionSample, AttitudeSample)


class _Series(Generic[S]):
    """Time-sorted samples with a bounded length (amortised trimming)."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.items: list[S] = []
        self.times: list[int] = []

    def add(self, s: S) -> bool:
        if self.times and s.t_boot_ns <= self.times[-1]:
            return False
        self.items.append(s)
        self.times.append(s.t_boot_ns)
        if len(self.items) > 2 * self.capacity:
            del self.items[: -self.capacity]
            del self.times[: -self.capacity]
        return True

    def clear(self) -> None:
        self.items.clear()
        self.times.clear()

    def oldest_ns(self) -> int:
        return self.times[max(0, len(self.times) - self.capacity)]


class PoseBuffer:
    """Ring buffers of position and attitude samples; :meth:`pose_at` any recent instant.

    Thread-safe (one lock): the telemetry thread adds, the capture thread asks.

    Parameters
    ----------
    capacity : samples kept per series (older ones are forgotten).
    max_gap_ns : refuse to interpolate between samples further apart than this, ns.
    max_extrapolation_ns : extrapolate past the newest sample at most this far, ns.
    reboot_ns : a sample this much older than the newest means the autopilot rebooted
        (its boot clock restarted): the buffer is cleared, ns.
    validity : what decides whether a position is real (default :class:`PoseValidity`).
    """

    def __init__(
        self,
        *,
        capacity: int = 1024,
        max_gap_ns: int = 500_000_000,
        max_extrapolation_ns: int = 200_000_000,
        reboot_ns: int = 2_000_000_000,
        validity: PoseValidity | None = None,
    ) -> None:
        if capacity < 2 or max_gap_ns <= 0 or max_extrapolation_ns < 0:
            raise ValueError("need capacity >= 2, max_gap_ns > 0, max_extrapolation_ns >= 0")
        self.max_gap_ns = max_gap_ns
        self.max_extrapolation_ns = max_extrapolation_ns
        self._reboot_ns = reboot_ns
        self._pos: _Series[PositionSample] = _Series(capacity)
        self._att: _Series[AttitudeSample] = _Series(capacity)
        self.validity = validity if validity is not None else PoseValidity()
        self._latest_fix: GpsFix | None = None
        self._lock = threading.Lock()
        self.n_rejected = 0
        self.n_reboots = 0

    # -- input ----------------------------------------------------------------------------

    def add_position(self, s: PositionSample) -> bool:
        """Add a position; False when dropped (not newer than the newest: duplicate/late)."""
        with self._lock:
            self._check_reboot(s.t_boot_ns)
            ok = self._pos.add(s)
            self.n_rejected += not ok
            if ok:
                self.validity.add_position(s)
            return ok

    def add_attitude(self, s: AttitudeSample) -> bool:
        """Add an attitude; False when dropped (not newer than the newest: duplicate/late)."""
        with self._lock:
            self._check_reboot(s.t_boot_ns)
            ok = self._att.add(s)
            self.n_rejected += not ok
            return ok

    def add_gps(self, fix: GpsFix) -> None:
        """Remember a GPS fix (its type decides whether poses after it are real; its
        accuracy is attached to them)."""
        with self._lock:
            self.validity.add_fix(fix)
            self._latest_fix = fix

    def add_nav(self, status: NavStatus) -> None:
        """Remember an estimator status (whether it has a horizontal position)."""
        with self._lock:
            self.validity.add_nav(status)

    def clear(self) -> None:
        with self._lock:
            self._pos.clear()
            self._att.clear()
            self.validity.clear()
            self._latest_fix = None

    def _check_reboot(self, t_boot_ns: int) -> None:
        newest = max(self._pos.times[-1:] + self._att.times[-1:], default=None)
        if newest is not None and t_boot_ns < newest - self._reboot_ns:
            self.n_reboots += 1
            self._pos.clear()
            self._att.clear()
            self.validity.clear()
            self._latest_fix = None

    # -- output ---------------------------------------------------------------------------

    @property
    def newest_t_boot_ns(self) -> int | None:
        """Boot time of the newest position or attitude sample (the older of the two), ns."""
        with self._lock:
            if not self._pos.times or not self._att.times:
                return None
            return min(self._pos.times[-1], self._att.times[-1])

    def latest_gps(self) -> GpsFix | None:
        with self._lock:
            return self._latest_fix

    def pose_at(self, t_boot_ns: int) -> VehiclePose:
        """Vehicle pose at autopilot boot time ``t_boot_ns``.

        Raises
        ------
        PoseUnavailable
            No samples yet, samples bracketing ``t_boot_ns`` more than ``max_gap_ns`` apart,
            newest sample older than ``max_extrapolation_ns``, or ``t_boot_ns`` older than the
            buffer holds; :class:`PoseInvalid` (a subclass) when the autopilot did not have
            the position it reported then.
        """
        with self._lock:
            pos, pos_age = _at(self._pos, t_boot_ns, "position", self, _lerp_position, _dr)
            q, att_age = _at(self._att, t_boot_ns, "attitude", self, _slerp, _propagate)
            self.validity.check(t_boot_ns, _bracket(self._pos, t_boot_ns))
            fix = self.validity.fix_at(t_boot_ns)
        yaw, pitch, roll = _rotation(q).as_euler("ZYX")
        return VehiclePose(
            t_boot_ns=t_boot_ns,
            lat_deg=pos.lat_deg,
            lon_deg=pos.lon_deg,
            alt_m=pos.alt_m,
            rel_alt_m=pos.rel_alt_m,
            roll=float(roll),
            pitch=float(pitch),
            yaw=float(yaw),
            vn=pos.vn,
            ve=pos.ve,
            vd=pos.vd,
            eph_m=fix.eph_m if fix is not None else math.nan,
            age_ns=max(pos_age, att_age),
        )


T = TypeVar("T")


def _at(
    series: _Series[S],
    t: int,
    what: str,
    buf: PoseBuffer,
    interp: Callable[[S, S, float], T],
    extrap: Callable[[S, int], T],
) -> tuple[T, int]:
    """Interpolate/extrapolate ``series`` at ``t``; return (value, age of nearest sample ns)."""
    times = series.times
    if not times:
        raise PoseUnavailable(f"no {what} telemetry received yet")
    oldest = series.oldest_ns()
    if t < oldest:
        raise PoseUnavailable(
            f"time is {(oldest - t) / 1e9:.3f} s older than the oldest buffered {what} sample"
        )
    i = bisect.bisect_right(times, t)
    if i == len(times):
        newest = series.items[-1]
        dt = t - newest.t_boot_ns
        if dt > buf.max_extrapolation_ns:
            raise PoseUnavailable(
                f"newest {what} sample is {dt / 1e9:.3f} s old "
                f"(limit {buf.max_extrapolation_ns / 1e9:.3f} s)"
            )
        return extrap(newest, dt), dt
    a, b = series.items[i - 1], series.items[i]
    gap = b.t_boot_ns - a.t_boot_ns
    if gap > buf.max_gap_ns:
        raise PoseUnavailable(
            f"{what} samples around the time are {gap / 1e9:.3f} s apart "
            f"(limit {buf.max_gap_ns / 1e9:.3f} s)"
        )
    f = (t - a.t_boot_ns) / gap
    return interp(a, b, f), min(t - a.t_boot_ns, b.t_boot_ns - t)


def _bracket(series: _Series[PositionSample], t: int) -> tuple[PositionSample, ...]:
    """The position samples a pose at ``t`` is made of: the pair around it, or the newest."""
    i = bisect.bisect_right(series.times, t)
    return tuple(series.items[max(i - 1, 0) : i + 1])


def _lerp_position(a: PositionSample, b: PositionSample, f: float) -> PositionSample:
    dlon = (b.lon_deg - a.lon_deg + 180.0) % 360.0 - 180.0  # across the antimeridian
    lon = a.lon_deg + f * dlon
    lon = (lon + 180.0) % 360.0 - 180.0
    return PositionSample(
        t_boot_ns=a.t_boot_ns + round(f * (b.t_boot_ns - a.t_boot_ns)),
        lat_deg=a.lat_deg + f * (b.lat_deg - a.lat_deg),
        lon_deg=lon,
        alt_m=a.alt_m + f * (b.alt_m - a.alt_m),
        rel_alt_m=a.rel_alt_m + f * (b.rel_alt_m - a.rel_alt_m),
        vn=a.vn + f * (b.vn - a.vn),
        ve=a.ve + f * (b.ve - a.ve),
        vd=a.vd + f * (b.vd - a.vd),
    )


def _dr(s: PositionSample, dt_ns: int) -> PositionSample:
    """Dead-reckon ``dt_ns`` ahead at constant NED velocity, in the local frame at ``s``."""
    dt = dt_ns / 1e9
    lat, lon = LocalFrame(s.lat_deg, s.lon_deg, s.alt_m).to_geodetic(s.ve * dt, s.vn * dt)
    return PositionSample(
        t_boot_ns=s.t_boot_ns + dt_ns,
        lat_deg=float(lat),
        lon_deg=float(lon),
        alt_m=s.alt_m - s.vd * dt,
        rel_alt_m=s.rel_alt_m - s.vd * dt,
        vn=s.vn,
        ve=s.ve,
        vd=s.vd,
    )


def _slerp(a: AttitudeSample, b: AttitudeSample, f: float) -> tuple[float, float, float, float]:
    ra, rb = _rotation(a.quat_wxyz), _rotation(b.quat_wxyz)
    step = (ra.inv() * rb).as_rotvec()  # shortest arc, |angle| <= pi
    return _wxyz(ra * Rotation.from_rotvec(f * step))


def _propagate(s: AttitudeSample, dt_ns: int) -> tuple[float, float, float, float]:
    """Rotate by the body rates for ``dt_ns`` (rates in the body frame: right-multiply)."""
    rotvec = np.asarray(s.rate_frd, dtype=float) * (dt_ns / 1e9)
    return _wxyz(_rotation(s.quat_wxyz) * Rotation.from_rotvec(rotvec))


def _wxyz(r: Rotation) -> tuple[float, float, float, float]:
    w, x, y, z = (float(v) for v in r.as_quat(scalar_first=True))
    return (w, x, y, z)
