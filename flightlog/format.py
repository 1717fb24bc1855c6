"""The MCAP file format, written down once: magic, record framing, footer, chunk fields,
summary section, compression names.

What the flight log's readers and writers share about the bytes of an MCAP file
(https://mcap.dev/spec). The well-formed parts are read with ``mcap``'s own parsers (record
readers, :class:`mcap.stream_reader.StreamReader` for the summary section); this module adds
only the checks a damaged or cut-off file needs first: every length is compared with the
bytes there are before anything is read or allocated.

    file     magic, Header, data records ..., DataEnd, summary records ..., Footer, magic
    record   u8 opcode, u64 length of the body, body
    footer   u64 summary start, u64 summary offsets start, u32 CRC of the summary section
             up to and including the footer's own first 25 bytes
"""

from __future__ import annotations

import dataclasses
import io
import struct
import zlib
from collections.abc import Callable, Mapping
from typing import IO, Any, Final

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType

from holescan.flightlog.errors import RecordError

__all__ = [
    "CHUNK_FIELDS",
    "CHUNK_MIN_BYTES",
    "COMPRESSION",
    "FOOTER_BYTES",
    "KNOWN_OPCODES",
    "MAGIC",
    "MESSAGE_MIN_BYTES",
    "RECORD_HEADER",
    "Summary",
    "compression_type",
    "parse_record",
    "read_footer",
    "read_record_at",
    "read_summary",
    "summary_crc_ok",
]

MAGIC: Final = b"\x89MCAP0\r\n"
RECORD_HEADER: Final = struct.Struct("<BQ")  # opcode, length of the body
#: The footer record with its header: opcode, length, summary start, offsets start, CRC.
FOOTER_BYTES: Final = RECORD_HEADER.size + 8 + 8 + 4
#: A chunk body's fixed fields: message start/end time, uncompressed size, uncompressed
#: CRC, length of the compression name (the name and the compressed data follow).
CHUNK_FIELDS: Final = struct.Struct("<QQQII")
#: The shortest chunk body: its fixed fields, an empty compression name, the data length.
CHUNK_MIN_BYTES: Final = CHUNK_FIELDS.size + 8
#: The shortest message body: channel id, sequence, log time, publish time.
MESSAGE_MIN_BYTES: Final = 2 + 4 + 8 + 8

#: What the flight log's settings call each chunk compression.
COMPRESSION: Final[Mapping[str, CompressionType]] = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}

_READERS: Final[Mapping[int, Callable[[ReadDataStream], Any]]] = {
    Opcode.ATTACHMENT: Attachment.read,
    Opcode.ATTACHMENT_INDEX: AttachmentIndex.read,
    Opcode.CHANNEL: Channel.read,
    Opcode.CHUNK: Chunk.read,
    Opcode.CHUNK_INDEX: ChunkIndex.read,
    Opcode.DATA_END: DataEnd.read,
    Opcode.FOOTER: Footer.read,
    Opcode.HEADER: Header.read,
    Opcode.MESSAGE_INDEX: MessageIndex.read,
    Opcode.METADATA: Metadata.read,
    Opcode.METADATA_INDEX: MetadataIndex.read,
    Opcode.SCHEMA: Schema.read,
    Opcode.STATISTICS: Statistics.read,
    Opcode.SUMMARY_OFFSET: SummaryOffset.read,
}
#: Every opcode the spec defines (a record of another opcode is skipped, as it says).
KNOWN_OPCODES: Final = frozenset({*_READERS, Opcode.MESSAGE})


def compression_type(name: str) -> CompressionType:
    """The writer's :class:`CompressionType` of a chunk's compression field or a setting
    (``"zstd"``, ``"lz4"``; ``""``, ``"none"`` or anything else: no compression)."""
    return COMPRESSION.get(name, CompressionType.NONE)


def parse_record(opcode: int, body: bytes) -> McapRecord | None:
    """The record of ``opcode`` from exactly its ``body`` bytes, with mcap's record readers.

    Inner lengths cannot run past ``body``. Returns None for an opcode the spec does not
    define (skipped, as the spec says). Raises :class:`RecordError` when the bytes do not
    parse.
    """
    stream = ReadDataStream(io.BytesIO(body))
    try:
        if opcode == Opcode.MESSAGE:
            if len(body) < MESSAGE_MIN_BYTES:
                raise RecordError("message record too short")
            message: McapRecord = Message.read(stream, len(body))
            return message
        reader = _READERS.get(opcode)
        if reader is None:
            return None
        record: McapRecord = reader(stream)
    except RecordError:
        raise
    except Exception as err:  # a parse error of damaged bytes, whatever the library raises
        raise RecordError(f"{Opcode(opcode).name.lower()} record does not parse ({err})") from err
    return record


