"""What a flight log holds (:func:`log_info`): its topics, frames, drops and gaps, every
CRC checked."""

from __future__ import annotations

import dataclasses
import json
import os
from collections import defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path

from mcap.records import Channel, Footer, Message, Metadata, Schema, Statistics

import holescan.flightlog.schemas as sch
from holescan.flightlog.errors import FlightLogError, TruncatedLogError
from holescan.flightlog.format import summary_crc_ok
from holescan.flightlog.reader import log_files
from holescan.flightlog.scan import ScanState, scan_records

__all__ = ["LogInfo", "TopicInfo", "log_info"]


@dataclasses.dataclass(frozen=True)
class TopicInfo:
    """One topic of a log: its schema, how many messages, which sequence numbers are missing
    (records the logger dropped)."""

    topic: str
    schema: str
    message_encoding: str
    count: int
    first_sequence: int
    last_sequence: int
    missing_sequences: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class LogInfo:
    """What a flight log (one file or its rotated files) holds.

    start_t_unix_ns, end_t_unix_ns : first and last message log time (Unix clock).
    frames : complete RGB-D frames; dropped_frames : frame sequence numbers the logger
        dropped; frame_index_gaps : frame indices missing from the sensor's numbering.
    logger_dropped : records the logger dropped per topic, from its last ``/health``
        record (also counts drops after the last message written, which leave no gap).
    metadata : the MCAP metadata records of the first file (``holescan``,
        ``holescan.config``, ``holescan.camera``, ...), later files' names added.
    """

    paths: tuple[Path, ...]
    file_bytes: int
    chunks: int
    start_t_unix_ns: int
    end_t_unix_ns: int
    message_count: int
    topics: Mapping[str, TopicInfo]
    frames: int
    dropped_frames: tuple[int, ...]
    frame_index_gaps: tuple[int, ...]
    metadata: Mapping[str, Mapping[str, str]]
    truncated: tuple[str, ...]
    logger_dropped: Mapping[str, int]

    @property
    def duration_s(self) -> float:
        return max(self.end_t_unix_ns - self.start_t_unix_ns, 0) / 1e9

    def lines(self) -> list[str]:
        """Human-readable report, one fact per line."""
        out = [
            f"files: {len(self.paths)} ({self.file_bytes / 1e6:.1f} MB, {self.chunks} chunks)",
            f"duration: {self.duration_s:.2f} s, {self.message_count} messages",
            f"frames: {self.frames}, dropped by logger: {len(self.dropped_frames)}, "
            f"missing sensor indices: {len(self.frame_index_gaps)}",
            f"logger drops: {dict(self.logger_dropped)}",
        ]
        for t in sorted(self.topics.values(), key=lambda t: t.topic):
            gaps = f", {len(t.missing_sequences)} missing" if t.missing_sequences else ""
            out.append(f"  {t.topic}: {t.count} x {t.schema}{gaps}")
        for name, values in self.metadata.items():
            out.append(f"metadata {name}: {json.dumps(dict(values), sort_keys=True)}")
        out.extend(f"truncated: {why}" for why in self.truncated)
        return out


def _missing(seqs: list[int]) -> tuple[int, ...]:
    if not seqs:
        return ()
    seen = set(seqs)
    return tuple(s for s in range(min(seqs), max(seqs) + 1) if s not in seen)


def _check_summary_crc(path: Path, footer: Footer, size: int) -> None:
    with open(path, "rb") as f:
        if not summary_crc_ok(f, footer, size):
            raise FlightLogError(f"{path}: summary section CRC mismatch (corrupt file)")


def log_info(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    *,
    allow_truncated: bool = False,
) -> LogInfo:
    """Scan a flight log (every CRC checked) and report what it holds.

    Raises
    ------
    FlightLogError : missing, empty, not MCAP, or its summary disagrees with its content.
    TruncatedLogError : a file was cut off (unless ``allow_truncated``); repair it with
        :func:`recover_log`.
    """
    files = log_files(paths)
    seqs: dict[str, list[int]] = defaultdict(list)
    schemas_of: dict[str, tuple[str, str]] = {}
    frame_indices: list[int] = []
    metadata: dict[str, dict[str, str]] = {}
    truncated: list[str] = []
    logger_dropped: dict[str, int] = {}
    start, end, total_bytes, chunks, count = 2**64, 0, 0, 0, 0
    for path in files:
        state = ScanState(path)
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        counted: dict[int, int] = defaultdict(int)
        stats: Statistics | None = None
        footer: Footer | None = None
        for rec in scan_records(path, state):
            if isinstance(rec, Message):
                ch = channels[rec.channel_id]
                counted[rec.channel_id] += 1
                seqs[ch.topic].append(rec.sequence)
                start, end, count = min(start, rec.log_time), max(end, rec.log_time), count + 1
                if ch.topic == sch.TOPIC_FRAME_INFO:
                    frame_indices.append(int(sch.from_json(rec.data)["index"]))
                elif ch.topic == sch.TOPIC_HEALTH:
                    health = sch.from_json(rec.data)
                    if health.get("source") == "logger":
                        logger_dropped = dict(health.get("dropped", {}))
            elif isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
                schema = schemas.get(rec.schema_id)
                schemas_of[rec.topic] = (
                    "" if schema is None else schema.name,
                    rec.message_encoding,
                )
            elif isinstance(rec, Metadata):
                if rec.name not in metadata or rec.name == "holescan.world_origin":
                    metadata[rec.name] = dict(rec.metadata)
            elif isinstance(rec, Statistics):
                stats = rec
            elif isinstance(rec, Footer):
                footer = rec
        total_bytes += state.size
        chunks += state.chunks
        if not state.whole:
            if not allow_truncated:
                raise TruncatedLogError(state.describe_stop())
            truncated.append(state.describe_stop())
            continue
        if footer is not None:
            _check_summary_crc(path, footer, state.size)
        if stats is not None and dict(stats.channel_message_counts) != dict(counted):
            raise FlightLogError(
                f"{path}: summary counts {dict(stats.channel_message_counts)} "
                f"disagree with the {sum(counted.values())} messages in the file"
            )
    topics = {
        topic: TopicInfo(topic, *schemas_of[topic], len(s), min(s), max(s), _missing(s))
        for topic, s in seqs.items()
    }
    frames = min(len(seqs[t]) for t in (sch.TOPIC_COLOR, sch.TOPIC_DEPTH, sch.TOPIC_FRAME_INFO))
    return LogInfo(
        paths=tuple(files),
        file_bytes=total_bytes,
        chunks=chunks,
        start_t_unix_ns=start if count else 0,
        end_t_unix_ns=end,
        message_count=count,
        topics=topics,
        frames=frames,
        dropped_frames=_missing(seqs[sch.TOPIC_FRAME_INFO]),
        frame_index_gaps=_missing(frame_indices),
        metadata=metadata,
        truncated=tuple(truncated),
        logger_dropped=logger_dropped,
    )
