"""Telemetry against the simulated autopilot, routed through the real MAVProxy (headless).

sim autopilot --udpout--> MAVProxy (--master=udpin, --streamrate=-1) --udpout--> Telemetry.
A few tests use a direct sim -> Telemetry link where MAVProxy would hide what is tested
(garbage bytes: MAVProxy drops them; the REQUEST_DATA_STREAM fallback).
"""

from __future__ import annotations

import logging
import math
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pymap3d
import pytest

from holescan.capture import ClockSync, Telemetry
from holescan.geotag import VehiclePose
from holescan.link import PoseUnavailable, TelemetryTimeoutError
from holescan.sim import SimAutopilot, SimPath

os.environ.setdefault("MAVLINK20", "1")
from holescan.link import mavlink as mavlink2
from tests._support import free_udp_port, wait_for

log = logging.getLogger(__name__)

MS = 1_000_000
RATES = {"GLOBAL_POSITION_INT": 20.0, "ATTITUDE_QUATERNION": 50.0, "GPS_RAW_INT": 5.0,
         "SYSTEM_TIME": 2.0}  # fmt: skip


def _pose_errors(sim: SimAutopilot, pose: VehiclePose, t_mono_ns: int) -> tuple[float, float]:
    """(position error m, attitude error deg) of ``pose`` against the simulator's truth."""
    t_boot = sim.boot_ns_at_mono(t_mono_ns)
    truth = sim.truth_pose(t_boot)
    e, n, u = pymap3d.geodetic2enu(
        pose.lat_deg, pose.lon_deg, pose.alt_m, truth.lat_deg, truth.lon_deg, truth.alt_m
    )
    from scipy.spatial.transform import Rotation

    got = Rotation.from_euler("ZYX", [pose.yaw, pose.pitch, pose.roll])
    angle = (got.inv() * sim.truth_rotation(t_boot)).magnitude()
    return math.sqrt(e * e + n * n + u * u), math.degrees(angle)


