"""Whether the autopilot *has* the position it reports (pure; used by the pose buffer).

An autopilot streams GLOBAL_POSITION_INT whether or not its estimator knows where it is:
ArduPilot sends lat = lon = 0 before its EKF has an origin, keeps dead-reckoning (and
drifting) after the GPS fix is lost, and jumps when the EKF resets onto a new fix. A frame
posed from such a sample puts its holes in the wrong place (issue 20: two holes announced
at Null Island). :class:`PoseValidity` keeps what says whether a position is real and
refuses (:class:`capture.errors.PoseInvalid`) a pose at a time when

* the GPS had no 3-D fix (the latest GPS_RAW_INT at or before it has ``fix_type < 3``, or
  GPS_RAW_INT stopped arriving), once the autopilot has sent any GPS_RAW_INT;
* the estimator had no absolute horizontal position (EKF_STATUS_REPORT / ESTIMATOR_STATUS
  without POS_HORIZ_ABS, or in constant-position mode, or flagging a GPS glitch), once it
  has sent any such status;
* a position sample it would use lies at lat = lon = 0 (within ``null_island_deg``);
* it falls from the sample before a position jump (farther than ``max_speed_m_s`` times
  the time between two samples plus ``jump_slack_m``) to ``settle_ns`` after it: an
  estimator reset or a glitch, which of the two sides is right is not known until the new
  track has lasted.

An autopilot that sends neither GPS_RAW_INT nor an estimator status (an indoor vehicle on
motion capture, a log without them) is judged by the last two rules only.
"""

from __future__ import annotations

import bisect
import logging
import math
from dataclasses import dataclass

from holescan.geotag import local_en_m
from holescan.link.errors import PoseInvalid

__all__ = ["GpsFix", "NavStatus", "PoseValidity", "PositionSample", "is_null_island"]

_log = logging.getLogger("holescan.link._posebuffer")

_GPS_3D = 3


@dataclass(frozen=True)
class PositionSample:
    """One GLOBAL_POSITION_INT, in SI units.

    t_boot_ns : autopilot boot time, ns. lat_deg, lon_deg : WGS84. alt_m : above MSL, m.
    rel_alt_m : above home, m. vn, ve, vd : NED velocity, m/s.
    """

    t_boot_ns: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    rel_alt_m: float
    vn: float
    ve: float
    vd: float


@dataclass(frozen=True)
class GpsFix:
    """One GPS_RAW_INT, in SI units.

    t_boot_ns : autopilot boot time the fix was received at (estimated), ns.
    fix_type : MAVLink GPS_FIX_TYPE (0-1 none, 2 = 2D, 3 = 3D, 4 DGPS, 5/6 RTK float/fixed).
    satellites : visible satellites (-1 unknown).
    hdop : horizontal dilution of precision (NaN unknown).
    h_acc_m, v_acc_m : 1-sigma position accuracy the receiver reports, m (NaN unknown).
    lat_deg, lon_deg, alt_m : the receiver's own position (MSL), unfiltered.
    """

    t_boot_ns: int
    fix_type: int
    satellites: int
    hdop: float
    h_acc_m: float
    v_acc_m: float
    lat_deg: float
    lon_deg: float
    alt_m: float

    @property
    def eph_m(self) -> float:
        """1-sigma horizontal accuracy, m: ``h_acc_m``; inf without a fix; NaN if unreported."""
        if self.fix_type < 2:
            return math.inf
        return self.h_acc_m


@dataclass(frozen=True)
class NavStatus:
    """One estimator status (ArduPilot EKF_STATUS_REPORT or PX4 ESTIMATOR_STATUS).

    t_boot_ns : autopilot boot time it was received at (estimated), ns.
    horizontal_ok : the estimator has an absolute horizontal position (POS_HORIZ_ABS set,
        not in constant-position mode, no GPS glitch flagged).
    flags : the message's flags as sent. source : the message's name.
    """

    t_boot_ns: int
    horizontal_ok: bool
    flags: int
    source: str


def is_null_island(lat_deg: float, lon_deg: float, tol_deg: float = 1e-4) -> bool:
    """True for a position within ``tol_deg`` of lat = lon = 0 (an autopilot's "nothing")."""
    return abs(lat_deg) < tol_deg and abs(lon_deg) < tol_deg


