"""Issue 20: mode changes during a survey (AUTO -> RTL, LAND, LOITER, GUIDED, back to AUTO)
and disarming / arming break nothing: capture, poses, detection and announcements go on
in every mode (decided: nothing depends on the mode or on arming, see docs/sitl.md), and
the health records say which mode and arming state the autopilot reported."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from holescan.capture import Flight, FlightConfig, Telemetry
from holescan.flightlog import LoggedFrame, LoggedHealth, read_flight_log
from holescan.sim import SimAutopilot
from tests._support import free_udp_port
from tests.capture.test_daemon import CAM, ScriptedSource, hover_path

# ArduCopter custom modes: 3 AUTO, 6 RTL, 9 LAND, 5 LOITER, 4 GUIDED
NAMES = {3: "AUTO", 6: "RTL", 9: "LAND", 5: "LOITER", 4: "GUIDED"}
STEPS = [(6, True), (9, True), (5, True), (4, True), (3, True), (3, False), (3, True)]


def test_mode_changes_and_arming_break_nothing(tmp_path: Path) -> None:
    port = free_udp_port()
    telemetry: list[Telemetry] = []

    def factory(conn: str, **kw: object) -> Telemetry:
        tel = Telemetry(conn, **kw)  # type: ignore[arg-type]
        telemetry.append(tel)
        return tel

    n = 15 * 16
    cfg = FlightConfig(
        log_prefix=tmp_path / "f", max_frames=n, startup_sync_s=1.0, health_period_s=0.5
    )
    seen: list[tuple[str, bool | None]] = []
    marks: list[int] = []
    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path()) as ap:
        flight = Flight(
            cfg,
            lambda: ScriptedSource(n + 10, fps=15.0),
            CAM,
            mavlink=f"udpin:127.0.0.1:{port}",
            telemetry_factory=factory,
        )

        def switch() -> None:
            while not telemetry and not flight.stop.is_set():
                time.sleep(0.05)
            time.sleep(2.0)
            marks.append(time.monotonic_ns())
            for mode, armed in STEPS:
                ap.mode, ap.armed = mode, armed
                want = (NAMES[mode], armed)
                deadline = time.monotonic() + 5.0  # a heartbeat a second carries it
                while time.monotonic() < deadline:
                    v = telemetry[0].stats().vehicle
                    if (v["mode"], v["armed"]) == want:
                        break
                    time.sleep(0.05)
                seen.append((v["mode"], v["armed"]))
                time.sleep(0.6)  # a health record or two in this state

        t = threading.Thread(target=switch, daemon=True)
        t.start()
        summary = flight.run()
        t.join(15)
    tel = telemetry[0]
    assert seen == [
        ("RTL", True),
        ("LAND", True),
        ("LOITER", True),
        ("GUIDED", True),
        ("AUTO", True),
        ("AUTO", False),
        ("AUTO", True),
    ], seen
    assert tel.stats().vehicle["mode_changes"] == len(STEPS)
    assert tel.reboots == 0 and tel.rate_method == "message_interval"
    c = summary.counters
    assert summary.frames_logged == n, c
    frames = list(read_flight_log(summary.log.files, kinds={LoggedFrame}))
    during = [r for r in frames if isinstance(r, LoggedFrame) and r.frame.t_mono_ns > marks[0]]
    assert len(during) > 100 and all(r.pose is not None for r in during)  # posed throughout
    assert c.detect_errors == 0 and flight.tracker.holes(), c
    health = [
        r.values
        for r in read_flight_log(summary.log.files, kinds={LoggedHealth})
        if isinstance(r, LoggedHealth) and "autopilot_mode" in r.values
    ]
    modes = {h["autopilot_mode"] for h in health}
    assert {"RTL", "LAND", "LOITER", "GUIDED", "AUTO"} <= modes, modes
    armed = [h["autopilot_armed"] for h in health]
    # None: no HEARTBEAT heard yet (the first records of a flight), never after one.
    first = next(i for i, a in enumerate(armed) if a is not None)
    assert set(armed[first:]) == {True, False}, armed
