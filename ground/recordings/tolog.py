"""A recording made elsewhere as a holescan flight log, so that ``holescan reprocess`` (and
everything that reads flight logs) takes it: frames, the camera, and the vehicle's pose
when the recording has one (a bag's NavSatFix + Imu, see :mod:`.bagtelemetry`).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from holescan.detect import CameraIntrinsics
from holescan.errors import HolescanError, InputError
from holescan.flightlog import FlightLogWriter, log_file_path, read_log_layout
from holescan.ground.recordings.bagtelemetry import BagTelemetry, read_bag_telemetry
from holescan.ground.recordings.source import open_recording, recording_kind
from holescan.link import TelemetryReplay

__all__ = ["ConvertedRecording", "flight_logs_of", "recording_to_log"]

_QUEUE_LOW: Final = 16  # records waiting for the writer before the reader waits (never drop)
_SOURCE_KEY: Final = "source_recording"


@dataclass(frozen=True)
class ConvertedRecording:
    """What :func:`recording_to_log` did.

    log : the flight log's first file. frames : frames written (0 when reused).
    telemetry : the bag's telemetry topics (``fix`` and ``imu``), or None (frames only).
    reused : the log existed, made from the same recording, and was kept.
    """

    log: Path
    frames: int
    telemetry: tuple[str, str] | None
    reused: bool


def _identity(path: Path) -> str:
    """The recording's path, size and modification time (a reused log must match it)."""
    st = path.stat()
    size = st.st_size if path.is_file() else sum(p.stat().st_size for p in path.rglob("*"))
    return json.dumps([str(path.resolve()), size, st.st_mtime_ns])


def recording_to_log(
    recording: str | os.PathLike[str],
    prefix: str | os.PathLike[str],
    *,
    camera: CameraIntrinsics | None = None,
    max_dt_s: float = 0.02,
) -> ConvertedRecording:
    """Write ``recording`` (anything :func:`open_recording` reads but a flight log) as the
    flight log ``PREFIX_0000.mcap``. A log already there that was made from this same
    recording is reused; one made from anything else is refused (never written over).

    Frames keep the recording's timestamps as their capture time (Unix clock: TUM and ROS
    stamps are). Raises :class:`InputError`.
    """
    path = Path(recording)
    kind = recording_kind(path)
    if kind == "mcap":
        raise InputError(f"{path}: already a flight log: reprocess it as it is")
    first = log_file_path(prefix, 0)
    identity = _identity(path)
    if first.exists():
        try:
            config = read_log_layout(first).metadata.get("holescan.config", {})
        except HolescanError as err:  # a damaged or foreign file: refuse, never overwrite
            raise InputError(f"{first} exists and is not a readable flight log") from err
        if config.get(_SOURCE_KEY) == json.dumps(identity):
            return ConvertedRecording(first, 0, None, reused=True)
        raise InputError(
            f"{first} exists and was not made from {path} as it is now: remove it or choose "
            "another --out"
        )
    first.parent.mkdir(parents=True, exist_ok=True)
    source = open_recording(path, camera=camera, max_dt_s=max_dt_s)
    frames = 0
    telemetry: BagTelemetry | None = None
    with source:
        reader = getattr(source, "reader", None)
        if reader is not None:
            telemetry = read_bag_telemetry(reader, reader.start_time)
        packets = list(telemetry.packets) if telemetry else []
        boot = telemetry.boot_unix_ns if telemetry else None
        replay = TelemetryReplay(capacity=max(len(packets), 2))  # the flight's own decoder
        for _, packet in packets:
            replay.feed(packet)
        config = {_SOURCE_KEY: identity, "source_kind": kind}
        with FlightLogWriter(prefix, source.camera, config=config) as log:
            k = 0
            for frame in source:
                t = frame.t_sensor_ns
                while k < len(packets) and packets[k][0] <= t:
                    _wait(log)
                    log.write_mavlink(packets[k][1], packets[k][0])
                    k += 1
                t_boot = None if boot is None else t - boot
                pose = replay.pose_at(t_boot)  # logged with the frame, as in flight
                _wait(log)
                if pose is not None:
                    log.write_pose(pose, t)
                log.write_frame(frame, t, pose=pose, t_boot_ns=t_boot)
                frames += 1
            for t_p, packet in packets[k:]:
                _wait(log)
                log.write_mavlink(packet, t_p)
        stats = log.stats()
    if any(stats.dropped.values()):
        raise InputError(f"{first}: the log writer dropped records ({stats.dropped})")
    if frames == 0:
        raise InputError(f"{path}: no frame to convert")
    topics = (telemetry.fix_topic, telemetry.imu_topic) if telemetry else None
    return ConvertedRecording(first, frames, topics, reused=False)


def _wait(log: FlightLogWriter) -> None:
    """Let the writer's queue drain below :data:`_QUEUE_LOW` (a conversion never drops)."""
    while log.stats().queue_depth >= _QUEUE_LOW:
        time.sleep(0.002)


def flight_logs_of(
    inputs: Sequence[str | os.PathLike[str]], out: str | os.PathLike[str]
) -> tuple[list[str | os.PathLike[str]], list[tuple[Path, ConvertedRecording]]]:
    """The flight logs for ``holescan reprocess``: flight logs and URLs as given, every other
    recording converted to ``OUT/recordings/NAME_0000.mcap`` (:func:`recording_to_log`).
    Returns the logs and, per converted recording, what was done."""
    logs: list[str | os.PathLike[str]] = []
    converted: list[tuple[Path, ConvertedRecording]] = []
    used: set[str] = set()
    for given in inputs:
        text = os.fspath(given)
        if "://" in text and not text.startswith("file://"):
            logs.append(given)
            continue
        path = Path(text.removeprefix("file://"))
        if path.is_file() and path.suffix == ".mcap":
            logs.append(given)
            continue
        if recording_kind(path) == "mcap":
            logs.append(given)
            continue
        base = (path.stem if path.is_file() else path.name) or "recording"
        name, n = base, 1
        while name in used:  # e.g. scene.bag and a folder scene/ in one run
            n += 1
            name = f"{base}-{n}"
        used.add(name)
        done = recording_to_log(path, Path(out) / "recordings" / name)
        logs.append(done.log)
        converted.append((path, done))
    return logs, converted
