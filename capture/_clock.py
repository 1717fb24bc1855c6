"""Companion monotonic clock <-> autopilot boot clock <-> UTC, estimated from samples.

Pure: the caller feeds timestamps it measured (TIMESYNC round trips, message arrivals,
SYSTEM_TIME pairs); nothing here reads a clock or touches a link.

Convention: ``t_boot_ns = t_mono_ns + offset_ns``. The offset is followed as a line
``offset(t_mono) = a + b * (t_mono - t_ref)`` (b = relative drift of the two crystals).

TIMESYNC (preferred). The companion sends ``tc1 = 0, ts1 = t0`` (its monotonic ns) and notes
the arrival time ``t1`` of the reply ``tc1 = autopilot boot ns, ts1 = t0``. If the two legs of
the round trip take equally long, ``offset = tc1 - (t0 + t1) / 2``; the error is at most half
the round trip. Samples are binned in time (``bin_ns``); each bin keeps its lowest-round-trip
sample; a weighted line is fitted to the bins of a sliding window (``window_ns``).

Arrival (fallback, when no TIMESYNC answers). A message stamped ``time_boot_ms`` that arrived
at ``t_mono`` says ``offset >= boot - t_mono`` (the link never delivers early); each bin keeps
the largest value (the lower envelope of ``t_mono - boot``) and the line is the lowest one
above all of them (a bin whose every message came late, during a stall, is under it).
The result is late by the link's smallest latency plus up to 1 ms of ``time_boot_ms``
truncation, which ``arrival_floor_ns`` states as the uncertainty.

Steps. A sample far off the line (``step_ns``) is not taken. It restarts the estimate only
when it is part of consistent evidence: ``step_count`` samples in a row off the line on the
same side, agreeing with each other within ``step_ns``, and (arrivals) spanning at least
``step_span_ns`` of companion time; the estimate then restarts from those samples. A
message that arrives late is not a step: an overloaded companion reads its telemetry in
bursts after a stall, every message of the burst late by the stall (seconds at load 25-30),
and then on time again, so the burst neither agrees with itself nor lasts. A TIMESYNC
sample's error is bounded by half its round trip (``max_rtt_ns``), so its steps need no
span. An autopilot reboot is found at once by its boot clock going back (the caller resets,
:meth:`ClockSync.reset`); a reboot the boot clock does not show (the link was down longer
than the autopilot had been up) is a step that lasts, taken after ``step_span_ns``.
"""

from __future__ import annotations

import logging
import statistics
import threading
from collections import deque
from dataclasses import dataclass
from typing import Literal

import numpy as np

from holescan.capture.errors import ClockUnavailable

__all__ = ["ClockEstimate", "ClockSource", "ClockSync"]

_log = logging.getLogger(__name__)

ClockSource = Literal["timesync", "arrival", "none"]

_NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class ClockEstimate:
    """One snapshot of the offset model ``t_boot_ns = t_mono_ns + offset_at(t_mono_ns)``.

    source : where it comes from ("none" = no estimate; the other fields are then 0).
    ref_mono_ns : companion monotonic time the line is anchored at, ns.
    offset_ns : boot - mono at ``ref_mono_ns``, ns.
    drift : d(offset)/d(t_mono), dimensionless (1e-6 = 1 ppm).
    uncertainty_ns : stated error bound of the offset, ns (see the module docstring).
    n_points : bins the line was fitted to.
    best_rtt_ns : lowest TIMESYNC round trip among those bins (0 for "arrival"/"none").
    """

    source: ClockSource
    ref_mono_ns: int = 0
    offset_ns: int = 0
    drift: float = 0.0
    uncertainty_ns: int = 0
    n_points: int = 0
    best_rtt_ns: int = 0

    def offset_at(self, t_mono_ns: int) -> int:
        """Offset boot - mono at companion monotonic time ``t_mono_ns``, ns."""
        return self.offset_ns + round(self.drift * (t_mono_ns - self.ref_mono_ns))


_NONE = ClockEstimate(source="none")


