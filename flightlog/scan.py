"""A front-to-back MCAP scanner that survives damage: the record layer of flight-log reading.

Every length field is checked against the bytes left in the file before anything is
allocated; every chunk is decompressed with a bound and its CRC checked. A damaged chunk
costs that chunk only: it is skipped and reported (:class:`DamagedRegion`: offset, time
range, messages lost from the message indexes that follow it), and reading goes on. When a
record header itself is damaged (a corrupt length or opcode), the scanner resyncs on the
next chunk: from the summary's chunk index when the file has an intact summary, else by
scanning for a chunk opcode followed by plausible lengths and a valid CRC. Schemas and
channels lost with a damaged chunk are taken from the summary, when there is one.

Why not ``mcap``'s :class:`~mcap.stream_reader.StreamReader` for the top level: it stops at
the first record that does not parse (mcap's own ``recover`` stopped at the first bad
chunk: foxglove/mcap#1390), trusts a record's length (a corrupt one allocates gigabytes or
swallows the rest of the file) and does not say where in the file a record lies, which
the resync, the damage report and ``recover_log`` need. So the record framing is walked
here; each record that fits is parsed by mcap's readers (:func:`format.parse_record`), the
summary section by the StreamReader (:func:`format.read_summary`), and a chunk's content,
once decompressed within bounds and its CRC checked, by mcap's
:func:`~mcap.stream_reader.breakup_chunk`.
"""

from __future__ import annotations

import dataclasses
import io
import os
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import zstandard
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    DataEnd,
    Footer,
    McapRecord,
    Message,
    MessageIndex,
    Schema,
)
from mcap.stream_reader import breakup_chunk

from holescan.flightlog.errors import FlightLogError, RecordError
from holescan.flightlog.format import (
    CHUNK_FIELDS,
    CHUNK_MIN_BYTES,
    KNOWN_OPCODES,
    MAGIC,
    RECORD_HEADER,
    Summary,
    parse_record,
    read_summary,
)
from holescan.utc import utc_text

__all__ = ["ChunkHead", "DamagedRegion", "ScanState", "scan_records", "walk_records"]

#: Records other than chunks and attachments are small; a longer one is a corrupt length.
_SMALL_RECORD_LIMIT = 64 << 20
#: A chunk never decompresses to more than this (the writer's chunks are ~1 MiB).
_CHUNK_LIMIT = 1 << 30
_SCAN_BLOCK = 8 << 20
_DATA_CRC = "data section CRC mismatch"
_HEAD = RECORD_HEADER.size
_DATA_END_HEADER = RECORD_HEADER.pack(Opcode.DATA_END, 4)  # its body: the data CRC


@dataclasses.dataclass(frozen=True)
class DamagedRegion:
    """Bytes of a log that could not be read (a damaged chunk, or garbage skipped to resync).

    offset, length : where in the file (bytes). t_start_ns, t_end_ns : log time range of
    the messages lost (Unix ns; None when unknown). messages : how many were lost (from the
    chunk's message indexes; None when unknown).
    """

    offset: int
    length: int
    reason: str
    t_start_ns: int | None = None
    t_end_ns: int | None = None
    messages: int | None = None

    def describe(self) -> str:
        if self.reason == _DATA_CRC:
            return (
                f"data section CRC mismatch (bytes {self.offset}-{self.offset + self.length}): "
                "a record outside the chunks is damaged; every chunk checked out"
            )
        lost = "an unknown number of" if self.messages is None else str(self.messages)
        when = ""
        if self.t_start_ns is not None and self.t_end_ns is not None:
            when = f", log time {_utc(self.t_start_ns)} to {_utc(self.t_end_ns)}"
        return (
            f"bytes {self.offset}-{self.offset + self.length} skipped ({self.reason}{when}): "
            f"{lost} messages lost"
        )


def _utc(t_unix_ns: int) -> str:
    try:
        return utc_text(t_unix_ns)
    except ValueError:
        return f"{t_unix_ns} ns"


