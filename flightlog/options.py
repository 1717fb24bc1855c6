"""How the flight log writer is set up (:class:`LogOptions`), what it reports
(:class:`WriterStats`), and the names of a log's rotated files.

:class:`LogOptions` holds the one copy of the writer's defaults: the ``[log]`` table of
``holescan fly``'s configuration takes its defaults from it.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Literal

from holescan.errors import InputError
from holescan.flightlog.format import COMPRESSION
from holescan.flightlog.images import COLOR_CODECS, DEPTH_CODECS, ColorCodec, DepthCodec

__all__ = ["LogOptions", "WriterStats", "log_file_path"]


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
    color, jpeg_quality : how colour images are stored: ``jpeg`` (lossy, this quality),
        ``png`` (lossless) or ``raw`` (``foxglove.RawImage``, ~28 MB/s at 30 fps).
    depth : how depth images are stored, always lossless: ``zstd`` (fast), ``png``
        (Foxglove shows it; 5-10x slower) or ``raw`` (see :mod:`~flightlog.images`).
    image_reserve_bytes : when the log's disk has less free space than this, the writer
        stops logging frames (colour, depth) and keeps everything else (telemetry,
        detections, holes, health); 0 = never stop. Checked before each frame is written
        (and every ``sync_interval_s``): frames still queued when it is reached are not
        logged either.
    """

    chunk_size: int = 1 << 20
    compression: Literal["zstd", "lz4", "none"] = "zstd"
    max_file_bytes: int = 1 << 30
    max_file_s: float = 60.0
    sync_interval_s: float = 1.0
    max_queued_frames: int = 60
    max_queued_messages: int = 20_000
    color: ColorCodec = "jpeg"
    jpeg_quality: int = 90
    depth: DepthCodec = "zstd"
    image_reserve_bytes: int = 1 << 30

    def __post_init__(self) -> None:
        if self.compression not in COMPRESSION:
            raise InputError(f"compression must be one of {sorted(COMPRESSION)}")
        if self.chunk_size < 1024 or self.max_file_bytes < self.chunk_size:
            raise InputError("chunk_size must be >= 1024 and <= max_file_bytes")
        if self.max_file_s <= 0 or self.sync_interval_s <= 0:
            raise InputError("max_file_s and sync_interval_s must be positive")
        if self.max_queued_frames < 1 or self.max_queued_messages < self.max_queued_frames:
            raise InputError("max_queued_frames >= 1 and max_queued_messages >= it")
        if self.color not in COLOR_CODECS:
            raise InputError(f"color must be one of {list(COLOR_CODECS)}, got {self.color!r}")
        if self.depth not in DEPTH_CODECS:
            raise InputError(f"depth must be one of {list(DEPTH_CODECS)}, got {self.depth!r}")
        if not 1 <= self.jpeg_quality <= 100:
            raise InputError(f"jpeg_quality must be 1..100, got {self.jpeg_quality}")
        if self.image_reserve_bytes < 0:
            raise InputError("image_reserve_bytes must be >= 0")


@dataclasses.dataclass(frozen=True)
class WriterStats:
    """Counters of a :class:`FlightLogWriter` (a snapshot).

    enqueued, written, dropped : per topic (a frame counts once, under ``frames``).
    frames_synced : frames written and fsynced (what a power loss cannot take).
    queue_depth, queue_depth_max : records waiting now / at most so far.
    frames_queued_max : RGB-D frames waiting at most so far.
    frame_write_ms_mean, frame_write_ms_max : writer-thread time to encode and write one
        frame (amortising the chunk compression it triggers).
    frame_cpu_ms_mean : the writer thread's CPU time per frame (image encoding, protobuf,
        chunk compression): x fps / 1000 = the share of one core logging takes.
    enqueue_ms_max : the longest a ``write_*`` call took on the caller's thread.
    images_stopped_t_unix_ns : when the disk reserve stopped frame logging (None: never).
    frames_not_logged : frames offered after that (not logged, not counted as dropped).
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
    frame_cpu_ms_mean: float
    enqueue_ms_max: float
    bytes_written: int
    files: tuple[Path, ...]
    error: str | None
    images_stopped_t_unix_ns: int | None = None
    frames_not_logged: int = 0


def log_file_path(prefix: str | os.PathLike[str], index: int) -> Path:
    """``PREFIX_0003.mcap`` for file ``index`` 3 of the log ``PREFIX`` (``.mcap`` stripped)."""
    p = Path(prefix)
    if p.suffix == ".mcap":
        p = p.with_suffix("")
    return p.with_name(f"{p.name}_{index:04d}.mcap")
