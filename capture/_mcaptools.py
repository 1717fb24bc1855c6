"""Flight log maintenance: what a log holds (:func:`log_info`) and repairing a file cut off
by a crash or power loss (:func:`recover_log`)."""

from __future__ import annotations

import dataclasses
import json
import os
import zlib
from collections import defaultdict
from collections.abc import Iterable, Mapping
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import IO

from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    Footer,
    Header,
    Message,
    Metadata,
    Schema,
    Statistics,
)
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from holescan.capture import _mcapschemas as sch
from holescan.capture._mcaplog import FlightLogError
from holescan.capture._mcapread import TruncatedLogError, _as_paths
from holescan.capture._mcapscan import DamagedRegion, ScanState, scan_records
from holescan.capture._outpath import OutputPathError, check_output, commit_part, part_path

__all__ = ["LogInfo", "RecoveryReport", "TopicInfo", "log_info", "recover_log"]

_FOOTER_BYTES = 1 + 8 + 8 + 8 + 4  # opcode, length, summary start, offsets start, crc
_MAGIC_BYTES = 8


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
    if footer.summary_start == 0 or footer.summary_crc == 0:
        return
    end = size - _MAGIC_BYTES - 4
    with open(path, "rb") as f:
        f.seek(footer.summary_start)
        data = f.read(end - footer.summary_start)
    if zlib.crc32(data) != footer.summary_crc:
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
    files = _as_paths(paths)
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


@dataclasses.dataclass(frozen=True)
class RecoveryReport:
    """What :func:`recover_log` saved.

    source_complete : the source had its footer (nothing was lost; it was rewritten).
    bytes_used : the source's bytes up to its last intact record, of ``bytes_total``.
    last_t_unix_ns : log time of the last message saved.
    stop_reason : why reading stopped early (None when complete).
    """

    src: Path
    dst: Path
    source_complete: bool
    messages: int
    topics: Mapping[str, int]
    frames: int
    bytes_used: int
    bytes_total: int
    last_t_unix_ns: int
    stop_reason: str | None
    damaged: tuple[DamagedRegion, ...] = ()
    messages_lost: int = 0

    def line(self) -> str:
        how = "complete" if self.source_complete else f"cut off: {self.stop_reason}"
        if self.damaged:
            how += (
                f"; {len(self.damaged)} damaged region(s) skipped, "
                f"{self.messages_lost} messages lost: "
                + "; ".join(d.describe() for d in self.damaged)
            )
        return (
            f"{self.dst}: {self.messages} messages, {self.frames} frames recovered from "
            f"{self.src} ({how}; {self.bytes_used} of {self.bytes_total} bytes used)"
        )


def _compression(name: str) -> CompressionType:
    return {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(
        name, CompressionType.NONE
    )


def recover_log(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> RecoveryReport:
    """Rewrite ``src`` (a flight log file, possibly cut off mid-write) as a valid, indexed
    MCAP file ``dst`` holding every message up to its last complete chunk, with its
    metadata and attachments.

    ``dst`` must not exist (and must not be ``src``); it is written under a temporary name
    and renamed when complete. Raises :class:`FlightLogError` when ``src`` is missing or
    not MCAP.
    """
    src_p, dst_p = Path(src), check_output(dst, inputs=[src])
    state = ScanState(src_p)
    records = scan_records(src_p, state)
    tmp = part_path(dst_p)
    header: Header | None = None
    writer: McapWriter | None = None
    stream: IO[bytes] | None = None
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    channels: dict[int, Channel] = {}
    pending_schemas: dict[int, Schema] = {}
    topics: dict[str, int] = defaultdict(int)
    messages, last_t, unschematic = 0, 0, 0
    try:
        for rec in records:
            if isinstance(rec, Header):
                header = rec
                continue
            if writer is None:
                compression = rec.compression if isinstance(rec, Chunk) else "zstd"
                try:
                    stream = open(tmp, "wb")  # noqa: SIM115 (closed below)
                except OSError as err:
                    raise OutputPathError(f"cannot write {tmp}: {err.strerror}") from err
                writer = McapWriter(
                    stream, compression=_compression(compression), enable_data_crcs=True
                )
                library = header.library if header is not None else ""
                writer.start(
                    profile=header.profile if header is not None else "",
                    library=f"{library} recovered-by holescan/{_dist_version('holescan')}".strip(),
                )
            if isinstance(rec, Schema):
                if rec.id not in schema_ids and rec.id not in pending_schemas:
                    pending_schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                if rec.id not in channel_ids:
                    sid = 0
                    if rec.schema_id != 0:
                        if rec.schema_id not in schema_ids:
                            s = pending_schemas.pop(rec.schema_id, None)
                            if s is None:  # its schema was lost with damaged bytes
                                continue  # (so are its messages: counted below)
                            schema_ids[rec.schema_id] = writer.register_schema(
                                s.name, s.encoding, s.data
                            )
                        sid = schema_ids[rec.schema_id]
                    channel_ids[rec.id] = writer.register_channel(
                        rec.topic, rec.message_encoding, sid, dict(rec.metadata)
                    )
                    channels[rec.id] = rec
            elif isinstance(rec, Message):
                if rec.channel_id not in channel_ids:
                    unschematic += 1
                    continue
                writer.add_message(
                    channel_ids[rec.channel_id],
                    rec.log_time,
                    rec.data,
                    rec.publish_time,
                    rec.sequence,
                )
                topics[channels[rec.channel_id].topic] += 1
                messages += 1
                last_t = max(last_t, rec.log_time)
            elif isinstance(rec, Metadata):
                writer.add_metadata(rec.name, dict(rec.metadata))
            elif isinstance(rec, Attachment):
                writer.add_attachment(
                    rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data
                )
        if writer is None or stream is None:
            raise FlightLogError(f"{src_p}: nothing to recover (cut off inside its header)")
        writer.finish()  # type: ignore[no-untyped-call]
        stream.flush()
        os.fsync(stream.fileno())
        stream.close()
        commit_part(tmp, dst_p)
    except OSError as err:
        if stream is not None:
            stream.close()
        tmp.unlink(missing_ok=True)
        raise OutputPathError(f"cannot write {dst_p}: {err.strerror or err}") from err
    except BaseException:
        if stream is not None:
            stream.close()
        tmp.unlink(missing_ok=True)
        raise
    frames = min(topics.get(t, 0) for t in (sch.TOPIC_COLOR, sch.TOPIC_DEPTH, sch.TOPIC_FRAME_INFO))
    return RecoveryReport(
        src=src_p,
        dst=dst_p,
        source_complete=state.complete,
        messages=messages,
        topics=dict(topics),
        frames=frames,
        bytes_used=state.good_bytes,
        bytes_total=state.size,
        last_t_unix_ns=last_t,
        stop_reason=state.stop_reason,
        damaged=tuple(state.damaged),
        messages_lost=state.messages_lost + unschematic,
    )
