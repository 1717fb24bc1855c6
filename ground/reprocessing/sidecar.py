"""The reprocessing results of a flight as a sidecar MCAP, written with mcap's own Writer.

``NAME_reprocess.mcap`` holds only the new topics (``/reprocess/detections``,
``/reprocess/detections/annotations``, ``/reprocess/holes``, ``/reprocess/holes/geojson``)
and a ``ground.reprocess`` metadata record; the flight's log is not copied. Foxglove merges
files opened together into one timeline (open the flight's logs and the sidecar at once),
so the new detections draw over the logged images without a second copy of every image:
a campaign's logs are hundreds of gigabytes, and a copy would double them.

The file is written as ``.NAME_reprocess.mcap.part`` and renamed when complete.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_protobuf.schema import build_file_descriptor_set

from holescan.capture import JSON_SCHEMAS, TOPIC_DETECTIONS, TOPIC_HOLES, to_json

__all__ = ["Sidecar"]


class Sidecar:
    """Context manager: ``write(topic, obj, t_unix_ns)`` adds a record (a protobuf message
    or JSON-able data) on ``prefix/topic``; on a clean exit the file is finished and
    renamed into place, on an exception it is removed."""

    def __init__(self, path: Path, prefix: str, metadata: dict[str, str]) -> None:
        self.path = path
        self._tmp = path.with_name(f".{path.name}.part")
        self._prefix = prefix
        self._metadata = metadata
        self._stream: IO[bytes] | None = None
        self._writer: McapWriter | None = None
        self._channels: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self.messages = 0

    def __enter__(self) -> Sidecar:
        self._stream = open(self._tmp, "wb")
        self._writer = McapWriter(
            self._stream, compression=CompressionType.ZSTD, enable_data_crcs=True
        )
        self._writer.start(profile="", library="holescan reprocess")
        return self

    def _channel(self, topic: str, obj: Any) -> int:
        cid = self._channels.get(topic)
        if cid is not None:
            return cid
        assert self._writer is not None
        if hasattr(obj, "SerializeToString"):
            fds = build_file_descriptor_set(type(obj)).SerializeToString()
            sid = self._writer.register_schema(
                obj.DESCRIPTOR.full_name, SchemaEncoding.Protobuf, fds
            )
            encoding = MessageEncoding.Protobuf
        else:
            logged = TOPIC_DETECTIONS if topic.endswith("/detections") else TOPIC_HOLES
            name, schema = JSON_SCHEMAS[logged]
            sid = self._writer.register_schema(name, SchemaEncoding.JSONSchema, to_json(schema))
            encoding = MessageEncoding.JSON
        cid = self._writer.register_channel(topic, encoding, sid)
        self._channels[topic] = cid
        return cid

    def write(self, topic: str, obj: Any, t_unix_ns: int) -> None:
        full = f"{self._prefix}/{topic}"
        cid = self._channel(full, obj)
        data = obj.SerializeToString() if hasattr(obj, "SerializeToString") else to_json(obj)
        seq = self._seq.get(full, 0)
        self._seq[full] = seq + 1
        assert self._writer is not None
        self._writer.add_message(
            cid, log_time=t_unix_ns, data=data, publish_time=t_unix_ns, sequence=seq
        )
        self.messages += 1

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close(ok=exc_type is None)

    def close(self, ok: bool) -> None:
        """Finish and rename into place (``ok``), or remove the partial file. Idempotent."""
        if self._writer is None or self._stream is None:
            return
        writer, stream = self._writer, self._stream
        self._writer = self._stream = None
        try:
            if ok:
                writer.add_metadata("ground.reprocess", self._metadata)
                writer.finish()  # type: ignore[no-untyped-call]
                stream.flush()
                os.fsync(stream.fileno())
        finally:
            stream.close()
        if ok:
            os.replace(self._tmp, self.path)
        else:
            self._tmp.unlink(missing_ok=True)
