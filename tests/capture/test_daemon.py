"""The capture daemon end to end with a scripted source and a simulated autopilot."""

from __future__ import annotations

import bisect
import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from holescan.capture import DEFAULT_RATES_HZ, Flight, FlightConfig, Telemetry
from holescan.detect import CameraIntrinsics, Frame
from holescan.flightlog import LoggedFrame, LoggedMavlink, LoggedPose, read_flight_log
from holescan.link import mavlink
from holescan.sim import SimAutopilot, SimPath
from tests._support import free_udp_port

CAM = CameraIntrinsics.xtion()
_POSE_MESSAGES = {
    "GLOBAL_POSITION_INT": "position",
    "ATTITUDE": "attitude",
    "ATTITUDE_QUATERNION": "attitude",
}


class ScriptedSource:
    """Frames of a flat floor with one hole, at ``fps``; fails or stalls on request."""

    camera = CAM

    def __init__(
        self, n: int, fps: float = 30.0, fail_at: int | None = None, stall_at: int | None = None
    ) -> None:
        self.n, self.fps, self.fail_at, self.stall_at = n, fps, fail_at, stall_at
        self.closed = False

    def __enter__(self) -> ScriptedSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.closed = True

    def __iter__(self) -> Iterator[Frame]:
        depth = np.full((480, 640), 2500, np.uint16)
        depth[180:300, 250:420] = 0
        rgb = np.full((480, 640, 3), 80, np.uint8)
        t0 = time.monotonic_ns()
        for i in range(self.n):
            if i == self.fail_at:
                raise OSError("USB transfer failed")
            if i == self.stall_at:
                time.sleep(3600)
            target = t0 + int(i * 1e9 / self.fps)
            time.sleep(max(0.0, (target - time.monotonic_ns()) / 1e9))
            yield Frame(i, rgb, depth, time.monotonic_ns(), i * 33_333_333)


def unposed_with_telemetry(files: tuple[Path, ...]) -> list[tuple[int, int | None]]:
    """(index, boot time) of each logged frame without a pose although the autopilot's
    positions and attitudes around it (its raw messages, as logged) are each no more than
    the pose buffer's 0.5 s apart. A simulator starved of CPU sends late, and drops what
    is due more than 0.5 s ago (at 50 Hz, attitudes go first): frames in such a gap are
    rightly unposed."""
    records = list(read_flight_log(files, kinds={LoggedFrame, LoggedMavlink}))
    mav = mavlink.MAVLink(None)
    series: dict[str, list[int]] = {"position": [], "attitude": []}
    for r in records:
        if isinstance(r, LoggedMavlink) and r.name in _POSE_MESSAGES:
            msg = mav.decode(bytearray(r.packet))
            series[_POSE_MESSAGES[r.name]].append(int(msg.time_boot_ms) * 1_000_000)
    samples = [sorted(v) for v in series.values()]

    def bridged(t: int, times: list[int]) -> bool:
        i = bisect.bisect_right(times, t)
        return 0 < i < len(times) and times[i] - times[i - 1] <= 5e8

    out: list[tuple[int, int | None]] = []
    for r in records:
        if not isinstance(r, LoggedFrame) or r.pose is not None:
            continue
        if r.t_boot_ns is None or all(bridged(r.t_boot_ns, times) for times in samples):
            out.append((r.frame.index, r.t_boot_ns))
    return out


def hover_path() -> SimPath:
    return SimPath(waypoints_enu=((0.0, 0.0, 2.5), (0.3, 0.0, 2.5), (0.3, 0.3, 2.5)), speed_m_s=0.2)


def test_flight_logs_every_frame_poses_them_and_finds_the_hole(tmp_path: Path) -> None:
    port = free_udp_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path()):
        cfg = FlightConfig(log_prefix=tmp_path / "flight", max_frames=90)
        flight = Flight(cfg, lambda: ScriptedSource(200), CAM, mavlink=f"udpin:127.0.0.1:{port}")
        summary = flight.run()
    c = summary.counters
    assert c.frames_captured == 90
    assert summary.frames_logged == 90 and c.frames_log_dropped == 0
    assert c.frames_detected >= 10
    # Frames wait for their telemetry at most pose_wait_s (0.5 s); under heavy CPU load
    # the telemetry thread can lag longer than that for a few frames.
    assert c.frames_unposed <= 30, c
    assert len(summary.holes) == 1 and summary.holes[0].sightings >= 10
    records = list(read_flight_log(summary.log.files))
    kinds = {type(r).__name__ for r in records}
    assert {
        "LoggedFrame",
        "LoggedPose",
        "LoggedMavlink",
        "LoggedDetections",
        "LoggedHoles",
        "LoggedHealth",
    } <= kinds
    frames = [r for r in records if type(r).__name__ == "LoggedFrame"]
    assert [f.frame.index for f in frames] == list(range(90))