@dataclasses.dataclass
class ScanState:
    """What a front-to-back scan of one file found (filled while iterating).

    complete : the footer and the closing magic were read. good_bytes : end of the last
    intact top-level record yielded; record_start : where that record began. damaged :
    regions skipped (the scan went on after them). stop_reason : why the scan ended before
    the footer (None when complete).
    """

    path: Path
    size: int = 0
    complete: bool = False
    good_bytes: int = 0
    record_start: int = 0
    stop_reason: str | None = None
    chunks: int = 0
    damaged: list[DamagedRegion] = dataclasses.field(default_factory=list)
    orphan_messages: int = 0  # messages whose channel record was lost

    @property
    def messages_lost(self) -> int:
        return sum(d.messages or 0 for d in self.damaged) + self.orphan_messages

    def describe_stop(self) -> str:
        """One line: why the file is not whole, and what to do."""
        parts = [d.describe() for d in self.damaged]
        if self.orphan_messages:
            parts.append(f"{self.orphan_messages} messages on channels lost with a chunk")
        if self.stop_reason is not None:
            parts.append(f"{self.stop_reason} at byte {self.good_bytes} of {self.size}")
        return f"{self.path}: {'; '.join(parts)}; run `holescan log recover {self.path}`"

    @property
    def whole(self) -> bool:
        """Complete and nothing skipped."""
        return self.complete and not self.damaged and not self.orphan_messages


def _open(path: str | os.PathLike[str]) -> tuple[IO[bytes], int]:
    p = Path(path)
    try:
        f = open(p, "rb")  # noqa: SIM115 (the caller closes it)
    except FileNotFoundError as err:
        raise FlightLogError(f"{p}: no such file") from err
    except IsADirectoryError as err:
        raise FlightLogError(f"{p}: is a folder, not an MCAP flight log") from err
    except OSError as err:
        raise FlightLogError(f"{p}: cannot read: {err.strerror}") from err
    size = os.fstat(f.fileno()).st_size
    if size == 0:
        f.close()
        raise FlightLogError(f"{p}: empty file, not an MCAP flight log")
    return f, size


def _decompress(chunk: Chunk) -> bytes:
    if chunk.uncompressed_size > _CHUNK_LIMIT:
        raise RecordError(f"chunk claims {chunk.uncompressed_size} bytes uncompressed")
    if chunk.compression == "zstd":
        try:
            reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data))
            data = reader.read(chunk.uncompressed_size + 1)
            while len(data) <= chunk.uncompressed_size:
                more = reader.read(chunk.uncompressed_size + 1 - len(data))
                if not more:
                    break
                data += more
        except zstandard.ZstdError as err:
            raise RecordError(f"zstd: {err}") from err
    elif chunk.compression == "lz4":
        import lz4.frame  # type: ignore[import-not-found,unused-ignore]

        try:
            dec = lz4.frame.LZ4FrameDecompressor()
            data = dec.decompress(chunk.data, max_length=chunk.uncompressed_size + 1)
        except RuntimeError as err:
            raise RecordError(f"lz4: {err}") from err
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise RecordError(f"unknown chunk compression {chunk.compression[:20]!r}")
    if len(data) != chunk.uncompressed_size:
        raise RecordError(f"chunk decompresses to {len(data)} bytes, not {chunk.uncompressed_size}")
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        raise RecordError("chunk CRC mismatch")
    return bytes(data)


def _chunk_content(chunk: Chunk) -> list[McapRecord]:
    """Schema, Channel and Message records of a chunk, decompressed within bounds and its
    CRC checked here (mcap's decompression trusts the sizes), parsed by mcap."""
    data = _decompress(chunk)
    plain = dataclasses.replace(chunk, compression="", data=data)
    try:
        return breakup_chunk(plain, validate_crc=False)  # the CRC was checked above
    except Exception as err:  # the content of a chunk without a CRC, damaged
        raise RecordError(f"chunk content does not parse ({type(err).__name__}: {err})") from err


def _plausible_chunk_at(f: IO[bytes], at: int, size: int) -> bool:
    """A chunk record header at ``at`` whose lengths add up (where a resync may restart)."""
    f.seek(at)
    head = f.read(_HEAD + CHUNK_MIN_BYTES)
    if len(head) < _HEAD + CHUNK_MIN_BYTES or head[0] != Opcode.CHUNK:
        return False
    _opcode, length = RECORD_HEADER.unpack_from(head)
    if not CHUNK_MIN_BYTES <= length <= size - at - _HEAD:
        return False
    _t0, _t1, usize, _crc, clen = CHUNK_FIELDS.unpack_from(head, _HEAD)
    if usize > _CHUNK_LIMIT or clen > 16:
        return False
    f.seek(at + _HEAD + CHUNK_FIELDS.size)
    tail = f.read(clen + 8)
    if len(tail) < clen + 8:
        return False
    (dlen,) = struct.unpack_from("<Q", tail, clen)
    return bool(CHUNK_FIELDS.size + clen + 8 + dlen == length)


