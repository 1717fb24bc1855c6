"""Issue 20: the autopilot reboots mid-flight, in place (ArduPilot on MAV_CMD_PREFLIGHT_
REBOOT_SHUTDOWN: its boot clock and TIMESYNC restart from 0, the streams stop until
SET_MESSAGE_INTERVAL is sent again, the mission is kept). The companion re-synchronises
its clock, asks for the rates again, and never poses a frame with a sample from the
other side of the reboot: every posed frame is where the vehicle really was."""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

from holescan.capture import FlightConfig
from holescan.flightlog import LoggedFrame, read_flight_log
from holescan.geotag import local_en_m
from holescan.sim import SimAutopilot, SimPath
from tests._support import free_udp_port, wait_for
from tests.capture.test_daemon import unposed_with_telemetry
from tests.capture.test_faults import floor_flight

# 1 m/s: a pose from the wrong side of a 1.5 s reboot is metres off.
PATH = SimPath(waypoints_enu=((0.0, 0.0, 3.0), (6.0, 0.0, 3.0), (6.0, 6.0, 3.0)), speed_m_s=1.0)


def test_autopilot_reboot_in_flight(tmp_path: Path) -> None:
    # Driven by what the flight did, not by wall time (a loaded machine starts and
    # re-synchronises late): the reboot once 30 frames were posed, the flight stopped once
    # 45 more were posed after it. pose_wait_s: each frame waits for the telemetry after
    # it, long enough here for a loaded machine's late simulator and receiver.
    port = free_udp_port()
    cfg = FlightConfig(log_prefix=tmp_path / "f", startup_sync_s=3.0, pose_wait_s=3.0)
    flight, telemetry = floor_flight(cfg, port)
    c = flight.counters

    def posed() -> int:
        return c.frames_captured - c.frames_unposed

    with SimAutopilot(f"udpout:127.0.0.1:{port}", PATH) as ap:
        box: dict[str, object] = {}
        runner = threading.Thread(target=lambda: box.setdefault("s", flight.run()), daemon=True)
        runner.start()
        try:
            wait_for(lambda: posed() >= 30, 120.0, "30 posed frames")
            assert "GLOBAL_POSITION_INT" in ap.rates_hz()
            t_reboot = time.monotonic_ns()
            ap.reboot(1.5)
            assert set(ap.rates_hz()) == {"HEARTBEAT"}  # intervals forgotten
            before = posed()  # nothing is posed while the autopilot is down
            wait_for(lambda: posed() >= before + 45, 120.0, "45 posed frames after the reboot")
        finally:
            flight.stop.set()
            runner.join(60)
        rates_after = ap.rates_hz()
        frames = [r for r in read_flight_log(box["s"].log.files) if isinstance(r, LoggedFrame)]  # type: ignore[attr-defined]
        truth = {r.sequence: ap.truth_pose(ap.boot_ns_at_mono(r.frame.t_mono_ns)) for r in frames}
    tel = telemetry[0]
    assert tel.reboots == 1
    assert "GLOBAL_POSITION_INT" in rates_after  # asked for again after the reboot
    after = [r for r in frames if r.frame.t_mono_ns > t_reboot + 1_500_000_000]
    posed_after = [r for r in after if r.pose is not None]
    assert posed_after  # re-synchronised (how soon on a real ArduPilot: benchmarks/sitl_sortie.py)
    # Posed again from the first posed frame after the reboot on, but where the (CPU-
    # starved) simulator left a gap in its positions or attitudes the pose buffer does not
    # bridge.
    unexplained = {i for i, _ in unposed_with_telemetry(box["s"].log.files)}  # type: ignore[attr-defined]
    resynced = [
        r
        for r in after
        if r.frame.t_mono_ns >= posed_after[0].frame.t_mono_ns
        and (r.pose is not None or r.frame.index in unexplained)
    ]
    assert len(posed_after) >= 0.8 * len(resynced), (len(posed_after), len(resynced))
    worst = 0.0
    for r in frames:
        if r.pose is None:
            continue
        t = truth[r.sequence]
        worst = max(
            worst, math.hypot(*local_en_m(r.pose.lat_deg, r.pose.lon_deg, t.lat_deg, t.lon_deg))
        )
    print(
        f"\nreboot in flight: {len(frames)} frames, {len(posed_after)}/{len(after)} posed after "
        f"({len(resynced)} from the first posed one), "
        f"worst pose error {worst:.2f} m"
    )
    assert worst < 0.5  # never a sample from the other side of the reboot