def test_each_frame_waits_for_the_telemetry_after_it(tmp_path: Path) -> None:
    # Positions 0.25 s apart, more than the 0.2 s a pose is extrapolated: a frame posed the
    # moment it is captured could not be, late in each interval. Each frame is held (never
    # the capture thread) until the position after it has arrived, then logged with its
    # pose interpolated between the two. pose_wait_s is long enough here for a loaded
    # machine's late telemetry: what is tested is that frames wait, not how fast it comes.
    port = free_udp_port()
    rates = {**DEFAULT_RATES_HZ, "GLOBAL_POSITION_INT": 4.0}

    def slow_positions(conn: str, **kw: object) -> Telemetry:
        return Telemetry(conn, rates_hz=rates, command_timeout_s=5.0, **kw)  # type: ignore[arg-type]

    cfg = FlightConfig(
        log_prefix=tmp_path / "flight", max_frames=60, pose_wait_s=3.0, startup_sync_s=60.0
    )
    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path()) as ap:
        flight = Flight(
            cfg,
            lambda: ScriptedSource(100, fps=15.0),
            CAM,
            mavlink=f"udpin:127.0.0.1:{port}",
            telemetry_factory=slow_positions,
        )
        summary = flight.run()
        records = list(read_flight_log(summary.log.files, kinds={LoggedFrame, LoggedPose}))
        frames = [r for r in records if isinstance(r, LoggedFrame)]
        samples = sorted(r.pose.t_boot_ns for r in records if isinstance(r, LoggedPose))
        truth = {f.frame.index: ap.truth_pose(f.pose.t_boot_ns) for f in frames if f.pose}
    assert len(frames) == 60 and summary.counters.frames_unposed == sum(not f.pose for f in frames)
    late = 0  # frames more than 0.2 s after the position before them: posed only by waiting
    for f in frames:
        assert f.t_boot_ns is not None
        i = bisect.bisect_right(samples, f.t_boot_ns)
        before, after = samples[i - 1], samples[i]  # the flight ended after its last frame
        late += f.t_boot_ns - before > 200_000_000
        # Unposed only where the autopilot's positions themselves are more than the pose
        # buffer's 0.5 s apart (a simulator starved of CPU sends late).
        assert f.pose is not None or after - before > 500_000_000, (f.frame.index, before, after)
        if f.pose is not None:
            t = truth[f.frame.index]
            e, n, _ = pymap3d.geodetic2enu(
                f.pose.lat_deg, f.pose.lon_deg, t.alt_m, t.lat_deg, t.lon_deg, t.alt_m
            )
            assert math.hypot(e, n) < 0.05, (f.frame.index, e, n)  # interpolated, not guessed
    assert late > 0, "no frame came late in an interval: the test proves nothing"


def test_mavlink_silent_frames_still_logged_unposed(tmp_path: Path) -> None:
    cfg = FlightConfig(log_prefix=tmp_path / "flight", max_frames=30)
    summary = Flight(cfg, lambda: ScriptedSource(30), CAM).run()
    assert summary.frames_logged == 30
    assert summary.counters.frames_unposed == 30
    assert summary.holes == ()  # nothing can be geotagged without a pose
    assert summary.counters.pose_refusals >= 1


@pytest.mark.parametrize("fault", ["fail", "stall"])
def test_sensor_fault_is_retried_with_reset(tmp_path: Path, fault: str) -> None:
    opened: list[ScriptedSource] = []
    resets = threading.Event()

    def factory() -> ScriptedSource:
        first = not opened
        src = ScriptedSource(
            40 if not first else 100,
            fail_at=10 if first and fault == "fail" else None,
            stall_at=10 if first and fault == "stall" else None,
        )
        opened.append(src)
        return src

    cfg = FlightConfig(log_prefix=tmp_path / "flight", frame_timeout_s=1.0, retry_backoff_s=(0.2,))
    summary = Flight(cfg, factory, CAM, usb_reset=resets.set).run()
    assert summary.counters.sensor_failures == 1
    assert resets.is_set()
    assert len(opened) == 2 and opened[0].closed
    assert summary.frames_logged == 10 + 40
    health = [r for r in read_flight_log(summary.log.files) if type(r).__name__ == "LoggedHealth"]
    assert any("sensor_failure" in str(h) for h in health)


def test_silent_autopilot_at_start_still_logs_unposed_frames(tmp_path: Path) -> None:
    from holescan.capture import Telemetry

    port = free_udp_port()
    cfg = FlightConfig(log_prefix=tmp_path / "flight", max_frames=45)

    def quick(conn: str, **kw: object) -> Telemetry:
        return Telemetry(conn, heartbeat_timeout_s=0.5, **kw)  # type: ignore[arg-type]

    summary = Flight(
        cfg,
        lambda: ScriptedSource(45),
        CAM,
        mavlink=f"udpin:127.0.0.1:{port}",
        telemetry_factory=quick,
    ).run()
    assert summary.frames_logged == 45
    assert summary.counters.frames_unposed == 45


class BurstSource:
    """Frames in bursts of ``burst`` at once, then a pause: the log writer falls behind for a
    moment, as it does on a computer short of CPU, and catches up in the pause."""

    camera = CAM

    def __init__(self, bursts: int, burst: int = 8, pause_s: float = 0.6) -> None:
        self.bursts, self.burst, self.pause_s = bursts, burst, pause_s

    def __enter__(self) -> BurstSource:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def __iter__(self) -> Iterator[Frame]:
        rng = np.random.default_rng(0)
        depth = rng.integers(2000, 3000, size=(480, 640), dtype=np.uint16)  # hard to compress
        rgb = rng.integers(0, 255, size=(480, 640, 3), dtype=np.uint8)
        i = 0
        for _ in range(self.bursts):
            for _ in range(self.burst):
                yield Frame(i, rgb, depth, time.monotonic_ns(), i * 33_333_333)
                i += 1
            time.sleep(self.pause_s)


def test_a_log_behind_sheds_detection_never_log_frames(tmp_path: Path) -> None:
    from holescan.flightlog import LogOptions

    options = LogOptions(max_queued_frames=16)  # sheds above 4 queued
    cfg = FlightConfig(log_prefix=tmp_path / "flight", log_options=options)
    flight = Flight(cfg, lambda: BurstSource(5), CAM)
    summary = flight.run()
    c = summary.counters
    assert c.frames_captured == 40
    assert c.frames_log_dropped == 0 and summary.frames_logged == 40
    assert c.frames_shed > 0, "the writer never fell behind: the test proves nothing"
    assert summary.detect_offered == 40 - c.frames_shed