def read_record_at(f: IO[bytes], offset: int, length: int) -> McapRecord | None:
    """The record of ``length`` bytes (its header included) at byte ``offset``, where a
    summary index points. Raises :class:`RecordError` when the bytes there are not one."""
    f.seek(offset)
    raw = f.read(length)
    if len(raw) < RECORD_HEADER.size:
        raise RecordError(f"no record at byte {offset}")
    opcode, body_length = RECORD_HEADER.unpack_from(raw)
    if body_length != len(raw) - RECORD_HEADER.size:
        raise RecordError(f"the record at byte {offset} is not {length} bytes long")
    return parse_record(opcode, raw[RECORD_HEADER.size :])


def read_footer(f: IO[bytes], size: int) -> Footer | None:
    """The footer of a file of ``size`` bytes when its tail is intact (closing magic,
    footer opcode and length), else None (a file cut off by a crash)."""
    if size < len(MAGIC) * 2 + FOOTER_BYTES:
        return None
    f.seek(size - len(MAGIC) - FOOTER_BYTES)
    tail = f.read(FOOTER_BYTES + len(MAGIC))
    if len(tail) != FOOTER_BYTES + len(MAGIC) or tail[-len(MAGIC) :] != MAGIC:
        return None
    opcode, length = RECORD_HEADER.unpack_from(tail, 0)
    if opcode != Opcode.FOOTER or length != FOOTER_BYTES - RECORD_HEADER.size:
        return None
    record = parse_record(opcode, tail[RECORD_HEADER.size : FOOTER_BYTES])
    assert isinstance(record, Footer)
    return record


def summary_crc_ok(f: IO[bytes], footer: Footer, size: int) -> bool:
    """The footer's summary CRC matches the bytes (True when there is no summary or the
    writer left the CRC out)."""
    if footer.summary_start == 0 or footer.summary_crc == 0:
        return True
    end = size - len(MAGIC) - 4  # up to the footer's CRC field
    if not 0 < footer.summary_start <= end:
        return False
    f.seek(footer.summary_start)
    return zlib.crc32(f.read(end - footer.summary_start)) == footer.summary_crc


@dataclasses.dataclass(frozen=True)
class Summary:
    """What an intact summary section says.

    start : byte offset of the summary section (where the data section ends).
    chunk_indexes : in file order. statistics : None when the writer wrote none.
    """

    footer: Footer
    start: int
    schemas: Mapping[int, Schema]
    channels: Mapping[int, Channel]
    chunk_indexes: tuple[ChunkIndex, ...]
    metadata_indexes: tuple[MetadataIndex, ...]
    statistics: Statistics | None


def read_summary(f: IO[bytes], size: int) -> Summary | None:
    """The summary section of a cleanly closed file of ``size`` bytes, its CRC checked.

    None when the file has no intact footer, no summary, a summary whose CRC does not match
    or one that does not parse: the caller then reads the file front to back.
    """
    footer = read_footer(f, size)
    if footer is None or footer.summary_start == 0:
        return None
    start = footer.summary_start
    if not len(MAGIC) < start <= size - len(MAGIC) - FOOTER_BYTES:
        return None
    if not summary_crc_ok(f, footer, size):
        return None
    f.seek(start)
    section = f.read(size - start)  # the summary records, the footer, the closing magic
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    chunks: list[ChunkIndex] = []
    metadata: list[MetadataIndex] = []
    statistics: Statistics | None = None
    reader = StreamReader(io.BytesIO(section), skip_magic=True, record_size_limit=len(section))
    try:
        for record in reader.records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, ChunkIndex):
                if len(MAGIC) <= record.chunk_start_offset < start:
                    chunks.append(record)
            elif isinstance(record, MetadataIndex):
                metadata.append(record)
            elif isinstance(record, Statistics):
                statistics = record
    except Exception:  # damaged bytes, whatever the library raises: no usable summary
        return None
    chunks.sort(key=lambda c: c.chunk_start_offset)
    return Summary(footer, start, schemas, channels, tuple(chunks), tuple(metadata), statistics)
