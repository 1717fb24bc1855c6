"""A flight log's chunk index, and reading one chunk by its byte range.

For work split along the chunks of a log (``ground``'s campaign engine): the client reads
only the layout (:func:`read_log_layout`: where each chunk lies, the channels, the
metadata records); each task then opens the log itself and reads its own byte ranges
(:func:`read_chunk`), from a local path or any URL ``fsspec`` opens.

A cleanly closed file gives its layout from its summary section
(:func:`format.read_summary`, CRC checked). A file without a readable summary (cut off by
a crash) is walked record header by record header up to its last complete record (the
flight log's one record walker, :func:`scan.walk_records`, not mcap's
:class:`~mcap.stream_reader.StreamReader`: it must note each chunk's byte range and seek
over the chunk bodies rather than read gigabytes, also from a URL), and
its chunks are opened until every channel the caller needs is known; ``complete`` is then
False and ``stop_reason`` says where it ends.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import struct
from collections.abc import Collection, Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO, Any, Final

import zstandard
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, DataEnd, Footer, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from holescan.flightlog.errors import ChunkDamagedError, FlightLogError, RecordError
from holescan.flightlog.format import (
    MAGIC,
    RECORD_HEADER,
    parse_record,
    read_record_at,
    read_summary,
)
from holescan.flightlog.reader import LogRecord, decode_message
from holescan.flightlog.scan import ChunkHead, ScanState, walk_records

__all__ = [
    "ChunkSpan",
    "LogLayout",
    "decode_messages",
    "open_log",
    "read_chunk",
    "read_log_layout",
]

_DAMAGE: Final = (
    McapError,
    RecordError,
    ValueError,
    struct.error,
    zstandard.ZstdError,
    RuntimeError,
    EOFError,
)


@dataclasses.dataclass(frozen=True)
class ChunkSpan:
    """One chunk: bytes ``[offset, offset + length)`` of the file (the whole record), and the
    log times (ns since the Unix epoch) of its first and last message."""

    offset: int
    length: int
    start_time_ns: int
    end_time_ns: int


@dataclasses.dataclass(frozen=True)
class LogLayout:
    """Where the chunks of one log file lie, and what is known without opening them.

    url : the path or URL the file was read from. size : bytes.
    chunks : in file order. channels : id -> channel (topic, schema id, encoding).
    schemas : id -> schema. metadata : metadata records, name -> key -> value.
    complete : the file was closed cleanly (summary read). stop_reason : why a walked file
    ends where it does (None when complete).
    content_hash : a digest of the file's size, first 4 KiB and chunk index (or, for a
    walked file, of every chunk's header with its CRC): the file's identity for caching.
    """

    url: str
    size: int
    chunks: tuple[ChunkSpan, ...]
    channels: Mapping[int, Channel]
    schemas: Mapping[int, Schema]
    metadata: Mapping[str, Mapping[str, str]]
    complete: bool
    stop_reason: str | None
    content_hash: str

    def topics(self) -> dict[str, int]:
        """topic -> channel id."""
        return {c.topic: cid for cid, c in self.channels.items()}


def open_log(url: str, storage_options: Mapping[str, Any] | None = None) -> IO[bytes]:
    """Open a log for reading: a local path with ``open``, a URL (``s3://``, ``http://``...)
    with ``fsspec``. Raises :class:`FlightLogError` when it cannot be opened."""
    try:
        if "://" in url and not url.startswith("file://"):
            import fsspec  # only for URLs

            f: IO[bytes] = fsspec.open(url, "rb", **dict(storage_options or {})).open()
            return f
        return open(url.removeprefix("file://"), "rb")
    except FileNotFoundError as err:
        raise FlightLogError(f"{url}: no such file") from err
    except OSError as err:
        raise FlightLogError(f"{url}: cannot read: {err}") from err


def _size(f: IO[bytes]) -> int:
    f.seek(0, os.SEEK_END)
    return f.tell()


def read_log_layout(
    url: str | os.PathLike[str],
    *,
    topics: Collection[str] = (),
    storage_options: Mapping[str, Any] | None = None,
) -> LogLayout:
    """The layout of one MCAP log (see the module docstring).

    topics : channels the caller needs; a file without a summary has its chunks opened (in
    order) until all of them are found or the file ends.

    Raises :class:`FlightLogError` for a missing, empty or non-MCAP file.
    """
    name = os.fspath(url)
    with open_log(name, storage_options) as f:
        size = _size(f)
        f.seek(0)
        head = f.read(4096)
        if size == 0:
            raise FlightLogError(f"{name}: empty file, not an MCAP flight log")
        if not head.startswith(MAGIC):
            raise FlightLogError(f"{name}: not an MCAP file (bad magic)")
        digest = hashlib.blake2b(struct.pack("<Q", size) + head, digest_size=16)
        layout = _from_summary(f, name, size, digest)
        return layout if layout is not None else _walk(f, name, size, digest, set(topics))


def _from_summary(f: IO[bytes], name: str, size: int, digest: Any) -> LogLayout | None:
    try:
        summary = read_summary(f, size)
        if summary is None:
            return None
        metadata: dict[str, dict[str, str]] = {}
        for index in summary.metadata_indexes:
            record = read_record_at(f, index.offset, index.length)
            if isinstance(record, Metadata):
                metadata[record.name] = dict(record.metadata)
    except _DAMAGE:
        return None
    f.seek(summary.start)
    digest.update(f.read(size - summary.start))
    chunks = tuple(
        ChunkSpan(c.chunk_start_offset, c.chunk_length, c.message_start_time, c.message_end_time)
        for c in summary.chunk_indexes
    )
    return LogLayout(
        url=name,
        size=size,
        chunks=chunks,
        channels=dict(summary.channels),
        schemas=dict(summary.schemas),
        metadata=metadata,
        complete=True,
        stop_reason=None,
        content_hash=digest.hexdigest(),
    )


def _walk(f: IO[bytes], name: str, size: int, digest: Any, wanted: set[str]) -> LogLayout:
    """The file without a readable summary, through the one record walker
    (:func:`scan.walk_records`: chunk bodies not read, no resync): up to the first record
    that does not fit, or the data-end record (the data is whole, its summary was not)."""
    chunks: list[ChunkSpan] = []
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    metadata: dict[str, dict[str, str]] = {}
    state = ScanState(Path(name), size=size)
    complete = False
    for _offset, rec in walk_records(f, size, state, chunk_bodies=False, resync=False):
        if isinstance(rec, ChunkHead):
            digest.update(struct.pack("<QQ", rec.offset, rec.length - RECORD_HEADER.size))
            digest.update(rec.fields)
            chunks.append(ChunkSpan(rec.offset, rec.length, rec.start_time_ns, rec.end_time_ns))
        elif isinstance(rec, Metadata):
            metadata[rec.name] = dict(rec.metadata)
        elif isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            channels[rec.id] = rec
        elif isinstance(rec, DataEnd | Footer):
            complete = True  # the summary could not be read, the data could
            break
    stop = None if complete else f"{state.stop_reason} at byte {state.good_bytes} of {size}"
    _channels_from_chunks(f, chunks, channels, schemas, wanted)
    return LogLayout(
        url=name,
        size=size,
        chunks=tuple(chunks),
        channels=channels,
        schemas=schemas,
        metadata=metadata,
        complete=complete,
        stop_reason=stop,
        content_hash=digest.hexdigest(),
    )


def _channels_from_chunks(
    f: IO[bytes],
    chunks: list[ChunkSpan],
    channels: dict[int, Channel],
    schemas: dict[int, Schema],
    wanted: set[str],
) -> None:
    for span in chunks:
        if wanted <= {c.topic for c in channels.values()}:
            return
        try:
            records = read_chunk(f, span)
        except ChunkDamagedError:
            continue
        for rec in records:
            if isinstance(rec, Channel):
                channels.setdefault(rec.id, rec)
            elif isinstance(rec, Schema):
                schemas.setdefault(rec.id, rec)


def read_chunk(f: IO[bytes], span: ChunkSpan) -> list[McapRecord]:
    """The records (Schema, Channel, Message) of the chunk at ``span``, CRC checked.

    Raises :class:`ChunkDamagedError` when the bytes there are not an intact chunk.
    """
    f.seek(span.offset)
    data = f.read(span.length)
    if len(data) != span.length or data[0] != Opcode.CHUNK:
        got = f"{len(data)} of {span.length} bytes"
        raise ChunkDamagedError(f"no chunk at byte {span.offset} ({got})")
    try:
        chunk = parse_record(Opcode.CHUNK, data[RECORD_HEADER.size :])
        assert isinstance(chunk, Chunk)
        return breakup_chunk(chunk, validate_crc=True)
    except _DAMAGE as err:
        raise ChunkDamagedError(
            f"damaged chunk at byte {span.offset} ({type(err).__name__}: {err})"
        ) from err


def decode_messages(
    messages: Iterable[tuple[Channel, Message]],
    layout: LogLayout,
    pending: dict[int, dict[str, Any]],
) -> Iterator[LogRecord]:
    """Typed records (:class:`flightlog.LoggedFrame`, ...) of raw messages, through the flight
    log reader's own decoder (:func:`flightlog.read_flight_log`'s). ``pending`` holds the parts
    of frames not complete yet (keyed by sequence); pass the same dict for one stream."""
    for channel, msg in messages:
        schema = layout.schemas.get(channel.schema_id)
        rec = decode_message(channel.topic, schema, msg, layout.metadata, pending)
        if rec is not None:
            yield rec
