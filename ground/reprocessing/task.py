"""One partition task, run on a Dask worker: read my chunks, detect, return small records.

:func:`run_partition` opens the log itself (a shared path or a URL) and reads only its own
byte ranges, so frames never travel through the scheduler. A frame belongs to the
partition that holds its ``/camera/frame_info`` message; its image parts may lie in a
neighbouring chunk, which is then read too (at most two either side). Messages are decoded
by the flight log's decoder (:func:`flightlog.decode_messages`). What comes back is
small: the detections, the raw MAVLink packets and the flight's own records, each with its
position in the file so the client replays everything in log order. The few pictures the
outputs need (each hole's best view) are read again afterwards (:func:`best_view`).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import resource
import socket
import time
from collections.abc import Sequence
from typing import IO, Any

import numpy as np
import numpy.typing as npt
from mcap.records import Channel, McapRecord, Message

from holescan.detect import Detection, detect_holes
from holescan.errors import NoDepthError
from holescan.flightlog import (
    TOPIC_FRAME_INFO,
    ChunkDamagedError,
    ChunkSpan,
    LoggedDetections,
    LoggedFrame,
    LoggedHoles,
    LoggedMavlink,
    LoggedPose,
    decode_messages,
    open_log,
    read_chunk,
)
from holescan.geotag import VehiclePose
from holescan.ground.reprocessing.mapchunk import MapFrame, fuse_frames
from holescan.ground.reprocessing.plan import FRAME_TOPICS, TASK_TOPICS, PartitionTask
from holescan.mapping import MapLayers

__all__ = ["FrameResult", "PartitionResult", "View", "best_view", "run_partition"]

_log = logging.getLogger(__name__)

Box = tuple[int, int, int, int]
Pos = tuple[int, int]
"""(chunk offset in the file, record number in the chunk): the order records were logged."""


@dataclasses.dataclass(frozen=True)
class View:
    """A crop around a detection box: enough margin for the report's and KML thumbnails."""

    rgb: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.uint16]
    box_in_crop: Box


@dataclasses.dataclass(frozen=True)
class FrameResult:
    """One frame, detected. t_boot_ns is None when the frame was logged before the clocks
    were synchronised; pose is the pose logged with the frame (extrapolated in flight)."""

    pos: Pos
    index: int
    t_unix_ns: int
    t_mono_ns: int
    t_boot_ns: int | None
    pose: VehiclePose | None
    detections: tuple[Detection, ...]
    detect_ms: float
    error: str | None
    no_depth: bool = False  # no depth reading at all (under the sensor's range): no error


Event = FrameResult | LoggedMavlink | LoggedPose | LoggedDetections | LoggedHoles


@dataclasses.dataclass(frozen=True)
class PartitionResult:
    """What one task found, events in log order.

    damaged : chunks that could not be read (bad CRC...), in words; their frames are lost.
    incomplete_frames : frames of this partition missing an image part.
    read_s, detect_s : time reading+decoding / detecting. worker : host:pid.
    peak_rss_mib : the worker process's peak resident memory so far.
    map : the window of the search map this partition's frames saw (None: no map asked
    for, or nothing posed); map_frames : frames fused; map_s : time fusing.
    """

    key: str
    flight: int
    number: int
    events: tuple[tuple[Pos, Event], ...]
    frames: int
    damaged: tuple[str, ...]
    incomplete_frames: int
    read_s: float
    detect_s: float
    worker: str
    peak_rss_mib: float
    map: MapLayers | None = None
    map_frames: int = 0
    map_s: float = 0.0


def _crop(rgb: npt.NDArray[np.uint8], depth: npt.NDArray[np.uint16], box: Box) -> View:
    x, y, w, h = box
    m = max(w, h) + 24
    height, width = depth.shape
    x0, y0 = max(x - m, 0), max(y - m, 0)
    x1, y1 = min(x + w + m, width), min(y + h + m, height)
    return View(rgb[y0:y1, x0:x1].copy(), depth[y0:y1, x0:x1].copy(), (x - x0, y - y0, w, h))


def _read(
    f: IO[bytes], spans: Sequence[ChunkSpan], damaged: list[str]
) -> list[tuple[ChunkSpan, list[McapRecord]]]:
    out = []
    for span in spans:
        try:
            out.append((span, read_chunk(f, span)))
        except ChunkDamagedError as err:
            damaged.append(str(err))
    return out


def _messages(
    chunks: list[tuple[ChunkSpan, list[McapRecord]]], channels: dict[int, Channel]
) -> list[tuple[Pos, Channel, Message]]:
    out = []
    for span, records in chunks:
        for i, rec in enumerate(records):
            if isinstance(rec, Channel):
                channels.setdefault(rec.id, rec)
            elif isinstance(rec, Message):
                ch = channels.get(rec.channel_id)
                if ch is not None and ch.topic in TASK_TOPICS:
                    out.append(((span.offset, i), ch, rec))
    return out


