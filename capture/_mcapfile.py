"""One MCAP file of a flight log (:class:`_File`), the writer's options and statistics, and
the log's error class (see :mod:`capture._mcaplog`)."""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Mapping
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import IO, Any, Final, Literal

import mcap
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_protobuf.schema import build_file_descriptor_set

from holescan.capture import _mcapschemas as sch
from holescan.errors import InputError

__all__ = ["FlightLogError", "LogOptions", "WriterStats", "log_file_path", "mcap_version"]

_COMPRESSION: Final = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}


class FlightLogError(InputError):
    """A flight log cannot be written, or a file is not a readable flight log."""


@dataclasses.dataclass(frozen=True)
class LogOptions:
    """How the flight log is written.

    chunk_size : bytes of messages per compressed chunk (1 MiB: a steady ~11 ms per frame;
        larger chunks stall the writer longer when they close).
    compression : chunk compression; zstd (level 3, ~1.5x on RGB-D) or lz4 or none.
    max_file_bytes, max_file_s : start a new file when the current one reaches this size
        or age (a crash then costs at most one file's index; ``recover_log`` rebuilds it).
    sync_interval_s : flush the open chunk and fsync this often (bounds what a power loss
        loses), also the period of the logger's ``/health`` and camera_info records.
    max_queued_frames : RGB-D frames waiting for the writer before new ones are dropped
        (1.2 MB each at 640x480).
    max_queued_messages : all records waiting (frames included) before records are dropped.
    """

    chunk_size: int = 1 << 20
    compression: Literal["zstd", "lz4", "none"] = "zstd"
    max_file_bytes: int = 1 << 30
    max_file_s: float = 60.0
    sync_interval_s: float = 1.0
    max_queued_frames: int = 60
    max_queued_messages: int = 20_000

    def __post_init__(self) -> None:
        if self.compression not in _COMPRESSION:
            raise InputError(f"compression must be one of {sorted(_COMPRESSION)}")
        if self.chunk_size < 1024 or self.max_file_bytes < self.chunk_size:
            raise InputError("chunk_size must be >= 1024 and <= max_file_bytes")
        if self.max_file_s <= 0 or self.sync_interval_s <= 0:
            raise InputError("max_file_s and sync_interval_s must be positive")
        if self.max_queued_frames < 1 or self.max_queued_messages < self.max_queued_frames:
            raise InputError("max_queued_frames >= 1 and max_queued_messages >= it")


@dataclasses.dataclass(frozen=True)
class WriterStats:
    """Counters of a :class:`FlightLogWriter` (a snapshot).

    enqueued, written, dropped : per topic (a frame counts once, under ``frames``).
    frames_synced : frames written and fsynced (what a power loss cannot take).
    queue_depth, queue_depth_max : records waiting now / at most so far.
    frames_queued_max : RGB-D frames waiting at most so far.
    frame_write_ms_mean, frame_write_ms_max : writer-thread time to encode and write one
        frame (amortising the chunk compression it triggers).
    enqueue_ms_max : the longest a ``write_*`` call took on the caller's thread.
    """

    enqueued: Mapping[str, int]
    written: Mapping[str, int]
    dropped: Mapping[str, int]
    frames_synced: int
    queue_depth: int
    queue_depth_max: int
    frames_queued_max: int
    frame_write_ms_mean: float
    frame_write_ms_max: float
    enqueue_ms_max: float
    bytes_written: int
    files: tuple[Path, ...]
    error: str | None


def log_file_path(prefix: str | os.PathLike[str], index: int) -> Path:
    """``PREFIX_0003.mcap`` for file ``index`` 3 of the log ``PREFIX`` (``.mcap`` stripped)."""
    p = Path(prefix)
    if p.suffix == ".mcap":
        p = p.with_suffix("")
    return p.with_name(f"{p.name}_{index:04d}.mcap")


class _File:
    """One open MCAP file: stream, mcap writer, lazily registered schemas and channels."""

    def __init__(self, path: Path, options: LogOptions) -> None:
        try:
            self.stream: IO[bytes] = open(path, "xb")  # noqa: SIM115 (closed in close())
        except FileExistsError as err:
            raise FlightLogError(f"{path} exists: choose another log name") from err
        except OSError as err:
            raise FlightLogError(f"cannot create {path}: {err.strerror}") from err
        self.path = path
        self.writer = McapWriter(
            self.stream,
            chunk_size=options.chunk_size,
            compression=_COMPRESSION[options.compression],
            enable_data_crcs=True,
        )
        library = f"holescan/{_dist_version('holescan')} mcap-python/{mcap_version()}"
        self.writer.start(library=library)
        self.opened_mono_ns = time.monotonic_ns()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}

    def channel(self, topic: str, proto_class: Any | None) -> int:
        cid = self._channels.get(topic)
        if cid is not None:
            return cid
        if proto_class is not None:
            name = proto_class.DESCRIPTOR.full_name
            sid = self._schemas.get(name)
            if sid is None:
                fds = build_file_descriptor_set(proto_class).SerializeToString()
                sid = self.writer.register_schema(name, SchemaEncoding.Protobuf, fds)
                self._schemas[name] = sid
            encoding = MessageEncoding.Protobuf
        else:
            name, schema = sch.JSON_SCHEMAS[topic]
            sid = self.writer.register_schema(name, SchemaEncoding.JSONSchema, sch.to_json(schema))
            encoding = MessageEncoding.JSON
        cid = self.writer.register_channel(topic, encoding, sid)
        self._channels[topic] = cid
        return cid

    def sync(self) -> None:
        self.writer.flush()  # type: ignore[no-untyped-call]
        os.fsync(self.stream.fileno())

    def close(self) -> None:
        self.writer.finish()  # type: ignore[no-untyped-call]
        self.stream.flush()
        os.fsync(self.stream.fileno())
        self.stream.close()


def mcap_version() -> str:
    return getattr(mcap.writer, "__version__", "unknown")