def _resync(f: IO[bytes], start: int, size: int, summary: Summary | None) -> int | None:
    """The offset of the next record that looks intact at or after ``start``."""
    if summary is not None:
        for index in summary.chunk_indexes:
            if index.chunk_start_offset >= start:
                return index.chunk_start_offset
        return None  # nothing indexed after here: the summary itself follows
    pos = start
    while pos < size - _HEAD:
        f.seek(pos)
        block = f.read(_SCAN_BLOCK + _HEAD)
        i = 0
        while True:
            i = block.find(bytes([Opcode.CHUNK]), i)
            if i < 0 or i >= _SCAN_BLOCK:
                break
            if _plausible_chunk_at(f, pos + i, size):
                return pos + i
            i += 1
        i = block.find(_DATA_END_HEADER)
        if 0 <= i < _SCAN_BLOCK:
            return pos + i
        pos += _SCAN_BLOCK
    return None


def scan_records(path: str | os.PathLike[str], state: ScanState | None = None) -> Iterator[Any]:
    """Yield every intact record of ``path`` in file order, chunks followed by their
    content (Schema, Channel, Message records), every CRC checked.

    A damaged chunk or unreadable bytes are skipped and added to ``state.damaged``; the
    scan goes on with the next intact record. The scan ends at the footer
    (``state.complete``) or where the file is cut off (``state.stop_reason``). A message
    whose channel record was lost is preceded by the summary's copy of its schema and
    channel, or dropped (``state.orphan_messages``) when the file has no summary.

    Raises
    ------
    FlightLogError : the file is missing, empty or not MCAP at all.
    """
    st = state if state is not None else ScanState(Path(path))
    f, size = _open(path)
    st.path, st.size = Path(path), size
    with f:
        if f.read(len(MAGIC)) != MAGIC:
            raise FlightLogError(f"{st.path}: not an MCAP file (bad magic)")
        summary = read_summary(f, size)
        for _offset, rec in walk_records(f, size, st, summary=summary):
            yield rec


@dataclasses.dataclass(frozen=True)
class ChunkHead:
    """A chunk seen by :func:`walk_records` without reading its body: the record's bytes
    ``[offset, offset + length)``, its messages' log times (Unix ns) and ``fields``, the
    raw bytes of its fixed fields (times, sizes, CRC: what identifies its content)."""

    offset: int
    length: int
    start_time_ns: int
    end_time_ns: int
    fields: bytes


#: Records :func:`walk_records` parses when it does not read chunk bodies.
_HEAD_ONLY_PARSED = frozenset(
    {Opcode.HEADER, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA, Opcode.DATA_END, Opcode.FOOTER}
)