def _select(task: PartitionTask, f: IO[bytes], damaged: list[str]) -> list[Any]:
    """My messages in log order: every task topic in my chunks, and the image parts of my
    frames from the neighbours."""
    channels = dict(task.layout.channels)
    own = _messages(_read(f, task.chunks, damaged), channels)
    mine = {m.sequence for _, ch, m in own if ch.topic == TOPIC_FRAME_INFO}
    selected = [
        (pos, ch, m) for pos, ch, m in own if ch.topic not in FRAME_TOPICS or m.sequence in mine
    ]
    have: dict[int, int] = {}
    for _, ch, m in selected:
        if ch.topic in FRAME_TOPICS:
            have[m.sequence] = have.get(m.sequence, 0) + 1
    neighbours = [*task.after, *reversed(task.before)]
    for span in neighbours:
        if all(have.get(s, 0) >= len(FRAME_TOPICS) for s in mine):
            break
        extra = _messages(_read(f, [span], []), channels)
        for pos, ch, m in extra:
            if ch.topic in FRAME_TOPICS and ch.topic != TOPIC_FRAME_INFO and m.sequence in mine:
                selected.append((pos, ch, m))
                have[m.sequence] = have.get(m.sequence, 0) + 1
    selected.sort(key=lambda x: x[0])
    return selected


def _detect(task: PartitionTask, rec: LoggedFrame, pos: Pos) -> FrameResult:
    rgb, depth = rec.frame.rgb, rec.frame.depth
    t0 = time.perf_counter()
    no_depth = False
    try:
        dets = tuple(detect_holes(rgb, depth, task.camera, task.params))
        err = None
    except NoDepthError:  # counted apart from errors, as the flight's worker does
        dets, err = (), None
        no_depth = True
    except Exception as exc:  # reported and counted, as the flight's worker does
        dets, err = (), f"{type(exc).__name__}: {exc}"
    ms = (time.perf_counter() - t0) * 1000.0
    return FrameResult(
        pos=pos,
        index=rec.frame.index,
        t_unix_ns=rec.t_unix_ns,
        t_mono_ns=rec.frame.t_mono_ns,
        t_boot_ns=rec.t_boot_ns,
        pose=rec.pose,
        detections=dets,
        detect_ms=ms,
        error=err,
        no_depth=no_depth,
    )


def run_partition(task: PartitionTask) -> PartitionResult:
    """Read, decode and detect one partition (see the module docstring)."""
    t0 = time.perf_counter()
    damaged: list[str] = []
    with open_log(task.url, task.storage_options) as f:
        selected = _select(task, f, damaged)
    events: list[tuple[Pos, Event]] = []
    pending: dict[int, dict[str, Any]] = {}
    detect_s = 0.0
    frames = 0
    to_map: list[MapFrame] = []
    for pos, ch, msg in selected:
        for rec in decode_messages([(ch, msg)], task.layout, pending):
            if isinstance(rec, LoggedFrame):
                frames += 1
                if (
                    task.map_anchor is not None
                    and rec.pose is not None
                    and rec.frame.index % task.map_every == 0
                ):
                    to_map.append(MapFrame(rec.frame.depth, rec.frame.rgb, rec.pose))
                r = _detect(task, rec, pos)
                detect_s += r.detect_ms / 1000.0
                events.append((pos, r))
            elif isinstance(rec, LoggedMavlink | LoggedPose | LoggedDetections | LoggedHoles):
                events.append((pos, rec))
    events.sort(key=lambda e: e[0])
    m0 = time.perf_counter()
    window = None
    if task.map_anchor is not None:
        window = fuse_frames(to_map, task.camera, task.mount, task.map_anchor, task.map_cell_m)
    map_s = time.perf_counter() - m0
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return PartitionResult(
        key=task.key,
        flight=task.flight,
        number=task.number,
        events=tuple(events),
        frames=frames,
        damaged=tuple(f"{task.url}: {d}" for d in damaged),
        incomplete_frames=len(pending),
        read_s=time.perf_counter() - t0 - detect_s - map_s,
        detect_s=detect_s,
        worker=f"{socket.gethostname()}:{os.getpid()}",
        peak_rss_mib=peak_kib / 1024.0,
        map=window,
        map_frames=len(to_map),
        map_s=map_s,
    )


def best_view(task: PartitionTask, frame_index: int, box: Box) -> View | None:
    """The crop around ``box`` in frame ``frame_index`` of ``task``'s partition, read again
    from the log (None when the frame cannot be read any more)."""
    if box[2] <= 0 or box[3] <= 0:
        return None
    damaged: list[str] = []
    with open_log(task.url, task.storage_options) as f:
        selected = _select(task, f, damaged)
    pending: dict[int, dict[str, Any]] = {}
    for _, ch, msg in selected:
        for rec in decode_messages([(ch, msg)], task.layout, pending):
            if isinstance(rec, LoggedFrame) and rec.frame.index == frame_index:
                return _crop(rec.frame.rgb, rec.frame.depth, box)
    return None
