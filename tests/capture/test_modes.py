"""Issue 20: mode changes during a survey (AUTO -> RTL, LAND, LOITER, GUIDED, back to AUTO)
and disarming / arming break nothing: capture, poses, detection and announcements go on
in every mode (decided: nothing depends on the mode or on arming, see docs/sitl.md), and
the health records say which mode and arming state the autopilot reported."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

from holescan.capture import Flight, FlightConfig, Telemetry
from holescan.detect import Frame
from holescan.flightlog import FlightLogWriter, LoggedFrame, LoggedHealth, read_flight_log
from holescan.sim import SimAutopilot
from tests._support import free_udp_port, wait_for
from tests.capture.test_daemon import CAM, ScriptedSource, hover_path, unposed_with_telemetry

# ArduCopter custom modes: 3 AUTO, 6 RTL, 9 LAND, 5 LOITER, 4 GUIDED
NAMES = {3: "AUTO", 6: "RTL", 9: "LAND", 5: "LOITER", 4: "GUIDED"}
STEPS = [(6, True), (9, True), (5, True), (4, True), (3, True), (3, False), (3, True)]


class UntilDone(ScriptedSource):
    """The scripted frames until ``done`` is set: the recording then ends the flight."""

    def __init__(self, done: threading.Event) -> None:
        super().__init__(100_000, fps=15.0)
        self.done = done

    def __iter__(self) -> Iterator[Frame]:
        for frame in super().__iter__():
            if self.done.is_set():
                return
            yield frame


def test_mode_changes_and_arming_break_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Driven by what the flight did, never by wall time (a loaded machine runs each part
    # late): the first change waits for the autopilot's first HEARTBEAT (else it is the
    # first state heard, not a change), each state is held until a health record in it
    # was written, and the flight ends once the changes are done.
    port = free_udp_port()
    telemetry: list[Telemetry] = []
    written: list[dict[str, Any]] = []  # every health record, as the daemon writes it
    write_health = FlightLogWriter.write_health

    def spy(writer: FlightLogWriter, values: Mapping[str, Any], *a: Any, **kw: Any) -> bool:
        written.append(dict(values))
        return write_health(writer, values, *a, **kw)

    monkeypatch.setattr(FlightLogWriter, "write_health", spy)

    def factory(conn: str, **kw: object) -> Telemetry:
        # A loaded machine acknowledges late: rates by MESSAGE_INTERVAL all the same.
        tel = Telemetry(conn, command_timeout_s=5.0, **kw)  # type: ignore[arg-type]
        telemetry.append(tel)
        return tel

    # pose_wait_s: each frame waits (held, never the capture thread) for the telemetry
    # after it; long enough here for a loaded machine, whose in-process simulator and
    # receiver run tenths of a second late: what is tested is that frames are posed.
    cfg = FlightConfig(
        log_prefix=tmp_path / "f", startup_sync_s=1.0, health_period_s=0.5, pose_wait_s=3.0
    )
    seen: list[tuple[str, bool | None]] = []
    marks: list[int] = []
    done = threading.Event()

    def in_health(want: tuple[str, bool]) -> bool:
        return any(
            (h.get("autopilot_mode"), h.get("autopilot_armed")) == want for h in list(written)
        )

    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path()) as ap:
        flight = Flight(
            cfg,
            lambda: UntilDone(done),
            CAM,
            mavlink=f"udpin:127.0.0.1:{port}",
            telemetry_factory=factory,
        )

        def switch() -> None:
            try:
                wait_for(lambda: telemetry, 120.0, "the telemetry link")
                vehicle = telemetry[0].stats
                wait_for(
                    lambda: (
                        (vehicle().vehicle["mode"], vehicle().vehicle["armed"]) == ("AUTO", True)
                    ),
                    60.0,
                    "the first HEARTBEAT",
                )
                wait_for(lambda: flight.counters.frames_captured > 0, 120.0, "frames")
                marks.append(time.monotonic_ns())
                start = flight.counters.frames_captured
                for mode, armed in STEPS:
                    ap.mode, ap.armed = mode, armed
                    want = (NAMES[mode], armed)
                    with contextlib.suppress(TimeoutError):  # `seen` says what came
                        wait_for(  # a heartbeat a second carries it
                            lambda: (vehicle().vehicle["mode"], vehicle().vehicle["armed"]) == want,  # noqa: B023 (called in this iteration)
                            60.0,
                            f"{want} heard",
                        )
                    v = vehicle().vehicle
                    seen.append((v["mode"], v["armed"]))
                    with contextlib.suppress(TimeoutError):
                        wait_for(lambda: in_health(want), 60.0, f"a health record in {want}")  # noqa: B023
                # Enough frames after the first change to say "posed throughout".
                wait_for(lambda: flight.counters.frames_captured - start > 100, 120.0, "100 frames")
            finally:
                done.set()  # the recording ends: the flight ends normally

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
    assert summary.frames_logged == c.frames_captured and c.frames_log_dropped == 0, c
    frames = list(read_flight_log(summary.log.files, kinds={LoggedFrame}))
    during = [r for r in frames if isinstance(r, LoggedFrame) and r.frame.t_mono_ns > marks[0]]
    # Posed throughout, but where the (CPU-starved) simulator sent no position for longer
    # than the pose buffer bridges.
    indices = {r.frame.index for r in during}
    unposed = [u for u in unposed_with_telemetry(summary.log.files) if u[0] in indices]
    assert len(during) > 100 and not unposed, (unposed, c)
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