def walk_records(
    f: IO[bytes],
    size: int,
    st: ScanState,
    *,
    summary: Summary | None = None,
    chunk_bodies: bool = True,
    resync: bool = True,
) -> Iterator[tuple[int, Any]]:
    """The one MCAP record walker: ``(offset, record)`` of every intact record of the open
    file ``f`` (``size`` bytes, its magic already checked), front to back, filling ``st``.

    Every record's length is checked against the bytes left before anything is read.
    ``chunk_bodies`` : decompress each chunk (bounded, CRC checked; a damaged chunk is
    skipped and reported) and yield its content after it (offset of the chunk); False:
    yield a :class:`ChunkHead` instead, reading only its fixed fields (a log's layout,
    from a URL too), and parse only the header, schema, channel, metadata, data-end and
    footer records. ``resync`` : after a damaged record header, go on at the next intact
    record (from ``summary``'s chunk index, else by scanning); False: stop there (a record
    whose frame holds but whose body does not parse is then skipped alone).
    """
    pos = st.good_bytes = len(MAGIC)
    crc: int | None = zlib.crc32(MAGIC) if chunk_bodies else None
    seen_schemas: set[int] = set()
    seen_channels: set[int] = set()
    lost: DamagedRegion | None = None  # the damaged chunk whose indexes may follow
    while True:
        f.seek(pos)
        head = f.read(_HEAD)
        if len(head) < _HEAD:
            st.stop_reason = "file ends inside a record" if head else "file ends (no footer)"
            return
        opcode, length = RECORD_HEADER.unpack(head)
        limit = size - pos - _HEAD
        why = None
        if opcode not in KNOWN_OPCODES:
            why = f"unknown record type 0x{opcode:02x}"
        elif length > limit:
            why = f"record length {length} runs past the end of the file"
        elif length > _SMALL_RECORD_LIMIT and opcode not in (Opcode.CHUNK, Opcode.ATTACHMENT):
            why = f"{Opcode(opcode).name.lower()} record length {length} is implausible"
        rec: Any = None
        content: list[McapRecord] = []
        body = b""
        if why is None and not chunk_bodies and opcode == Opcode.CHUNK:
            fields = f.read(min(length, CHUNK_FIELDS.size))
            if len(fields) < CHUNK_FIELDS.size:
                why = f"chunk record length {length} is too short"
            else:
                t0, t1, _, _, _ = CHUNK_FIELDS.unpack(fields)
                rec = ChunkHead(pos, _HEAD + length, t0, t1, fields)
        elif why is None and (chunk_bodies or opcode in _HEAD_ONLY_PARSED):
            body = f.read(length)
            try:
                rec = parse_record(opcode, body)
                content = _chunk_content(rec) if isinstance(rec, Chunk) else []
            except RecordError as err:
                if isinstance(rec, Chunk) or not resync:  # the frame held: skip just it
                    lost = DamagedRegion(
                        pos, _HEAD + length, str(err),
                        rec.message_start_time if isinstance(rec, Chunk) else None,
                        rec.message_end_time if isinstance(rec, Chunk) else None,
                        None if isinstance(rec, Chunk) else 0,
                    )  # fmt: skip
                    st.damaged.append(lost)
                    crc = None
                    pos += _HEAD + length
                    continue
                why = str(err)
        if why is not None:
            nxt = _resync(f, pos + 1, size, summary) if resync else None
            if nxt is None:
                if length > limit:
                    st.stop_reason = "file ends inside a record"
                else:
                    st.stop_reason = f"damaged record ({why})"
                return
            lost = DamagedRegion(pos, nxt - pos, why)
            st.damaged.append(lost)
            crc = None
            pos = nxt
            continue
        if isinstance(rec, MessageIndex) and lost is not None:
            lost = dataclasses.replace(lost, messages=(lost.messages or 0) + len(rec.records))
            st.damaged[-1] = lost
            pos += _HEAD + length
            continue  # the index of a chunk not yielded
        lost = None
        if isinstance(rec, DataEnd) and crc is not None and rec.data_section_crc not in (0, crc):
            st.damaged.append(DamagedRegion(len(MAGIC), pos - len(MAGIC), _DATA_CRC, messages=0))
        if crc is not None:
            crc = zlib.crc32(head + body, crc)
        st.record_start, st.good_bytes = pos, pos + _HEAD + length
        record_at = pos
        pos = st.good_bytes
        if rec is None:
            continue
        if isinstance(rec, (Chunk, ChunkHead)):
            st.chunks += 1
        for item in (rec, *content):
            if isinstance(item, Message) and item.channel_id not in seen_channels:
                restored = _restore_channel(item.channel_id, summary, seen_schemas)
                if not restored:
                    st.orphan_messages += 1
                    continue
                seen_channels.add(item.channel_id)
                for r in restored:
                    yield record_at, r
            yield record_at, item
            if isinstance(item, Schema):
                seen_schemas.add(item.id)
            elif isinstance(item, Channel):
                seen_channels.add(item.id)
        if isinstance(rec, Footer):
            f.seek(pos)
            if f.read(len(MAGIC)) != MAGIC:
                st.stop_reason = "no closing magic after the footer"
                return
            st.complete = True
            st.good_bytes = size
            return


def _restore_channel(
    channel_id: int, summary: Summary | None, seen_schemas: set[int]
) -> list[Schema | Channel]:
    if summary is None or channel_id not in summary.channels:
        return []
    channel = summary.channels[channel_id]
    out: list[Schema | Channel] = []
    if channel.schema_id and channel.schema_id not in seen_schemas:
        schema = summary.schemas.get(channel.schema_id)
        if schema is None:
            return []
        seen_schemas.add(schema.id)
        out.append(schema)
    out.append(channel)
    return out
