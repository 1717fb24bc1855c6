"""Write OpenNI ``.oni`` recordings in pure Python, and check them before playback.

The layout follows OpenNI2's own recorder (``Source/Core/OniRecorder.cpp``,
``OniDataRecords.cpp``) and player (``Source/Drivers/OniFile/PlayerNode.cpp``): a 24-byte
file header, then records, all little-endian and packed::

    header   "NI10", version 1.0.1.0, u64 max timestamp (us), u32 max node id
    record   u32 magic "NIR\\0", u32 type, u32 node id, u32 fields size (incl. this
             28-byte header), u32 payload size, u64 undo position; fields; payload

A recording holds two nodes: node 1 ``Depth`` (DEPTH_1_MM, uint16 millimetres) and node 2
``Image`` (RGB888), both uncompressed (codec ``NONE``). Each frame is one NEW_DATA record
per node with the same timestamp (microseconds) and frame id (from 1). A seek table per
node and an END record close the file; the NODE_ADDED records are then patched with the
frame count and timestamp range, as the library's recorder does.

The writer writes to ``.NAME.part.oni`` and renames it to ``NAME`` when closed, so a crash
never leaves a half-written file under the final name; it never replaces an existing file
(``force`` allows it, except over a ``.mcap`` flight log or an input).
"""

from __future__ import annotations

import logging
import os
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from types import TracebackType
from typing import IO

import numpy as np

from holescan.capture.openni.oniformat import (
    FILE_HEADER,
    FILE_MAGIC,
    FILE_VERSION,
    MAX_PAYLOAD,
    NODES,
    SEEK_ENTRY,
    U32_MAX,
    U64_MAX,
    NodeSpec,
    RecordType,
    encode_record,
    node_added_record,
    node_property_records,
)
from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import InputError
from holescan.outputs import PartFile, check_output

__all__ = ["OniWriter", "export_oni", "write_oni"]

_log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- writer


@dataclass
class _NodeState:
    spec: NodeSpec
    added_pos: int = 0
    last_data_pos: int = 0
    seek_table: list[tuple[int, int]] = field(default_factory=list)  # (timestamp us, position)