@dataclass
class Flight:
    sim: SimAutopilot
    tel: Telemetry
    seen: list[tuple[Any, int]]
    t_open: float


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Flight]:
    mavproxy = shutil.which("mavproxy.py")
    if mavproxy is None:
        pytest.fail("mavproxy.py not installed (pip install MAVProxy)")
    state = tmp_path_factory.mktemp("mavproxy")
    p_master, p_out = free_udp_port(), free_udp_port()
    seen: list[tuple[Any, int]] = []
    with SimAutopilot(f"udpout:127.0.0.1:{p_master}", seed=11) as sim:
        proc = subprocess.Popen(
            [mavproxy, f"--master=udpin:127.0.0.1:{p_master}",
             f"--out=udpout:127.0.0.1:{p_out}", "--daemon", f"--state-basedir={state}",
             "--streamrate=-1", "--target-system=1", "--target-component=1"],
            cwd=state, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        try:
            tel = Telemetry(
                f"udpin:127.0.0.1:{p_out}",
                rates_hz=RATES,
                heartbeat_timeout_s=30.0,
                on_message=lambda msg, t: seen.append((msg, t)),
            )
            with tel:
                yield Flight(sim, tel, seen, time.monotonic())
        finally:
            proc.send_signal(signal.SIGINT)  # exits 1 even when clean (FIELD-NOTES)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _settle(flight: Flight, seconds: float = 3.0) -> None:
    remaining = flight.t_open + seconds - time.monotonic()
    if remaining > 0:
        time.sleep(remaining)


def test_rates_requested_through_mavproxy(flight: Flight) -> None:
    _settle(flight)
    assert flight.tel.rate_method == "message_interval"
    assert flight.tel.target == (1, 1)
    streamed = flight.sim.rates_hz()
    measured = flight.tel.message_rates_hz(window_s=2.5)
    log.info("requested %s measured %s", RATES, measured)
    # Each rate asked for through MAVProxy is the one the autopilot streams, and each stream
    # reaches the link (the rates measured at the receiver: benchmarks/bench_mavlink_garbage.py).
    got = flight.tel.stats().messages
    for name, hz in RATES.items():
        assert streamed[name] == pytest.approx(hz)
        assert got.get(name, 0) > 0, name
    stats = flight.tel.stats()
    assert stats.bad_bytes == stats.bad_packets == 0


def test_timesync_offset_within_1ms_of_truth(flight: Flight) -> None:
    _settle(flight)
    clock = flight.tel.clock
    assert clock.source == "timesync"
    errors = []
    for _ in range(10):
        t = time.monotonic_ns()
        errors.append(clock.mono_to_boot_ns(t) - flight.sim.boot_ns_at_mono(t))
        time.sleep(0.02)
    worst = max(abs(e) for e in errors)
    log.info(
        "TIMESYNC offset error %.1f..%.1f us; stated uncertainty %.1f us; best RTT %.1f us",
        min(errors) / 1e3, max(errors) / 1e3, clock.uncertainty_ns / 1e3,
        clock.estimate.best_rtt_ns / 1e3,
    )  # fmt: skip
    assert worst < 1 * MS
    assert worst <= clock.uncertainty_ns < 10 * MS  # the stated bound holds
    stats = flight.tel.stats()
    assert stats.timesync_received >= 0.8 * stats.timesync_sent > 0
    # SYSTEM_TIME: boot -> UTC as the autopilot reports it
    t_boot = flight.sim.boot_ns_at_mono(time.monotonic_ns())
    utc_err = clock.boot_to_unix_ns(t_boot) - flight.sim.unix_ns_at_boot(t_boot)
    log.info("UTC error %.1f us", utc_err / 1e3)
    assert abs(utc_err) < 1 * MS


def test_pose_at_frame_times_matches_truth(flight: Flight) -> None:
    _settle(flight)
    tel, sim = flight.tel, flight.sim
    pos_err, att_err, ages = [], [], []
    next_frame = time.monotonic_ns()
    for k in range(45):  # 1.5 s of 30 fps frames; every third one looked up 0.3 s late
        while time.monotonic_ns() < next_frame:
            time.sleep(0.001)
        t_frame = next_frame
        next_frame += 33_333_333
        pose = tel.pose_at_mono(t_frame - (300 * MS if k % 3 == 0 else 0), wait_s=0.15)
        dp, da = _pose_errors(sim, pose, t_frame - (300 * MS if k % 3 == 0 else 0))
        pos_err.append(dp)
        att_err.append(da)
        ages.append(pose.age_ns)
    log.info(
        "pose error at 20/50 Hz telemetry: position max %.1f mm mean %.1f mm; attitude max "
        "%.3f deg mean %.3f deg; max sample age %.1f ms",
        1e3 * max(pos_err), 1e3 * sum(pos_err) / len(pos_err), max(att_err),
        sum(att_err) / len(att_err), max(ages) / 1e6,
    )  # fmt: skip
    assert max(pos_err) < 0.05
    assert max(att_err) < 0.5
    fix = tel.latest_gps()
    assert fix is not None
    assert fix.fix_type == 3
    assert fix.eph_m == pytest.approx(sim.eph_m)


def test_raw_messages_reach_the_callback(flight: Flight) -> None:
    _settle(flight, 1.0)
    positions = [(m, t) for m, t in list(flight.seen) if m.get_type() == "GLOBAL_POSITION_INT"]
    assert len(positions) > 10
    msg, t_mono = positions[-1]
    assert flight.t_open * 1e9 < t_mono <= time.monotonic_ns()  # its arrival, monotonic clock
    parser = mavlink2.MAVLink(None)
    again = parser.decode(bytearray(msg.get_msgbuf()))  # the exact bytes, re-parsed
    assert (again.time_boot_ms, again.lat, again.lon) == (msg.time_boot_ms, msg.lat, msg.lon)


def test_silent_link_refuses_poses_quickly(flight: Flight) -> None:
    _settle(flight, 1.0)
    tel, sim = flight.tel, flight.sim
    sim.silent = True
    try:
        time.sleep(0.4)
        assert tel.last_message_age_s() > 0.3
        # The wait's own timeout ends it (a pose refused as too old), not telemetry that
        # does not come (that would hang here until the test's timeout).
        with pytest.raises(PoseUnavailable, match="old"):
            tel.pose_at_mono(time.monotonic_ns(), wait_s=0.1)
        with pytest.raises(PoseUnavailable):
            tel.pose_at_mono(time.monotonic_ns())
    finally:
        sim.silent = False

    def posed() -> bool:
        try:
            tel.pose_at_mono(time.monotonic_ns() - 50 * MS)
        except PoseUnavailable:
            return False
        return True

    # Telemetry resumes (10-50 Hz): poses come back; the 10 s only guard a hang.
    wait_for(posed, 10.0, "a pose after the autopilot spoke again", poll_s=0.05)


# -- direct links (no MAVProxy) ----------------------------------------------------------


def test_fallback_to_request_data_stream_at_10hz() -> None:
    port = free_udp_port()
    rates = {"GLOBAL_POSITION_INT": 10.0, "ATTITUDE": 10.0, "SYSTEM_TIME": 1.0}
    with (
        SimAutopilot(f"udpout:127.0.0.1:{port}", message_interval=False, seed=5) as sim,
        Telemetry(f"udpin:127.0.0.1:{port}", rates_hz=rates) as tel,
    ):
        assert tel.rate_method == "data_stream"  # no ACK exists: wait for the streams
        # The streams start with the first REQUEST_DATA_STREAM; the 10 s only guard a hang.
        wait_for(
            lambda: sim.rates_hz().get("ATTITUDE") == 10.0,
            10.0,
            "the autopilot streaming ATTITUDE at 10 Hz after REQUEST_DATA_STREAM",
        )
        time.sleep(2.5)
        measured = tel.message_rates_hz(window_s=2.0)
        log.info("sim sent %s; telemetry got %s; measured %s", sim.sent, tel.stats(), measured)
        # The streams asked for run at the rate asked (the autopilot's side) and reach the
        # link; the rates measured at the receiver: benchmarks/bench_mavlink_garbage.py.
        got = tel.stats().messages
        for name in ("GLOBAL_POSITION_INT", "ATTITUDE"):
            assert sim.rates_hz()[name] == 10.0
            assert got.get(name, 0) > 0
            # nothing received that was not sent (the simulator counts a message just after
            # sending it, so its count may trail the receiver's for an instant)
            wait_for(lambda n=name: got[n] <= sim.sent[n], 2.0, f"{name} counted as sent")
        pos_err, att_err = [], []
        for _ in range(20):
            t = time.monotonic_ns() - 20 * MS
            pose = tel.pose_at_mono(t, wait_s=0.25)
            dp, da = _pose_errors(sim, pose, t)
            pos_err.append(dp)
            att_err.append(da)
            time.sleep(0.037)
        log.info(
            "pose error at 10 Hz telemetry: position max %.1f mm, attitude max %.3f deg",
            1e3 * max(pos_err), max(att_err),
        )  # fmt: skip
        assert max(pos_err) < 0.05
        assert max(att_err) < 0.5


def test_garbage_is_ignored_and_counted() -> None:
    port = free_udp_port()
    with (
        SimAutopilot(f"udpout:127.0.0.1:{port}", seed=6) as sim,
        Telemetry(f"udpin:127.0.0.1:{port}", rates_hz={"GLOBAL_POSITION_INT": 20.0,
                  "ATTITUDE": 20.0}, timesync_hz=0) as tel,
    ):  # fmt: skip
        garbage = bytes(b for b in range(256) if b not in (0xFD, 0xFE)) * 3
        sim.inject_garbage(garbage)
        encoder = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        corrupt = bytearray(
            mavlink2.MAVLink_global_position_int_message(1, 2, 3, 4, 5, 6, 7, 8, 9).pack(encoder)
        )
        corrupt[12] ^= 0xFF  # a payload byte: the CRC no longer matches
        sim.inject_garbage(bytes(corrupt))
        unknown = bytes([0xFD, 4, 0, 0, 0, 1, 1]) + (0xABCDEF).to_bytes(3, "little")
        sim.inject_garbage(unknown + b"\x01\x02\x03\x04\x00\x00")
        # Wait until the receiver has read past all three (a loaded machine lags), then
        # count exactly: nothing more arrives that could be counted as bad.
        wait_for(lambda: tel.stats().unknown_packets >= 1, 30.0, "the injected bytes read")
        stats = tel.stats()
        assert stats.bad_bytes == len(garbage)
        assert stats.bad_packets == 1
        assert stats.unknown_packets == 1
        # telemetry carried on: a pose after the garbage, interpolated between the samples
        # around it (waiting for the one after it, however late a loaded machine reads
        # it), no clock from TIMESYNC so from arrivals
        wait_for(lambda: tel.clock.source != "none", 30.0, "the clock synchronised")
        assert tel.clock.source == "arrival"
        wait_for(lambda: tel.poses.newest_t_boot_ns is not None, 30.0, "a first pose")
        t = time.monotonic_ns()
        pose = tel.pose_at_mono(t, wait_s=30.0)
        assert _pose_errors(sim, pose, t)[0] < 1.0


def test_no_autopilot_times_out() -> None:
    tel = Telemetry(f"udpin:127.0.0.1:{free_udp_port()}", heartbeat_timeout_s=0.5)
    # The heartbeat timeout's path (its error), not a hang (the test's timeout would stop it).
    with pytest.raises(TelemetryTimeoutError, match="no autopilot heartbeat"), tel:
        pass
    assert isinstance(tel.clock, ClockSync)
    with pytest.raises(PoseUnavailable):
        tel.pose_at_mono(time.monotonic_ns())


def test_sim_accepts_and_flies_an_uploaded_mission() -> None:
    from holescan.missions import Waypoint, download_mission, upload_mission

    home = SimPath()
    square = [(0.0, 0.0), (30.0, 0.0), (30.0, 30.0), (0.0, 30.0)]
    items = []
    for e, n in square:
        lat, lon, _ = pymap3d.enu2geodetic(e, n, 0.0, home.home_lat_deg, home.home_lon_deg, 0.0)
        items.append(Waypoint(float(lat), float(lon), 15.0))
    port = free_udp_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", seed=7) as sim:
        upload_mission(f"udpin:127.0.0.1:{port}", items,
                       Waypoint(home.home_lat_deg, home.home_lon_deg, 0.0))  # fmt: skip
        stored = sim.mission.mission
        assert len(stored) == 5
        back = download_mission(f"udpin:127.0.0.1:{port}")
        assert len(back) == 5
    path = SimPath.from_waypoints(
        home.home_lat_deg, home.home_lon_deg, home.home_alt_m, stored[1:], speed_m_s=4.0
    )
    for (e, n), wp in zip(square, path.waypoints_enu, strict=True):
        assert wp == pytest.approx((e, n, 15.0), abs=0.02)
    flyer = SimAutopilot("udpout:127.0.0.1:9", path)  # never opened: truth only
    t = flyer.boot_ns_at_mono(time.monotonic_ns())
    assert flyer.truth_pose(t).rel_alt_m == pytest.approx(15.0, abs=0.5)
