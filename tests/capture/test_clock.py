"""ClockSync: synthetic TIMESYNC / arrival / SYSTEM_TIME samples with a known truth."""

from __future__ import annotations

import random

import pytest

from holescan.capture import ClockSync, ClockUnavailable

S = 1_000_000_000
MS = 1_000_000
US = 1_000


class _Truth:
    """An autopilot clock: boot = offset0 + (mono - mono0) * (1 + drift)."""

    def __init__(self, offset0: int, drift: float, mono0: int = 500 * S) -> None:
        self.offset0 = offset0
        self.drift = drift
        self.mono0 = mono0

    def boot(self, mono: int) -> int:
        return mono + self.offset0 + round((mono - self.mono0) * self.drift)

    def offset(self, mono: int) -> int:
        return self.boot(mono) - mono


def _feed_timesync(
    clock: ClockSync,
    truth: _Truth,
    rng: random.Random,
    *,
    start: int,
    seconds: float,
    hz: float = 5.0,
    outlier_fraction: float = 0.0,
    record: list[int] | None = None,
) -> int:
    """Round trips with 0.1-0.6 ms legs; outliers get one leg delayed 5-80 ms."""
    t = start
    end = start + round(seconds * S)
    while t < end:
        up = rng.uniform(50, 300) * US
        down = rng.uniform(50, 300) * US
        if rng.random() < outlier_fraction:
            if rng.random() < 0.5:
                up += rng.uniform(5, 80) * MS
            else:
                down += rng.uniform(5, 80) * MS
        t0 = t
        tc1 = truth.boot(round(t0 + up))
        t1 = round(t0 + up + down)
        clock.add_timesync(t0, t1, tc1)
        if record is not None:
            record.append(tc1 - (t0 + t1) // 2)
        t += round(S / hz)
    return end


def test_no_samples_means_no_estimate() -> None:
    clock = ClockSync()
    assert clock.source == "none"
    with pytest.raises(ClockUnavailable):
        clock.mono_to_boot_ns(10 * S)
    with pytest.raises(ClockUnavailable):
        _ = clock.offset_ns
    with pytest.raises(ClockUnavailable):
        clock.boot_to_unix_ns(10 * S)


def test_constant_offset_symmetric_jitter() -> None:
    truth = _Truth(offset0=-463_123_456_789, drift=0.0)
    clock = ClockSync()
    end = _feed_timesync(clock, truth, random.Random(1), start=500 * S, seconds=8)
    assert clock.source == "timesync"
    err = clock.mono_to_boot_ns(end) - truth.boot(end)
    assert abs(err) < 150 * US  # legs differ by at most 0.25 ms
    assert clock.uncertainty_ns >= abs(err)
    assert clock.estimate.best_rtt_ns < 400 * US


def test_drift_followed_over_a_minute() -> None:
    truth = _Truth(offset0=12_345_678_901, drift=40e-6)  # 40 ppm: 2.4 ms per minute
    clock = ClockSync()
    end = _feed_timesync(clock, truth, random.Random(2), start=500 * S, seconds=60)
    est = clock.estimate
    assert est.drift == pytest.approx(40e-6, abs=5e-6)
    for t in (end - 30 * S, end, end + 5 * S):  # inside the window and 5 s beyond it
        assert abs(clock.mono_to_boot_ns(t) - truth.boot(t)) < 150 * US
    # a constant offset would be 1.2 ms off at the end of the minute: the fit matters here
    assert abs(truth.offset(end) - truth.offset(end - 30 * S)) > 1 * MS


def test_round_trip_outliers_are_ignored() -> None:
    truth = _Truth(offset0=-5 * S, drift=-20e-6)
    clock = ClockSync()
    rng = random.Random(3)
    samples: list[int] = []
    end = _feed_timesync(
        clock, truth, rng, start=500 * S, seconds=40, outlier_fraction=0.4, record=samples
    )
    err = clock.mono_to_boot_ns(end) - truth.boot(end)
    assert abs(err) < 200 * US
    # the raw samples are far worse: the filter is doing the work
    worst = max(abs(y - truth.offset(end)) for y in samples)
    assert worst > 2 * MS


def test_rejects_impossible_samples() -> None:
    clock = ClockSync(max_rtt_ns=100 * MS)
    assert not clock.add_timesync(10 * S, 10 * S - 1, 5 * S)  # reply before request
    assert not clock.add_timesync(10 * S, 10 * S + 150 * MS, 5 * S)  # too slow
    assert not clock.add_timesync(10 * S, 10 * S + MS, 0)  # no autopilot time
    assert clock.n_timesync_rejected == 3
    assert clock.source == "none"


def test_arrival_fallback_then_timesync_takes_over() -> None:
    truth = _Truth(offset0=777 * S + 123_456, drift=10e-6)
    clock = ClockSync()
    rng = random.Random(4)
    t = 500 * S
    for _ in range(300):  # 30 s of 10 Hz messages, 2-25 ms latency, ms stamps
        boot_ms = truth.boot(t) // MS
        clock.add_arrival(t + round(rng.uniform(2, 25) * MS), boot_ms * MS)
        t += 100 * MS
    assert clock.source == "arrival"
    err = clock.mono_to_boot_ns(t) - truth.boot(t)
    # late by the smallest latency (~2 ms) plus the ms truncation, never early by much
    assert -5 * MS < err < 0.5 * MS
    assert clock.uncertainty_ns >= abs(err)
    _feed_timesync(clock, truth, rng, start=t, seconds=3)
    assert clock.source == "timesync"
    t_end = t + 3 * S
    assert abs(clock.mono_to_boot_ns(t_end) - truth.boot(t_end)) < 200 * US


def test_autopilot_reboot_restarts_the_estimate() -> None:
    before = _Truth(offset0=100 * S, drift=0.0)
    clock = ClockSync()
    rng = random.Random(5)
    t = _feed_timesync(clock, before, rng, start=500 * S, seconds=10)
    after = _Truth(offset0=-t + 3 * S, drift=0.0)  # booted again 3 s ago
    end = _feed_timesync(clock, after, rng, start=t, seconds=3)
    assert abs(clock.mono_to_boot_ns(end) - after.boot(end)) < 200 * US


def test_boot_to_mono_inverts_mono_to_boot() -> None:
    truth = _Truth(offset0=-3 * S, drift=200e-6)
    clock = ClockSync()
    end = _feed_timesync(clock, truth, random.Random(6), start=500 * S, seconds=30)
    for t in (end - 20 * S, end, end + 100 * S):
        assert abs(clock.boot_to_mono_ns(clock.mono_to_boot_ns(t)) - t) <= 1


def test_boot_to_unix_from_system_time() -> None:
    clock = ClockSync()
    rng = random.Random(7)
    unix_minus_boot = 1_760_000_000 * S + 987_654_321
    for _ in range(16):
        boot = rng.randrange(100 * S, 200 * S)  # both read at once, truncated to ms / us
        clock.add_system_time((boot // MS) * MS, ((boot + unix_minus_boot) // US) * US)
    clock.add_system_time(150 * S, 0)  # no GPS time yet: ignored
    err = clock.boot_to_unix_ns(123 * S) - (123 * S + unix_minus_boot)
    assert abs(err) < 300 * US


def _arrivals_with_stalls(
    truth: _Truth, rng: random.Random, *, start: int, seconds: float, hz: float = 50.0
) -> list[tuple[int, int]]:
    """(arrival mono, ``time_boot_ms`` in ns) of messages sent at ``hz``, in arrival order.

    Read 2-10 ms after sent, except that every 2-5 s the companion's process stalls for
    1-2.5 s (an overloaded Pi): what was sent meanwhile is read at the stall's end in one
    burst, 0.1 ms apart, each message as late as the stall left it."""
    out: list[tuple[int, int]] = []
    t = start
    end = start + round(seconds * S)
    stall_at = start + round(rng.uniform(2, 5) * S)
    stall_end = stall_at + round(rng.uniform(1.0, 2.5) * S)
    reader_free = start  # the reader handles one message at a time
    while t < end:
        if t >= stall_end:
            stall_at = t + round(rng.uniform(2, 5) * S)
            stall_end = stall_at + round(rng.uniform(1.0, 2.5) * S)
        arrival = t + round(rng.uniform(2, 10) * MS)
        if stall_at <= arrival < stall_end:
            arrival = stall_end
        arrival = max(arrival, reader_free + 100 * US)
        reader_free = arrival
        out.append((arrival, truth.boot(t) // MS * MS))
        t += round(S / hz)
    return out


def test_late_arrivals_of_a_stalled_companion_are_not_a_clock_step(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # A burst of messages read 1-2.5 s late after each stall used to read as a step
    # ("arrival clock offset stepped by -1.4 s") and restart the estimate from a late
    # message: seconds off, every few seconds, at load 25-30. The earliest arrivals hold
    # the offset; a stall's burst neither lasts nor agrees with itself.
    truth = _Truth(offset0=-321 * S + 654_321, drift=25e-6)
    clock = ClockSync()
    worst = 0
    arrivals = _arrivals_with_stalls(truth, random.Random(11), start=500 * S, seconds=60)
    assert sum(a - t_boot + truth.offset0 > 1 * S for a, t_boot in arrivals) > 300  # 1 s late
    for i, (t_mono, t_boot) in enumerate(arrivals):
        clock.add_arrival(t_mono, t_boot)
        if i >= 50:  # from the second second on
            err = clock.mono_to_boot_ns(t_mono) - truth.boot(t_mono)
            worst = max(worst, abs(err))
            assert -15 * MS < err < 1 * MS, (i, err)
    assert clock.n_steps == 0 and clock.n_off_line > 300
    assert "stepped" not in caplog.text
    print(f"\nstalled arrivals: worst offset error {worst / MS:.1f} ms")


def test_a_lasting_arrival_step_is_taken_despite_the_stalls(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # The autopilot rebooted while the link was down longer than it had been up: its boot
    # clock does not go back, but every message from then on is 40 s "late". That lasts:
    # after step_span_ns (3 s) of it, the estimate restarts, once, stalls or not.
    before = _Truth(offset0=50 * S, drift=0.0)
    after = _Truth(offset0=10 * S, drift=0.0)
    rng = random.Random(12)
    clock = ClockSync()
    for t_mono, t_boot in _arrivals_with_stalls(before, rng, start=500 * S, seconds=20):
        clock.add_arrival(t_mono, t_boot)
    t_step = 530 * S
    errors: list[tuple[int, int]] = []
    for t_mono, t_boot in _arrivals_with_stalls(after, rng, start=t_step, seconds=20):
        clock.add_arrival(t_mono, t_boot)
        errors.append((t_mono, clock.mono_to_boot_ns(t_mono) - after.boot(t_mono)))
    assert clock.n_steps == 1 and caplog.text.count("stepped") == 1
    late = [e for t, e in errors if t > t_step + 8 * S]  # the span, and a stall, later
    assert late and all(-15 * MS < e < 1 * MS for e in late)


def test_a_timesync_step_needs_no_span() -> None:
    # TIMESYNC samples are off by at most half their round trip: three in a row that agree
    # are a step at once (a real autopilot's reboot is also seen by its boot clock).
    before = _Truth(offset0=100 * S, drift=0.0)
    clock = ClockSync()
    rng = random.Random(13)
    t = _feed_timesync(clock, before, rng, start=500 * S, seconds=10)
    after = _Truth(offset0=before.offset0 + 2 * S, drift=0.0)
    end = _feed_timesync(clock, after, rng, start=t, seconds=1)
    assert clock.n_steps == 1
    assert abs(clock.mono_to_boot_ns(end) - after.boot(end)) < 200 * US
