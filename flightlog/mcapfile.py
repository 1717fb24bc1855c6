"""One MCAP file being written: the one writer lifecycle of every MCAP file holescan makes.

:class:`McapFile` wraps ``mcap``'s :class:`~mcap.writer.Writer`: it creates the file (never
over an existing one), registers each topic's schema and channel on its first message,
syncs to disk on request, and on close finishes the summary, fsyncs and closes. An output
written ``via_part`` (the default) goes through the output-path rule (an
:class:`outputs.PartFile`): checked, ``.STEM.part.mcap`` until it is complete, fsynced and
renamed into place; a failure removes it. The flight
log's own files are written in place instead: while the flight goes on, the file is the
record, and a crash leaves it readable up to its last chunk (``recover_log`` repairs it).

Used by the flight log writer (each ``PREFIX_NNNN.mcap``), by ``recover_log`` and by the
ground station's reprocessing sidecar.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import mcap
from mcap.records import Attachment, Channel, Schema
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import Writer
from mcap_protobuf.schema import build_file_descriptor_set

from holescan.flightlog.errors import FlightLogError
from holescan.flightlog.format import compression_type
from holescan.flightlog.schemas import to_json
from holescan.outputs import PartFile

__all__ = ["JsonSchema", "McapFile", "mcap_version"]

JsonSchema = tuple[str, Mapping[str, Any]]
"""A JSON schema as a channel takes it: (schema name, the schema)."""


def mcap_version() -> str:
    """The version of the ``mcap`` library writing the files."""
    return str(getattr(mcap.writer, "__version__", "unknown"))


class McapFile:
    """An MCAP file open for writing; a context manager (a clean exit closes and keeps
    the file, an exception discards a ``.part`` output).

    Parameters
    ----------
    path : the file to write; it must not exist (in place: :class:`FlightLogError`;
        ``via_part``: :class:`outputs.OutputPathError`, as :func:`outputs.check_output`).
    library, profile : the Header record's fields.
    compression : ``"zstd"``, ``"lz4"`` or ``"none"`` (also a chunk's ``""``).
    chunk_size : bytes of messages per chunk.
    via_part : write ``.STEM.part.mcap`` and rename it to ``path`` when closed.
    replace : with ``via_part``, replace an existing ``path`` on close (an output this
        program wrote before and writes again); otherwise an existing one is refused.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        library: str,
        profile: str = "",
        compression: str = "zstd",
        chunk_size: int = 1 << 20,
        via_part: bool = True,
        replace: bool = False,
    ) -> None:
        self.path = Path(path)
        self._part: PartFile | None = None
        if via_part:
            self._part = PartFile(self.path, replace=replace)
            self._stream: IO[bytes] | None = self._part.file
        else:
            try:
                self._stream = open(self.path, "xb")  # noqa: SIM115
            except FileExistsError as err:
                raise FlightLogError(f"{self.path} exists: choose another log name") from err
            except OSError as err:
                raise FlightLogError(f"cannot create {self.path}: {err.strerror}") from err
        self._writer = Writer(
            self._stream,
            chunk_size=chunk_size,
            compression=compression_type(compression),
            enable_data_crcs=True,
        )
        self._writer.start(profile=profile, library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}

    def __enter__(self) -> McapFile:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    @property
    def closed(self) -> bool:
        return self._stream is None

    @property
    def bytes_written(self) -> int:
        """Bytes in the file so far (the open chunk not counted)."""
        stream = self._stream  # read once: another thread may close the file
        return 0 if stream is None else stream.tell()

    # ------------------------------------------------------------------ channels

    def channel(self, topic: str, schema: type[Any] | JsonSchema) -> int:
        """The channel id of ``topic``, registered on first use with its schema: a protobuf
        message class (its file descriptor set, registered once per message type) or a
        JSON schema ``(name, schema)``."""
        cid = self._channels.get(topic)
        if cid is not None:
            return cid
        if isinstance(schema, tuple):
            name, json_schema = schema
            sid = self._schema(name, SchemaEncoding.JSONSchema, lambda: to_json(json_schema))
            encoding = MessageEncoding.JSON
        else:
            name = schema.DESCRIPTOR.full_name
            fds = lambda: build_file_descriptor_set(schema).SerializeToString()  # noqa: E731
            sid = self._schema(name, SchemaEncoding.Protobuf, fds)
            encoding = MessageEncoding.Protobuf
        cid = self._writer.register_channel(topic, encoding, sid)
        self._channels[topic] = cid
        return cid

    def _schema(self, name: str, encoding: str, data: Callable[[], bytes]) -> int:
        sid = self._schemas.get(name)
        if sid is None:
            sid = self._writer.register_schema(name, encoding, data())
            self._schemas[name] = sid
        return sid

    def copy_schema(self, schema: Schema) -> int:
        """Register a schema record read from another file; returns its id in this one."""
        sid: int = self._writer.register_schema(schema.name, schema.encoding, schema.data)
        return sid

    def copy_channel(self, channel: Channel, schema_id: int) -> int:
        """Register a channel record read from another file, on this file's ``schema_id``
        (0: no schema); returns its id in this one."""
        cid: int = self._writer.register_channel(
            channel.topic, channel.message_encoding, schema_id, dict(channel.metadata)
        )
        return cid

    # ------------------------------------------------------------------ records

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int
    ) -> None:
        self._writer.add_message(channel_id, log_time, data, publish_time, sequence)

    def add_metadata(self, name: str, values: Mapping[str, str]) -> None:
        self._writer.add_metadata(name, dict(values))

    def add_attachment(self, attachment: Attachment) -> None:
        a = attachment
        self._writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)

    # ------------------------------------------------------------------ lifecycle

    def sync(self) -> None:
        """Write out the open chunk and fsync: what a power loss can no longer take."""
        assert self._stream is not None
        self._writer.flush()  # type: ignore[no-untyped-call]
        os.fsync(self._stream.fileno())

    def close(self) -> None:
        """Finish the file (summary, indexes), fsync, close, and rename a ``.part`` into
        place. On an error (disk full...) a ``.part`` is removed and the error raised (an
        ``OSError`` of the writer as it is, :class:`OutputPathError` from the rename).
        Idempotent."""
        stream, self._stream = self._stream, None
        if stream is None:
            return
        if self._part is not None:
            try:
                self._writer.finish()  # type: ignore[no-untyped-call]
            except BaseException:
                self._part.discard()
                raise
            self._part.commit()
            return
        try:
            self._writer.finish()  # type: ignore[no-untyped-call]
            stream.flush()
            os.fsync(stream.fileno())
        finally:
            stream.close()

    def abort(self) -> None:
        """Close without finishing: a ``.part`` output is removed; a file written in place
        is left as it is (readable up to its last chunk). Idempotent."""
        stream, self._stream = self._stream, None
        if stream is None:
            return
        if self._part is not None:
            self._part.discard()
        else:
            stream.close()
