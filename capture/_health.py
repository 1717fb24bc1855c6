"""What the flight daemon writes on the flight log's ``/health`` topic, as typed records.

Two kinds of record: the periodic :class:`FlightHealth` (every ``health_period_s``: frames,
detector, poses, sensor, the autopilot link), and events when something happens
(:class:`SensorFailed`, :class:`AutopilotSilent`). Each turns into the JSON object the log
has always held (:meth:`~FlightHealth.record`): the keys are the logs' format, read back by
:class:`flightlog.LoggedHealth` and the reports, so they never change name. The logger's
own health records (``source = "logger"``) are the flight log writer's.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from holescan.capture._flightrecords import FlightCounters
from holescan.capture._mavlink import Telemetry
from holescan.capture._worker import WorkerStats
from holescan.capture.errors import ClockUnavailable
from holescan.flightlog.options import WriterStats

__all__ = ["AutopilotSilent", "FlightHealth", "LinkHealth", "SensorFailed"]


@dataclass(frozen=True)
class LinkHealth:
    """The autopilot link's part of a health record (only while a link is up).

    bad_bytes, bad_packets : garbage skipped and packets refused so far
        (:class:`capture.TelemetryStats`).
    age_s : seconds since anything arrived from the autopilot (inf before the first).
    clock_source : how companion time maps to the autopilot's (:class:`capture.ClockSync`).
    vehicle : the autopilot's ``mode``, ``armed`` and ``mode_changes`` seen: recorded, no
        behaviour depends on them.
    clock_offset_ns, clock_uncertainty_ns : boot - mono offset and its bound, ns; None
        until the clock is synchronised.
    """

    bad_bytes: int
    bad_packets: int
    age_s: float
    clock_source: str
    vehicle: Mapping[str, Any]
    clock_offset_ns: int | None = None
    clock_uncertainty_ns: int | None = None

    @classmethod
    def of(cls, tel: Telemetry) -> LinkHealth:
        """The link's health now."""
        ts = tel.stats()
        offset = uncertainty = None
        with contextlib.suppress(ClockUnavailable):
            offset, uncertainty = tel.clock.offset_ns, tel.clock.uncertainty_ns
        return cls(
            bad_bytes=ts.bad_bytes,
            bad_packets=ts.bad_packets,
            age_s=tel.last_message_age_s(),
            clock_source=tel.clock.source,
            vehicle=dict(ts.vehicle),
            clock_offset_ns=offset,
            clock_uncertainty_ns=uncertainty,
        )

    def record(self) -> dict[str, Any]:
        """The keys of a ``/health`` record (``mavlink_*``, ``clock_*``, ``autopilot_*``)."""
        out: dict[str, Any] = {
            "mavlink_bad_bytes": self.bad_bytes,
            "mavlink_bad_packets": self.bad_packets,
            "mavlink_age_s": self.age_s,
            "clock_source": self.clock_source,
            **{f"autopilot_{k}": v for k, v in self.vehicle.items()},
        }
        if self.clock_offset_ns is not None:
            out["clock_offset_ns"] = self.clock_offset_ns
            out["clock_uncertainty_ns"] = self.clock_uncertainty_ns
        return out


