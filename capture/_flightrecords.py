"""The flight daemon's records: its settings, counters and summary."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from holescan.detect import DEFAULT, DetectParams
from holescan.flightlog.options import LogOptions, WriterStats
from holescan.geotag import AnnounceGate, CameraMount, ErrorModel, Hole


@dataclass(frozen=True)
class FlightConfig:
    """How one flight is captured.

    log_prefix : path prefix of the MCAP files (``PREFIX_0000.mcap`` ...).
    params : detector parameters. mount : camera mount on the vehicle.
    attitude_sigma_deg : how well the camera's attitude is known (autopilot roll/pitch and
        mount calibration), degrees: the attitude term of each sighting's ``sigma_h_m``.
    frame_timeout_s : no frame for this long = the sensor stalled.
    retry_backoff_s : waits between sensor reopen attempts (the last one repeats).
    announce_min_p_hole, announce_min_sightings, announce_min_span_s : the announce gate
        (:class:`geotag.AnnounceGate`): a hole is announced, served as a waypoint and its
        view sent only when its ``p_hole``, sightings and time span reach these.
    review_min_p_hole : a hole not announced whose ``p_hole`` reaches this is sent to the
        ground for review (its card, not a waypoint). Weaker holes stay candidates
        (logged, never sent).
    pose_wait_s : how long after a frame's time its pose waits for the telemetry after it
        (the frame is held, never the capture thread; the results thread waits for the rest).
    startup_sync_s : at start, wait up to this long for the clock sync and a first pose
        (the sensor opens only then; a silent autopilot just delays the start).
    max_frames, max_duration_s : stop after this many frames / seconds (None: until the
        source ends or a stop is requested).
    """

    log_prefix: Path
    params: DetectParams = DEFAULT
    mount: CameraMount = field(default_factory=CameraMount)
    attitude_sigma_deg: float = math.degrees(ErrorModel.attitude_sigma_rad)
    log_options: LogOptions = field(default_factory=LogOptions)
    frame_timeout_s: float = 3.0
    retry_backoff_s: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0, 8.0)
    announce_min_p_hole: float = AnnounceGate.min_p_hole
    announce_min_sightings: int = AnnounceGate.min_sightings
    announce_min_span_s: float = AnnounceGate.min_span_s
    review_min_p_hole: float = AnnounceGate.review_min_p_hole
    health_period_s: float = 1.0
    # 0.5 s: on this 2-core machine at load ~16, 0.15 s left 36-46 of 90 frames unposed
    # (the simulator and the receiver tenths of a second late), 0.5 s 0-15.
    pose_wait_s: float = 0.5
    max_frames: int | None = None
    max_duration_s: float | None = None
    startup_sync_s: float = 3.0
    config_record: dict[str, Any] = field(default_factory=dict)

    @property
    def errors(self) -> ErrorModel:
        """The sightings' error model these settings make."""
        return ErrorModel(attitude_sigma_rad=math.radians(self.attitude_sigma_deg))

    @property
    def gate(self) -> AnnounceGate:
        """The announce gate these settings make."""
        return AnnounceGate(
            self.announce_min_p_hole,
            self.announce_min_sightings,
            self.announce_min_span_s,
            self.review_min_p_hole,
        )


@dataclass
class FlightCounters:
    frames_captured: int = 0
    frames_log_dropped: int = 0
    frames_unposed: int = 0
    frames_detected: int = 0
    detections: int = 0
    detect_ms_total: float = 0.0
    detect_errors: int = 0
    frames_no_depth: int = 0  # depth image without any reading: under range, not an error
    pose_refusals: int = 0
    pose_invalid: int = 0
    sensor_failures: int = 0
    sensor_reopens: int = 0
    announcements: int = 0
    reviews: int = 0
    frames_shed: int = 0  # logged, not offered to the detector or the live map: log behind


@dataclass(frozen=True)
class FlightSummary:
    counters: FlightCounters
    log: WriterStats
    holes: tuple[Hole, ...]
    detect_offered: int
    detect_skipped: int
    duration_s: float
    telemetry: dict[str, Any]

    @property
    def frames_logged(self) -> int:
        return int(self.log.written.get("frames", 0))