@dataclass
class _Point:
    x_ns: int  # companion monotonic time of the sample
    y_ns: int  # boot - mono measured there
    cost: int  # the bin keeps the lowest cost
    weight: float


class _Track:
    """Per-bin best samples over a sliding window, a robust weighted line through them."""

    def __init__(
        self,
        *,
        bin_ns: int,
        window_ns: int,
        min_fit_span_ns: int,
        max_drift: float,
        step_ns: int,
        step_count: int,
        step_span_ns: int,
        envelope: bool,
        name: str,
    ) -> None:
        self._bin_ns = bin_ns
        self._window_ns = window_ns
        self._min_fit_span_ns = min_fit_span_ns
        self._max_drift = max_drift
        self._step_ns = step_ns
        self._step_count = step_count
        self._step_span_ns = step_span_ns
        self._envelope = envelope
        self._name = name
        self._bins: dict[int, _Point] = {}
        self._fit: tuple[int, int, float, float] | None = None  # x_ref, y_ref, drift, rms_ns
        # Samples in a row off the line on one side and agreeing with the first of them:
        # the evidence of a step, until it is confirmed or broken.
        self._streak: list[_Point] = []
        self._streak_sign = 0
        self.newest_x_ns: int | None = None
        self.n_off_line = 0  # samples off the line not taken (late arrivals, one-offs)
        self.n_steps = 0  # confirmed steps (the estimate restarted)

    def clear(self) -> None:
        self._bins.clear()
        self._fit = None
        self._streak = []
        self._streak_sign = 0
        self.newest_x_ns = None

    def add(self, p: _Point) -> None:
        if self._fit is not None and self._step_ns > 0:
            x_ref, y_ref, drift, _ = self._fit
            off = p.y_ns - (y_ref + drift * (p.x_ns - x_ref))
            if abs(off) > self._step_ns:
                self.n_off_line += 1
                if self._confirms_step(p, 1 if off > 0 else -1):
                    self._restart(off)
                return
            self._streak = []
        if self._take(p):
            self._refit()

    def _confirms_step(self, p: _Point, sign: int) -> bool:
        """Add ``p`` (off the line) to the evidence; True when it confirms a step."""
        streak = self._streak
        if sign != self._streak_sign or not streak or abs(p.y_ns - streak[0].y_ns) > self._step_ns:
            streak = self._streak = []  # a new run of evidence starts with p
            self._streak_sign = sign
        streak.append(p)
        return (
            len(streak) >= self._step_count
            and streak[-1].x_ns - streak[0].x_ns >= self._step_span_ns
        )

    def _restart(self, off_ns: int | float) -> None:
        streak = self._streak
        _log.warning(
            "%s clock offset stepped by %.3f s (%d samples over %.1f s; autopilot reboot?): "
            "restarting estimate",
            self._name,
            off_ns / _NS_PER_S,
            len(streak),
            (streak[-1].x_ns - streak[0].x_ns) / _NS_PER_S,
        )
        self.clear()
        self.n_steps += 1
        for q in streak:  # the evidence is the new estimate's first samples
            self._take(q)
        self._refit()

    def _take(self, p: _Point) -> bool:
        """Bin ``p``; True when it became its bin's best sample."""
        key = p.x_ns // self._bin_ns
        best = self._bins.get(key)
        if self.newest_x_ns is None or p.x_ns > self.newest_x_ns:
            self.newest_x_ns = p.x_ns
        if best is not None and best.cost <= p.cost:
            return False
        self._bins[key] = p
        oldest = (self.newest_x_ns - self._window_ns) // self._bin_ns
        for k in [k for k in self._bins if k < oldest]:
            del self._bins[k]
        return True

    def points(self) -> list[_Point]:
        return sorted(self._bins.values(), key=lambda q: q.x_ns)

    @property
    def fit(self) -> tuple[int, int, float, float] | None:
        return self._fit

    def _refit(self) -> None:
        pts = self.points()
        if not pts:
            self._fit = None
            return
        x_ref = pts[-1].x_ns
        y_ref = pts[-1].y_ns
        x = np.array([(q.x_ns - x_ref) / _NS_PER_S for q in pts])
        y = np.array([float(q.y_ns - y_ref) for q in pts])
        w = np.array([q.weight for q in pts])
        if self._envelope:
            a, b = self._upper_envelope(x, y)
            late = a + b * x - y  # >= 0: how late each bin's earliest sample was
            self._fit = (x_ref, y_ref + round(a), b / _NS_PER_S, float(np.median(late)))
            return
        keep = np.ones(len(pts), dtype=bool)
        a, b = 0.0, 0.0
        for _ in range(2):  # fit, drop gross outliers (3.5 robust sigma), fit again
            a, b = self._line(x[keep], y[keep], w[keep])
            resid = y - (a + b * x)
            if keep.sum() < 5:
                break
            mad = float(np.median(np.abs(resid[keep] - np.median(resid[keep]))))
            new_keep = np.abs(resid) <= max(3.5 * 1.4826 * mad, 1_000.0)
            if new_keep.sum() < 3 or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        resid = (y - (a + b * x))[keep]
        rms = float(np.sqrt(np.average(resid**2, weights=w[keep])))
        # re-anchor the line at x_ref: offset(x_ref) = y_ref + a, slope in ns/s -> ns/ns
        self._fit = (x_ref, y_ref + round(a), b / _NS_PER_S, rms)

    def _upper_envelope(self, x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
        """The line above every point, lowest on average (slope within ``max_drift``).

        Arrivals can only be late: each point is at or below the truth, so the truth is
        the line over them that is as low as it can be (minimise the mean of ``a + b x - y``
        subject to ``a + b x >= y``). The optimum has a slope between two points (or a
        bound): try them all (a few dozen bins). Below ``min_fit_span_ns`` of data the
        drift is 0 and the line is the highest point.
        """
        span_ns = (x.max() - x.min()) * _NS_PER_S
        if len(x) < 3 or span_ns < self._min_fit_span_ns:
            return float(y.max()), 0.0
        limit = self._max_drift * _NS_PER_S
        dx = x[None, :] - x[:, None]
        pair = np.abs(dx) > 0
        slopes = ((y[None, :] - y[:, None])[pair] / dx[pair]).clip(-limit, limit)
        candidates = np.concatenate([slopes, [-limit, 0.0, limit]])
        intercepts = (y[None, :] - candidates[:, None] * x[None, :]).max(axis=1)
        best = int(np.argmin(intercepts + candidates * x.mean()))
        return float(intercepts[best]), float(candidates[best])

    def _line(self, x: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[float, float]:
        span_ns = (x.max() - x.min()) * _NS_PER_S if len(x) else 0.0
        if len(x) < 3 or span_ns < self._min_fit_span_ns:
            return float(np.average(y, weights=w)), 0.0
        sw = np.sqrt(w)
        A = np.stack([np.ones_like(x), x], axis=1) * sw[:, None]
        (a, b), *_ = np.linalg.lstsq(A, y * sw, rcond=None)
        limit = self._max_drift * _NS_PER_S
        if abs(b) > limit:  # implausible drift: clamp and refit the intercept
            b = float(np.clip(b, -limit, limit))
            a = float(np.average(y - b * x, weights=w))
        return float(a), float(b)


class ClockSync:
    """Follow the offset between the companion's monotonic clock and the autopilot's boot clock.

    Thread-safe: one thread may add samples while others convert times.

    Parameters
    ----------
    window_ns : sliding window the line is fitted over, ns.
    bin_ns : width of a bin (one best sample per bin), ns.
    min_fit_span_ns : below this span of data the drift is taken as 0 (a weighted mean).
    max_drift : largest plausible drift, dimensionless (default 500 ppm).
    max_rtt_ns : TIMESYNC samples with a longer round trip are ignored, ns.
    arrival_floor_ns : uncertainty stated for the arrival fallback, ns.
    step_ns : a sample this far from the line is not taken; ``step_count`` of them in a row,
        on one side and within ``step_ns`` of each other, restart the estimate (its clock
        stepped), ns. Arrivals use at least 1 s (their latency is not bounded).
    step_span_ns : the arrivals off the line must also span this much companion time (a
        burst of messages read late after a stall is not a step), ns.
    """

    def __init__(
        self,
        *,
        window_ns: int = 60 * _NS_PER_S,
        bin_ns: int = 2 * _NS_PER_S,
        min_fit_span_ns: int = 10 * _NS_PER_S,
        max_drift: float = 500e-6,
        max_rtt_ns: int = 200_000_000,
        arrival_floor_ns: int = 10_000_000,
        step_ns: int = 100_000_000,
        step_count: int = 3,
        step_span_ns: int = 3 * _NS_PER_S,
    ) -> None:
        if bin_ns <= 0 or window_ns < bin_ns:
            raise ValueError("need 0 < bin_ns <= window_ns")
        self._max_rtt_ns = max_rtt_ns
        self._arrival_floor_ns = arrival_floor_ns
        self._window_ns = window_ns

        def track(name: str, step: int, span: int, envelope: bool) -> _Track:
            return _Track(
                bin_ns=bin_ns,
                window_ns=window_ns,
                min_fit_span_ns=min_fit_span_ns,
                max_drift=max_drift,
                step_ns=step,
                step_count=step_count,
                step_span_ns=span,
                envelope=envelope,
                name=name,
            )

        # a TIMESYNC sample is off by at most half its round trip (<= max_rtt_ns / 2)
        self._timesync = track("TIMESYNC", step_ns, 0, False)
        # arrival values sit below the truth by the link latency, which has no bound (a
        # stalled process reads its messages seconds late): more before a step, and a span
        self._arrival = track("arrival", max(step_ns, _NS_PER_S), step_span_ns, True)
        self._unix: deque[int] = deque(maxlen=16)
        self._lock = threading.Lock()
        self._estimate = _NONE
        self.n_timesync = 0
        self.n_timesync_rejected = 0

    # -- samples ---------------------------------------------------------------------------

    def add_timesync(self, t0_mono_ns: int, t1_mono_ns: int, tc1_boot_ns: int) -> bool:
        """Add one TIMESYNC round trip; False when it was rejected (bad or slow).

        t0_mono_ns : companion monotonic time the request (tc1=0, ts1=t0) was sent, ns.
        t1_mono_ns : companion monotonic time the reply arrived, ns.
        tc1_boot_ns : the autopilot's boot time in the reply (its ``tc1``), ns.
        """
        rtt = t1_mono_ns - t0_mono_ns
        if rtt < 0 or rtt > self._max_rtt_ns or tc1_boot_ns <= 0:
            self.n_timesync_rejected += 1
            return False
        mid = (t0_mono_ns + t1_mono_ns) // 2
        half = rtt / 2 + 20_000.0  # ns; the floor keeps one lucky sample from dominating
        point = _Point(x_ns=mid, y_ns=tc1_boot_ns - mid, cost=rtt, weight=1.0 / half**2)
        with self._lock:
            self.n_timesync += 1
            self._timesync.add(point)
            self._update()
        return True

    def add_arrival(self, t_mono_ns: int, t_boot_ns: int) -> None:
        """Add a message stamped ``t_boot_ns`` (autopilot) that arrived at ``t_mono_ns``."""
        y = t_boot_ns - t_mono_ns
        with self._lock:
            self._arrival.add(_Point(x_ns=t_mono_ns, y_ns=y, cost=-y, weight=1.0))
            self._update()

    def add_system_time(self, t_boot_ns: int, t_unix_ns: int) -> None:
        """Add a SYSTEM_TIME pair (``time_boot_ms``, ``time_unix_usec``) in ns; unix 0 = unset."""
        if t_unix_ns <= 0:
            return
        with self._lock:
            self._unix.append(t_unix_ns - t_boot_ns)

    def reset(self) -> None:
        """Forget everything (e.g. after the autopilot rebooted)."""
        with self._lock:
            self._timesync.clear()
            self._arrival.clear()
            self._unix.clear()
            self._estimate = _NONE

    # -- results ---------------------------------------------------------------------------

    @property
    def estimate(self) -> ClockEstimate:
        """Current model (a frozen snapshot; cheap)."""
        return self._estimate

    @property
    def source(self) -> ClockSource:
        return self._estimate.source

    @property
    def n_steps(self) -> int:
        """Clock steps confirmed (each restarted the estimate; a reset is not counted)."""
        return self._timesync.n_steps + self._arrival.n_steps

    @property
    def n_off_line(self) -> int:
        """Samples off the line by more than a step and not taken: late arrivals (a stalled
        companion), one-off jumps, and the evidence of the steps."""
        return self._timesync.n_off_line + self._arrival.n_off_line

    @property
    def offset_ns(self) -> int:
        """boot - mono at the newest sample, ns; raises :class:`ClockUnavailable` before any."""
        est = self._require()
        return est.offset_ns

    @property
    def uncertainty_ns(self) -> int:
        return self._require().uncertainty_ns

    def offset_at(self, t_mono_ns: int) -> int:
        """boot - mono at ``t_mono_ns`` following the drift, ns."""
        return self._require().offset_at(t_mono_ns)

    def mono_to_boot_ns(self, t_mono_ns: int) -> int:
        """Companion monotonic ns -> autopilot boot ns."""
        return t_mono_ns + self._require().offset_at(t_mono_ns)

    def boot_to_mono_ns(self, t_boot_ns: int) -> int:
        """Autopilot boot ns -> companion monotonic ns (inverse of :meth:`mono_to_boot_ns`)."""
        est = self._require()
        # t_boot = t + off + d (t - r)  =>  t = (t_boot - off + d r) / (1 + d)
        return round((t_boot_ns - est.offset_ns + est.drift * est.ref_mono_ns) / (1.0 + est.drift))

    def boot_to_unix_ns(self, t_boot_ns: int) -> int:
        """Autopilot boot ns -> UTC ns since the Unix epoch (from SYSTEM_TIME).

        Uses the median of the last 16 SYSTEM_TIME differences, less 0.5 ms for the mean
        truncation of ``time_boot_ms``.
        """
        with self._lock:
            if not self._unix:
                raise ClockUnavailable("no SYSTEM_TIME with a UTC time received yet")
            diff = statistics.median(self._unix)
        return t_boot_ns + round(diff) - 500_000

    def mono_to_unix_ns(self, t_mono_ns: int) -> int:
        """Companion monotonic ns -> UTC ns via the autopilot's clock."""
        return self.boot_to_unix_ns(self.mono_to_boot_ns(t_mono_ns))

    def _require(self) -> ClockEstimate:
        est = self._estimate
        if est.source == "none":
            raise ClockUnavailable("no clock sync yet: no TIMESYNC reply and no stamped message")
        return est

    def _update(self) -> None:
        newest = max(
            (x for x in (self._timesync.newest_x_ns, self._arrival.newest_x_ns) if x is not None),
            default=None,
        )
        ts_fit = self._timesync.fit
        ts_newest = self._timesync.newest_x_ns
        if (
            ts_fit is not None
            and ts_newest is not None
            and newest is not None
            and newest - ts_newest <= self._window_ns
        ):
            pts = self._timesync.points()
            best_rtt = min(p.cost for p in pts)
            x_ref, y_ref, drift, rms = ts_fit
            self._estimate = ClockEstimate(
                source="timesync",
                ref_mono_ns=x_ref,
                offset_ns=y_ref,
                drift=drift,
                uncertainty_ns=round(best_rtt / 2 + rms),
                n_points=len(pts),
                best_rtt_ns=best_rtt,
            )
            return
        ar_fit = self._arrival.fit
        if ar_fit is not None:
            x_ref, y_ref, drift, rms = ar_fit
            self._estimate = ClockEstimate(
                source="arrival",
                ref_mono_ns=x_ref,
                offset_ns=y_ref,
                drift=drift,
                uncertainty_ns=round(self._arrival_floor_ns + rms),
                n_points=len(self._arrival.points()),
            )
            return
        self._estimate = _NONE