@dataclass(frozen=True)
class FlightHealth:
    """The daemon's periodic health record.

    frames_captured : frames read from the sensor. frames_logged, frames_log_dropped :
    frames the flight log wrote / dropped (queue full). log_queue_depth : records queued for
    the log. detect_offered, detect_skipped, detect_done : frames offered to the detector,
    replaced by a newer one before it was free, detected. detect_ms_mean : detector time per
    frame. detect_errors : frames the detector failed on. frames_no_depth : frames without
    any depth reading. frames_unposed : frames without a pose at capture. pose_refusals :
    detected frames never placed; pose_invalid : of them, because the autopilot had no
    position (pose_invalid_why : the last reason). sensor_failures : sensor faults (each
    followed by a reopen). holes : holes tracked. link : the autopilot link, None without
    one. frames_shed : frames logged but not offered to the detector or the live map
    because the log writer was behind (short of CPU).
    """

    frames_captured: int
    frames_logged: int
    frames_log_dropped: int
    log_queue_depth: int
    detect_offered: int
    detect_skipped: int
    detect_done: int
    detect_ms_mean: float
    detect_errors: int
    frames_no_depth: int
    frames_unposed: int
    pose_refusals: int
    pose_invalid: int
    pose_invalid_why: str
    sensor_failures: int
    holes: int
    link: LinkHealth | None = None
    frames_shed: int = 0

    @classmethod
    def of(
        cls,
        counters: FlightCounters,
        log: WriterStats,
        worker: WorkerStats,
        *,
        holes: int,
        pose_invalid_why: str,
        telemetry: Telemetry | None,
    ) -> FlightHealth:
        """The flight's health from its counters and its parts' statistics."""
        c = counters
        return cls(
            frames_captured=c.frames_captured,
            frames_logged=log.written.get("frames", 0),
            frames_log_dropped=log.dropped.get("frames", 0),
            log_queue_depth=log.queue_depth,
            detect_offered=worker.offered,
            detect_skipped=worker.skipped,
            detect_done=worker.done,
            detect_ms_mean=c.detect_ms_total / max(c.frames_detected, 1),
            detect_errors=c.detect_errors,
            frames_no_depth=c.frames_no_depth,
            frames_unposed=c.frames_unposed,
            pose_refusals=c.pose_refusals,
            pose_invalid=c.pose_invalid,
            pose_invalid_why=pose_invalid_why,
            sensor_failures=c.sensor_failures,
            holes=holes,
            link=None if telemetry is None else LinkHealth.of(telemetry),
            frames_shed=c.frames_shed,
        )

    def record(self) -> dict[str, Any]:
        """The ``/health`` record: these names as keys, then the link's (:class:`LinkHealth`)."""
        out: dict[str, Any] = {
            "frames_captured": self.frames_captured,
            "frames_logged": self.frames_logged,
            "frames_log_dropped": self.frames_log_dropped,
            "log_queue_depth": self.log_queue_depth,
            "detect_offered": self.detect_offered,
            "detect_skipped": self.detect_skipped,
            "detect_done": self.detect_done,
            "detect_ms_mean": self.detect_ms_mean,
            "detect_errors": self.detect_errors,
            "frames_no_depth": self.frames_no_depth,
            "frames_unposed": self.frames_unposed,
            "pose_refusals": self.pose_refusals,
            "pose_invalid": self.pose_invalid,
            "pose_invalid_why": self.pose_invalid_why,
            "sensor_failures": self.sensor_failures,
            "holes": self.holes,
            "frames_shed": self.frames_shed,
        }
        if self.link is not None:
            out.update(self.link.record())
        return out


@dataclass(frozen=True)
class SensorFailed:
    """Event: the sensor failed (raised, or no frame in time); reopened after ``retry_in_s``.

    >>> SensorFailed("no frame from the sensor for 3.0 s", 0.5).record()
    {'event': 'sensor_failure', 'error': 'no frame from the sensor for 3.0 s', 'retry_in_s': 0.5}
    """

    error: str
    retry_in_s: float

    def record(self) -> dict[str, Any]:
        """The ``/health`` record, ``event = "sensor_failure"``."""
        return {"event": "sensor_failure", "error": self.error, "retry_in_s": self.retry_in_s}


@dataclass(frozen=True)
class AutopilotSilent:
    """Event: the autopilot did not answer at start; frames are captured unposed while the
    link is retried.

    >>> AutopilotSilent("no heartbeat in 5.0 s").record()
    {'event': 'autopilot_silent', 'error': 'no heartbeat in 5.0 s'}
    """

    error: str

    def record(self) -> dict[str, Any]:
        """The ``/health`` record, ``event = "autopilot_silent"``."""
        return {"event": "autopilot_silent", "error": self.error}
