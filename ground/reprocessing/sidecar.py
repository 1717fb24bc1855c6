"""The reprocessing results of a flight as a sidecar MCAP, written with mcap's own Writer.

``NAME_reprocess.mcap`` holds only the new topics (``/reprocess/detections``,
``/reprocess/detections/annotations``, ``/reprocess/holes``, ``/reprocess/holes/geojson``)
and a ``ground.reprocess`` metadata record; the flight's log is not copied. Foxglove merges
files opened together into one timeline (open the flight's logs and the sidecar at once),
so the new detections draw over the logged images without a second copy of every image:
a campaign's logs are hundreds of gigabytes, and a copy would double them.

The file is written through the flight log's :class:`~flightlog.McapFile`
(``.NAME_reprocess.part.mcap`` until complete, then renamed into place, replacing the
sidecar of an earlier run).
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import Any

from holescan.flightlog import JSON_SCHEMAS, TOPIC_DETECTIONS, TOPIC_HOLES, McapFile, to_json

__all__ = ["Sidecar"]


class Sidecar:
    """Context manager: ``write(topic, obj, t_unix_ns)`` adds a record (a protobuf message
    or JSON-able data) on ``prefix/topic``; on a clean exit the file is finished and
    renamed into place, on an exception it is removed."""

    def __init__(self, path: Path, prefix: str, metadata: dict[str, str]) -> None:
        self.path = path
        self._prefix = prefix
        self._metadata = metadata
        self._file: McapFile | None = None
        self._seq: dict[str, int] = {}
        self.messages = 0

    def __enter__(self) -> Sidecar:
        self._file = McapFile(self.path, library="holescan reprocess", replace=True)
        return self

    def write(self, topic: str, obj: Any, t_unix_ns: int) -> None:
        full = f"{self._prefix}/{topic}"
        assert self._file is not None
        if hasattr(obj, "SerializeToString"):
            cid = self._file.channel(full, type(obj))
            data = obj.SerializeToString()
        else:
            logged = TOPIC_DETECTIONS if topic.endswith("/detections") else TOPIC_HOLES
            cid = self._file.channel(full, JSON_SCHEMAS[logged])
            data = to_json(obj)
        seq = self._seq.get(full, 0)
        self._seq[full] = seq + 1
        self._file.add_message(cid, t_unix_ns, data, t_unix_ns, seq)
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
        f, self._file = self._file, None
        if f is None:
            return
        if ok:
            f.add_metadata("ground.reprocess", self._metadata)
            f.close()
        else:
            f.abort()
