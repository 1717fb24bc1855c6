"""Frames without any depth reading (the vehicle on the ground, under the Xtion's 0.5 m
minimum range) are counted as "no depth", apart from detector failures, in the flight's
health records, its report and in reprocessing (ArduPilot SITL run: 239 such frames were
reported as detector errors before)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from holescan.capture import Flight, FlightConfig, FlyReport, format_report
from holescan.detect import Frame, detect_holes
from holescan.errors import InputError, NoDepthError
from holescan.flightlog import read_flight_log
from holescan.ground import ReprocessOptions, reprocess
from holescan.sim import SimAutopilot
from tests._support import free_udp_port
from tests.capture.test_daemon import CAM, ScriptedSource, hover_path

ON_GROUND = 40  # frames before take-off: depth all zero (closer than 0.5 m)


class TakeOffSource(ScriptedSource):
    """The scripted hole, after ``ON_GROUND`` frames without any depth reading."""

    def __iter__(self) -> Iterator[Frame]:
        for f in super().__iter__():
            if f.index < ON_GROUND:
                f = Frame(f.index, f.rgb, np.zeros_like(f.depth), f.t_mono_ns, f.t_sensor_ns)
            yield f


def test_no_depth_is_its_own_error_class() -> None:
    rgb = np.zeros((CAM.height, CAM.width, 3), np.uint8)
    with pytest.raises(NoDepthError):
        detect_holes(rgb, np.zeros((CAM.height, CAM.width), np.uint16), CAM)
    with pytest.raises(InputError) as bad:  # a real input fault is not "no depth"
        detect_holes(rgb, np.zeros((CAM.height, CAM.width), np.float32), CAM)  # type: ignore[arg-type]
    assert not isinstance(bad.value, NoDepthError)


def test_frames_on_the_ground_are_no_depth_not_detector_errors(tmp_path: Path) -> None:
    port = free_udp_port()
    n = 120
    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path()):
        cfg = FlightConfig(log_prefix=tmp_path / "flight", max_frames=n, startup_sync_s=1.0)
        flight = Flight(
            cfg, lambda: TakeOffSource(n + 10, fps=15.0), CAM, mavlink=f"udpin:127.0.0.1:{port}"
        )
        summary = flight.run()
    c = summary.counters
    assert c.detect_errors == 0, c
    assert c.frames_no_depth >= 1, c  # the worker may skip some frames for newer ones
    assert c.detections >= 1 and flight.tracker.holes(), c  # after take-off: the hole
    health = [
        r.values
        for r in read_flight_log(summary.log.files)
        if type(r).__name__ == "LoggedHealth" and "frames_no_depth" in r.values
    ]
    assert health and health[-1]["frames_no_depth"] == c.frames_no_depth
    assert health[-1]["detect_errors"] == 0
    text = format_report(FlyReport(summary, "scripted", (), 0, 0))
    assert "0 errors" in text and f"{c.frames_no_depth} without depth" in text

    out = reprocess(list(summary.log.files), tmp_path / "re", ReprocessOptions(workers=0))
    (f,) = out.flights
    assert f.detect_errors == 0 and f.frames_no_depth == ON_GROUND, f.summary()
    assert f.summary()["frames_no_depth"] == ON_GROUND