class OniWriter:
    """Write frames to an ``.oni`` file that OpenNI2 (and NiViewer, RTAB-Map...) can play.

    Use as a context manager; the file appears under ``path`` when the writer is closed,
    also when the ``with`` block ends with an exception (the frames written so far are
    kept). Until then it is ``.STEM.part.oni`` beside it (an :class:`outputs.PartFile`).

    Parameters
    ----------
    path : str or Path
        Output file; must not exist (unless ``force``), never a ``.mcap`` or one of
        ``inputs`` (:func:`outputs.check_output`).
    camera : CameraIntrinsics
        Size and intrinsics of the frames. Stored as the streams' field of view (OpenNI
        keeps nothing else) plus a private property holding fx, fy, cx, cy exactly.
    fps : int
        Nominal frame rate recorded in the video mode.

    Notes
    -----
    ``.oni`` timestamps are whole microseconds: ``Frame.t_sensor_ns`` is floored to us,
    and must not decrease. ``Frame.index`` is not stored; frame ids count from 1.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        camera: CameraIntrinsics,
        fps: int = 30,
        *,
        inputs: Iterable[str | os.PathLike[str]] = (),
        force: bool = False,
    ):
        if not 0 < fps <= 1000:
            raise InputError(f"fps must be in 1..1000, got {fps}")
        if camera.width * camera.height * 3 > MAX_PAYLOAD:
            raise InputError(
                f"{camera.width}x{camera.height} is too large for OpenNI playback (max 1600x1200)"
            )
        self.camera = camera
        self.fps = fps
        self._nodes = [_NodeState(spec) for spec in NODES]
        self._frames = 0
        self._min_ts_us = 0
        self._last_ts_us = -1
        self._out = PartFile(path, inputs=inputs, force=force)
        self.path = self._out.path
        self._partial = self._out.part
        self._file: IO[bytes] | None = self._out.file
        self._pos = 0  # end of the last complete record
        try:
            self._write_preamble()
        except OSError as err:
            self._file = None
            self._out.discard()
            raise InputError(f"cannot write {self._partial}: {err.strerror}") from err

    @property
    def frame_count(self) -> int:
        """Frames written so far."""
        return self._frames

    @property
    def closed(self) -> bool:
        return self._file is None

    def __enter__(self) -> OniWriter:
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
            self._close(raise_on_empty=False)

    def _append(self, *chunks: bytes | memoryview) -> None:
        f = self._require_open()
        for chunk in chunks:
            f.write(chunk)
        self._pos = f.tell()

    def _require_open(self) -> IO[bytes]:
        if self._file is None:
            raise InputError(f"{self.path}: writer is closed")
        return self._file

    def _write_preamble(self) -> None:
        header = FILE_HEADER.pack(FILE_MAGIC, *FILE_VERSION, U64_MAX, len(NODES))
        self._append(header)
        for node in self._nodes:
            node.added_pos = self._pos
            self._append(
                node_added_record(node.spec, U32_MAX, 0, U64_MAX, 0),
                node_property_records(node.spec, self.camera, self.fps),
            )
        for node in self._nodes:
            self._append(
                encode_record(RecordType.NODE_STATE_READY, node.spec.node_id),
                encode_record(
                    RecordType.NODE_DATA_BEGIN,
                    node.spec.node_id,
                    struct.pack("<IQ", U32_MAX, U64_MAX),
                ),
            )

    def write(self, frame: Frame) -> None:
        """Append one frame (a depth and a colour record with the same timestamp).

        Raises
        ------
        InputError
            Wrong image size or dtype, a timestamp earlier than the previous frame's, or the
            writer is closed.
        """
        f = self._require_open()
        h, w = self.camera.height, self.camera.width
        rgb, depth = np.asarray(frame.rgb), np.asarray(frame.depth)
        if rgb.shape != (h, w, 3) or rgb.dtype != np.uint8:
            raise InputError(f"rgb must be ({h}, {w}, 3) uint8, got {rgb.shape} {rgb.dtype}")
        if depth.shape != (h, w) or depth.dtype != np.uint16:
            raise InputError(f"depth must be ({h}, {w}) uint16, got {depth.shape} {depth.dtype}")
        if frame.t_sensor_ns < 0:
            raise InputError(f"t_sensor_ns must be >= 0, got {frame.t_sensor_ns}")
        ts_us = frame.t_sensor_ns // 1000
        if ts_us < self._last_ts_us:
            raise InputError(
                f"frame {frame.index}: t_sensor_ns goes back in time "
                f"({ts_us} us < previous {self._last_ts_us} us)"
            )
        frame_id = self._frames + 1
        payloads = (
            np.ascontiguousarray(depth, dtype="<u2").data.cast("B"),
            np.ascontiguousarray(rgb).data.cast("B"),
        )
        start = pos = self._pos
        positions = []
        try:
            for node, payload in zip(self._nodes, payloads, strict=True):
                head = encode_record(
                    RecordType.NEW_DATA,
                    node.spec.node_id,
                    struct.pack("<QI", ts_us, frame_id),
                    payload_size=payload.nbytes,
                    undo=node.last_data_pos,
                )
                f.write(head)
                f.write(payload)
                positions.append(pos)
                pos += len(head) + payload.nbytes
        except OSError as err:
            # Drop the incomplete frame: the file keeps ending at the last complete one.
            f.seek(start)
            f.truncate()
            raise InputError(f"{self._partial}: write failed: {err.strerror}") from err
        self._pos = pos
        for node, record_pos in zip(self._nodes, positions, strict=True):
            node.last_data_pos = record_pos
            node.seek_table.append((ts_us, record_pos))
        if self._frames == 0:
            self._min_ts_us = ts_us
        self._last_ts_us = ts_us
        self._frames = frame_id

    def close(self) -> None:
        """Write the seek tables and END record, patch the headers, rename into place.

        Raises
        ------
        InputError
            No frame was written (an empty recording cannot be played); the partial file
            is removed.
        """
        self._close(raise_on_empty=True)

    def _close(self, *, raise_on_empty: bool) -> None:
        f = self._file
        if f is None:
            return
        self._file = None
        if self._frames == 0:
            self._out.discard()
            if raise_on_empty:
                raise InputError(f"{self.path}: no frames to write")
            return
        try:
            f.seek(self._pos)
            f.truncate()
            tail_positions = []
            for node in self._nodes:
                f.write(
                    encode_record(RecordType.NODE_REMOVED, node.spec.node_id, undo=node.added_pos)
                )
                tail_positions.append(f.tell())
                table = [SEEK_ENTRY.pack(0, 0, 0)]
                table += [SEEK_ENTRY.pack(ts, 0, pos) for ts, pos in node.seek_table]
                payload = b"".join(table)
                f.write(
                    encode_record(
                        RecordType.SEEK_TABLE, node.spec.node_id, payload_size=len(payload)
                    )
                )
                f.write(payload)
            f.write(encode_record(RecordType.END, 0))
            for node, seek_pos in zip(self._nodes, tail_positions, strict=True):
                f.seek(node.added_pos)
                f.write(
                    node_added_record(
                        node.spec, self._frames, self._min_ts_us, self._last_ts_us, seek_pos
                    )
                )
            f.seek(0)
            f.write(FILE_HEADER.pack(FILE_MAGIC, *FILE_VERSION, self._last_ts_us, len(NODES)))
        except OSError as err:
            self._out.discard()
            raise InputError(
                f"{self._partial}: cannot finish the recording: {err.strerror}"
            ) from err
        self._out.commit()  # flush, fsync, rename (OutputPathError, an InputError, on failure)
        _log.info("wrote %s: %d frames", self.path, self._frames)


def write_oni(
    path: str | os.PathLike[str],
    frames: Iterable[Frame],
    camera: CameraIntrinsics,
    fps: int = 30,
    *,
    inputs: Iterable[str | os.PathLike[str]] = (),
    force: bool = False,
) -> int:
    """Write ``frames`` to the ``.oni`` file ``path``; return how many were written.

    See :class:`OniWriter`. Raises :class:`InputError` on bad frames or no frames at all.
    """
    with OniWriter(path, camera, fps, inputs=inputs, force=force) as writer:
        for frame in frames:
            writer.write(frame)
    return writer.frame_count


def export_oni(
    logs: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    path: str | os.PathLike[str],
    *,
    fps: int = 30,
    force: bool = False,
) -> int:
    """Write the frames of an MCAP flight log to an ``.oni`` file; return how many.

    Parameters
    ----------
    logs : one flight log, or its rotated files in order (``PREFIX_0000.mcap``, ...).
    path : the ``.oni`` file to write (for NiViewer, RTAB-Map, OpenNI tools).
    fps : nominal frame rate stored in the video mode.

    Sensor timestamps that jump back (the Xtion's clock restarts after a USB reset) are
    shifted to continue after the previous frame, by the companion clock's interval.
    """
    from holescan.flightlog.reader import McapSource

    inputs = [logs] if isinstance(logs, str | os.PathLike) else list(logs)
    check_output(path, inputs=inputs, suffixes={".oni"}, force=force)
    source = McapSource(inputs)
    frames = _continuous_sensor_time(source)
    return write_oni(path, frames, source.camera, fps, inputs=inputs, force=force)


def _continuous_sensor_time(frames: Iterable[Frame]) -> Iterator[Frame]:
    offset_ns = 0
    prev: Frame | None = None
    for frame in frames:
        if prev is not None and frame.t_sensor_ns + offset_ns < prev.t_sensor_ns:
            step_ns = max(frame.t_mono_ns - prev.t_mono_ns, 0)
            offset_ns = prev.t_sensor_ns + step_ns - frame.t_sensor_ns
            _log.warning(
                "frame %d: sensor clock went back (sensor reset?); shifted by %d ns",
                frame.index,
                offset_ns,
            )
        out = replace(frame, t_sensor_ns=frame.t_sensor_ns + offset_ns) if offset_ns else frame
        yield out
        prev = out
