"""The daemon's /health records: typed, with the JSON keys the logs have always held."""

from __future__ import annotations

import dataclasses
import math

from holescan.capture import FlightCounters
from holescan.capture._health import AutopilotSilent, FlightHealth, LinkHealth, SensorFailed
from holescan.capture._worker import WorkerStats
from holescan.flightlog.options import WriterStats

# The keys of the periodic record in logs written before the record was typed: readers
# (reports, tests/capture/test_modes.py, benchmarks/sitl_report.py) look them up by name.
DAEMON_KEYS = [
    "frames_captured", "frames_logged", "frames_log_dropped", "log_queue_depth",
    "detect_offered", "detect_skipped", "detect_done", "detect_ms_mean", "detect_errors",
    "frames_no_depth", "frames_unposed", "pose_refusals", "pose_invalid", "pose_invalid_why",
    "sensor_failures", "holes", "frames_shed",
]  # fmt: skip
LINK_KEYS = ["mavlink_bad_bytes", "mavlink_bad_packets", "mavlink_age_s", "clock_source"]
VEHICLE_KEYS = ["autopilot_mode", "autopilot_armed", "autopilot_mode_changes"]


def writer_stats() -> WriterStats:
    return WriterStats(
        enqueued={}, written={"frames": 7}, dropped={"frames": 2}, frames_synced=7,
        queue_depth=3, queue_depth_max=5, frames_queued_max=2, frame_write_ms_mean=1.0,
        frame_write_ms_max=2.0, frame_cpu_ms_mean=1.0, enqueue_ms_max=0.1, bytes_written=10,
        files=(), error=None,
    )  # fmt: skip


def test_periodic_record_keys_and_values() -> None:
    c = FlightCounters(frames_captured=9, frames_detected=4, detect_ms_total=10.0)
    h = FlightHealth.of(
        c, writer_stats(), WorkerStats(9, 5, 4), holes=2, pose_invalid_why="", telemetry=None
    )
    rec = h.record()
    assert list(rec) == DAEMON_KEYS
    assert (rec["frames_logged"], rec["frames_log_dropped"], rec["log_queue_depth"]) == (7, 2, 3)
    assert (rec["detect_offered"], rec["detect_skipped"], rec["detect_done"]) == (9, 5, 4)
    assert rec["detect_ms_mean"] == 2.5 and rec["holes"] == 2


def test_link_keys_follow_the_daemon_keys_clock_only_once_synchronised() -> None:
    vehicle = {"mode": "AUTO", "armed": True, "mode_changes": 1}
    unsynced = LinkHealth(0, 1, math.inf, "none", vehicle)
    assert list(unsynced.record()) == LINK_KEYS + VEHICLE_KEYS
    synced = LinkHealth(4, 1, 0.02, "timesync", vehicle, -12_345, 300_000)
    rec = synced.record()
    assert list(rec) == [*LINK_KEYS, *VEHICLE_KEYS, "clock_offset_ns", "clock_uncertainty_ns"]
    assert rec["autopilot_mode"] == "AUTO" and rec["clock_offset_ns"] == -12_345
    h = FlightHealth.of(
        FlightCounters(), writer_stats(), WorkerStats(0, 0, 0), holes=0, pose_invalid_why="",
        telemetry=None,
    )  # fmt: skip
    with_link = dataclasses.replace(h, link=synced).record()
    assert list(with_link) == DAEMON_KEYS + list(rec)


def test_events() -> None:
    assert SensorFailed("stalled", 2.0).record() == {
        "event": "sensor_failure",
        "error": "stalled",
        "retry_in_s": 2.0,
    }
    assert AutopilotSilent("no heartbeat").record() == {
        "event": "autopilot_silent",
        "error": "no heartbeat",
    }
