"""How long a frame is held for the telemetry after it: ``pose_wait_s`` from its time or
from its arrival at the capture thread, whichever is later. A stalled companion hands its
frames over late and reads the telemetry of their time late too (the frames 15-20 of a
mode-change flight at load ~20 reached the capture thread together, more than
``pose_wait_s`` after their time, and went unposed although positions around them came
a moment later). Real autopilot link (the simulator over loopback); the times asked about
are given, never waited for."""

from __future__ import annotations

import threading
import time

from holescan.capture._telemetrysupervisor import TelemetrySupervisor
from holescan.sim import SimAutopilot
from tests._support import free_udp_port, wait_for
from tests.capture.test_daemon import hover_path

S = 1_000_000_000


def test_a_frame_handed_over_late_waits_from_its_arrival() -> None:
    port = free_udp_port()
    stop = threading.Event()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path()) as ap:
        link = TelemetrySupervisor(f"udpin:127.0.0.1:{port}")
        try:
            link.start(stop, 60.0)
            wait_for(lambda: link.pose(time.monotonic_ns() - S // 2) is not None, 120.0, "a pose")
            ap.silent = True  # the telemetry after the frame has not been read yet
            time.sleep(0.1)
            t_frame = time.monotonic_ns()
            t_boot = link.boot_ns(t_frame)
            assert t_boot is not None
            arrived = t_frame + 2 * S  # the frame reached the capture thread 2 s late
            late = {"since_ns": arrived, "t_boot_ns": t_boot}
            # 0.1 s after it arrived: held (from its time alone, it would go unposed now)
            assert link.pose_pending(t_frame, 0.5, now_ns=arrived + S // 10, **late)
            assert not link.pose_pending(t_frame, 0.5, t_boot_ns=t_boot, now_ns=arrived + S // 10)
            # the bound: pose_wait_s after its arrival it goes, telemetry or not
            assert not link.pose_pending(t_frame, 0.5, now_ns=arrived + S // 2, **late)
            ap.silent = False  # the telemetry after it comes: it goes, posed
            wait_for(
                lambda: not link.pose_pending(t_frame, 0.5, now_ns=arrived, **late),
                120.0,
                "the telemetry after the frame",
            )
            assert link.pose(t_frame, t_boot_ns=t_boot) is not None
        finally:
            stop.set()
            link.close()