class _Timed:
    """Records sorted by ``t_boot_ns`` (inserted in any order), at most ``capacity``."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.times: list[int] = []
        self.items: list[GpsFix | NavStatus] = []
        self.trimmed = False

    def add(self, item: GpsFix | NavStatus) -> None:
        i = bisect.bisect_right(self.times, item.t_boot_ns)
        self.times.insert(i, item.t_boot_ns)
        self.items.insert(i, item)
        if len(self.items) > 2 * self.capacity:
            del self.items[: -self.capacity]
            del self.times[: -self.capacity]
            self.trimmed = True

    def at(self, t_boot_ns: int) -> GpsFix | NavStatus | None:
        """The newest record at or before the time; before the first: the first (None if
        none, or if older records were forgotten)."""
        i = bisect.bisect_right(self.times, t_boot_ns)
        if i:
            return self.items[i - 1]
        return None if self.trimmed or not self.items else self.items[0]

    def clear(self) -> None:
        self.times.clear()
        self.items.clear()
        self.trimmed = False


class PoseValidity:
    """GPS fixes, estimator states and position jumps; :meth:`check` a pose's time.

    Not thread-safe: :class:`link.PoseBuffer` calls it under its lock.

    Parameters
    ----------
    max_speed_m_s : no vehicle of ours moves faster: a step between two position samples
        longer than this times their spacing, plus ``jump_slack_m``, is a jump, m/s.
    jump_slack_m : position noise allowed on top, m.
    settle_ns : after a jump, the new track must last this long before it is used, ns.
    stale_ns : GPS_RAW_INT or the estimator status older than this at the pose's time
        (they stopped arriving) counts as no fix, ns.
    null_island_deg : positions this close to lat = lon = 0 are "no position", deg.
    capacity : records kept per kind.
    """

    def __init__(
        self,
        *,
        max_speed_m_s: float = 40.0,
        jump_slack_m: float = 5.0,
        settle_ns: int = 2_000_000_000,
        stale_ns: int = 3_000_000_000,
        null_island_deg: float = 1e-4,
        capacity: int = 512,
    ) -> None:
        self.max_speed_m_s = max_speed_m_s
        self.jump_slack_m = jump_slack_m
        self.settle_ns = settle_ns
        self.stale_ns = stale_ns
        self.null_island_deg = null_island_deg
        self._fixes = _Timed(capacity)
        self._nav = _Timed(capacity)
        self._jumps: list[tuple[int, int, float]] = []  # (t before, t after, metres)
        self._ref: PositionSample | None = None
        self.n_jumps = 0

    # -- input ----------------------------------------------------------------------------

    def add_fix(self, fix: GpsFix) -> None:
        self._fixes.add(fix)

    def add_nav(self, status: NavStatus) -> None:
        self._nav.add(status)

    def add_position(self, s: PositionSample) -> None:
        """A position sample was added (in time order): look for a jump from the last one."""
        if self.null_island(s):
            return  # "no position" is no reference for the next
        ref = self._ref
        self._ref = s
        if ref is None or s.t_boot_ns <= ref.t_boot_ns:
            return
        dt = (s.t_boot_ns - ref.t_boot_ns) / 1e9
        east, north = local_en_m(s.lat_deg, s.lon_deg, ref.lat_deg, ref.lon_deg)
        step = math.sqrt(east * east + north * north + (s.alt_m - ref.alt_m) ** 2)
        if step > self.max_speed_m_s * dt + self.jump_slack_m:
            self.n_jumps += 1
            self._jumps.append((ref.t_boot_ns, s.t_boot_ns, step))
            if len(self._jumps) > 64:
                del self._jumps[:-32]
            _log.warning(
                "autopilot position jumped %.1f m in %.2f s (estimator reset or glitch): "
                "no pose from the sample before it to %.1f s after it",
                step,
                dt,
                self.settle_ns / 1e9,
            )

    def clear(self) -> None:
        self._fixes.clear()
        self._nav.clear()
        self._jumps.clear()
        self._ref = None

    # -- queries ----------------------------------------------------------------------------

    def null_island(self, s: PositionSample) -> bool:
        return is_null_island(s.lat_deg, s.lon_deg, self.null_island_deg)

    def fix_at(self, t_boot_ns: int) -> GpsFix | None:
        """The GPS fix in force at the time (see :meth:`_Timed.at`), or None."""
        fix = self._fixes.at(t_boot_ns)
        assert fix is None or isinstance(fix, GpsFix)
        return fix

    def check(self, t_boot_ns: int, samples: tuple[PositionSample, ...]) -> None:
        """Raise :class:`PoseInvalid` when the pose at ``t_boot_ns`` built from the position
        ``samples`` (the bracketing pair, or the newest one) is not a real position."""
        for s in samples:
            if self.null_island(s):
                raise PoseInvalid(
                    f"the autopilot reports lat {s.lat_deg:.7f}, lon {s.lon_deg:.7f} "
                    "(no position yet)"
                )
        for t_a, t_b, step in reversed(self._jumps):
            if t_a < t_boot_ns <= t_b + self.settle_ns:
                raise PoseInvalid(
                    f"the autopilot's position jumped {step:.1f} m in {(t_b - t_a) / 1e9:.2f} s "
                    f"here (estimator reset or glitch; the new track is trusted "
                    f"{self.settle_ns / 1e9:g} s after it)"
                )
        if self._fixes.items:
            fix = self.fix_at(t_boot_ns)
            if fix is None:
                raise PoseInvalid("the GPS fix at that time is no longer known")
            if fix.fix_type < _GPS_3D:
                raise PoseInvalid(f"no 3-D GPS fix (GPS_RAW_INT fix_type {fix.fix_type})")
            if t_boot_ns - fix.t_boot_ns > self.stale_ns:
                raise PoseInvalid(
                    f"no GPS_RAW_INT for {(t_boot_ns - fix.t_boot_ns) / 1e9:.1f} s before it"
                )
        if self._nav.items:
            nav = self._nav.at(t_boot_ns)
            if nav is None:
                raise PoseInvalid("the estimator's state at that time is no longer known")
            assert isinstance(nav, NavStatus)
            if not nav.horizontal_ok:
                raise PoseInvalid(
                    f"the estimator has no horizontal position ({nav.source} flags 0x{nav.flags:x})"
                )
            if t_boot_ns - nav.t_boot_ns > self.stale_ns:
                raise PoseInvalid(
                    f"no {nav.source} for {(t_boot_ns - nav.t_boot_ns) / 1e9:.1f} s before it"
                )
