"""A flight log's chunk index, and reading one chunk by its byte range.

For work split along the chunks of a log (``ground``'s campaign engine): the client reads
only the layout (:func:`read_log_layout`: where each chunk lies, the channels, the
metadata records); each task then opens the log itself and reads its own byte ranges
(:func:`read_chunk`), from a local path or any URL ``fsspec`` opens.

A cleanly closed file gives its layout from its summary section (mcap's indexed reader).
A file without a readable summary (cut off by a crash) is walked record header by record
header up to its last complete record, and its chunks are opened until every channel the
caller needs is known; ``complete`` is then False and ``stop_reason`` says where it ends.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import math
import os
import struct
from collections.abc import Collection, Iterable, Iterator, Mapping
from typing import IO, Any, Final

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from holescan.capture._mcaplog import FlightLogError
from holescan.capture._mcapread import LogRecord, _decode
from holescan.errors import InputError
from holescan.geotag import CameraMount, ErrorModel

__all__ = [
    "ChunkDamagedError",
    "ChunkSpan",
    "LogLayout",
    "decode_messages",
    "mount_from_metadata",
    "open_log",
    "read_chunk",
    "read_log_layout",
]

_MAGIC: Final = b"\x89MCAP0\r\n"
_FOOTER_BYTES: Final = 1 + 8 + 8 + 8 + 4
_CHUNK_HEAD: Final = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, len(name)
_DAMAGE = (McapError, ValueError, struct.error, zstandard.ZstdError, RuntimeError, EOFError)


class ChunkDamagedError(FlightLogError):
    """A chunk's bytes are not a valid chunk (bad CRC, cut short, bad compression)."""


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
        if not head.startswith(_MAGIC):
            raise FlightLogError(f"{name}: not an MCAP file (bad magic)")
        digest = hashlib.blake2b(struct.pack("<Q", size) + head, digest_size=16)
        layout = _from_summary(f, name, size, digest)
        return layout if layout is not None else _walk(f, name, size, digest, set(topics))


def _from_summary(f: IO[bytes], name: str, size: int, digest: Any) -> LogLayout | None:
    if size < len(_MAGIC) * 2 + _FOOTER_BYTES:
        return None
    f.seek(size - len(_MAGIC) - _FOOTER_BYTES)
    tail = f.read(len(_MAGIC) + _FOOTER_BYTES)
    if not tail.endswith(_MAGIC) or tail[0] != Opcode.FOOTER:
        return None
    (summary_start,) = struct.unpack_from("<Q", tail, 9)
    if summary_start == 0 or summary_start >= size:
        return None
    try:
        f.seek(0)
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            return None
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except _DAMAGE:
        return None
    f.seek(summary_start)
    digest.update(f.read(size - summary_start))
    chunks = tuple(
        ChunkSpan(c.chunk_start_offset, c.chunk_length, c.message_start_time, c.message_end_time)
        for c in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
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
    """Record headers from the front; stops at the first record that does not fit."""
    chunks: list[ChunkSpan] = []
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    metadata: dict[str, dict[str, str]] = {}
    pos = len(_MAGIC)
    stop: str | None = "file ends inside a record"
    complete = False
    while True:
        f.seek(pos)
        header = f.read(9)
        if len(header) < 9:
            break
        opcode, length = header[0], struct.unpack_from("<Q", header, 1)[0]
        end = pos + 9 + length
        if end > size:
            break
        if opcode == Opcode.CHUNK:
            head = f.read(min(length, _CHUNK_HEAD.size))
            if len(head) < _CHUNK_HEAD.size:
                break
            start_ns, end_ns, _, _, _ = _CHUNK_HEAD.unpack(head)
            digest.update(struct.pack("<QQ", pos, length) + head)
            chunks.append(ChunkSpan(pos, end - pos, start_ns, end_ns))
        elif opcode in (Opcode.METADATA, Opcode.SCHEMA, Opcode.CHANNEL):
            rec = _parse(opcode, f.read(length))
            if isinstance(rec, Metadata):
                metadata[rec.name] = dict(rec.metadata)
            elif isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
        elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
            stop, complete = None, True  # the summary could not be read, the data could
            break
        pos = end
    if stop is not None:
        stop = f"{stop} at byte {pos} of {size}"
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


def _parse(opcode: int, body: bytes) -> McapRecord | None:
    stream = ReadDataStream(io.BytesIO(body))
    reader = {
        Opcode.METADATA: Metadata.read,
        Opcode.SCHEMA: Schema.read,
        Opcode.CHANNEL: Channel.read,
    }
    with contextlib.suppress(*_DAMAGE):
        rec: McapRecord = reader[Opcode(opcode)](stream)
        return rec
    return None


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
        chunk = Chunk.read(ReadDataStream(io.BytesIO(data[9:])))
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
    """Typed records (:class:`capture.LoggedFrame`, ...) of raw messages, through the flight
    log reader's own decoder (:func:`capture.read_flight_log`'s). ``pending`` holds the parts
    of frames not complete yet (keyed by sequence); pass the same dict for one stream."""
    metadata = {name: dict(values) for name, values in layout.metadata.items()}
    for channel, msg in messages:
        rec = _decode(channel.topic, layout.schemas.get(channel.schema_id), msg, metadata, pending)
        if rec is not None:
            yield rec


def errors_from_metadata(metadata: Mapping[str, Mapping[str, str]]) -> ErrorModel:
    """The sightings' error model of a log: its ``holescan.mount`` record's
    ``attitude_sigma_deg`` (the default model for logs without one). Raises
    :class:`FlightLogError` when the value cannot be read."""
    value = metadata.get("holescan.mount", {}).get("attitude_sigma_deg")
    if value is None:
        return ErrorModel()
    try:
        return ErrorModel(attitude_sigma_rad=math.radians(float(value)))
    except InputError as err:  # a ValueError too: first
        raise FlightLogError(f"holescan.mount {err}") from err
    except ValueError as err:
        raise FlightLogError(f"unreadable holescan.mount attitude_sigma_deg: {value!r}") from err


def mount_from_metadata(metadata: Mapping[str, Mapping[str, str]]) -> CameraMount:
    """The camera mount a log's ``holescan.mount`` metadata record gives (default mount when
    there is none). Raises :class:`FlightLogError` when the record cannot be read."""
    md = metadata.get("holescan.mount")
    if md is None:
        return CameraMount()
    try:
        rot = json.loads(md["rotation_frd_from_camera"])
        offset = tuple(float(v) for v in json.loads(md["offset_frd_m"]))
        rotation = tuple(tuple(float(v) for v in row) for row in rot)
        if len(offset) != 3 or len(rotation) != 3 or any(len(r) != 3 for r in rotation):
            raise ValueError("a 3x3 rotation and a 3-vector offset are expected")
        return CameraMount(rotation, offset)  # type: ignore[arg-type]
    except (KeyError, ValueError, TypeError) as err:
        raise FlightLogError(f"unreadable holescan.mount metadata: {err}") from err
