"""Post-flight reprocessing: detect again over a whole flight log and get the holes again.

:func:`reprocess` reads each flight log front to back once (a file cut off by a crash is
read up to its last complete chunk) and, for every RGB-D frame:

1. **detects** in a pool of worker processes (``spawn``), frames sent in small batches as
   the raw image messages (decoded in the worker), at most a few batches ahead;
2. **poses** the frame from the *logged telemetry*, not from the pose logged with the frame
   (that one was extrapolated: capture never waits). The raw MAVLink packets on
   ``/mavlink/raw`` are replayed through the same adapter and
   :class:`capture.PoseBuffer` as in flight (autopilot = the first heartbeat of a real
   autopilot), and the frame's autopilot boot time (``t_boot_ns``, logged with it) is
   interpolated as soon as telemetry after it has been read; this is what the daemon's
   results thread does when it waits ``pose_wait_s`` for telemetry after a frame. At the
   end of the log the last frames are extrapolated (at most 0.2 s) or refused, as in flight.
   A frame logged without a boot time (clock not synchronised yet) takes the boot-minus-
   monotonic offset of the last frame that had one, else stays unposed.
3. **merges** in frame order (results are put back in order whatever worker finished
   first; with ``frames="flight"`` in the order of the flight's ``/detections`` records,
   the order its tracker saw them in) through :class:`capture._holepipeline.HolePipeline`,
   the capture daemon's own step: detections -> pose -> sightings ->
   :class:`geotag.HoleTracker`. The output depends only on the log and the parameters,
   not on the number of workers or their timing.

What it writes into ``out`` for a flight ``NAME`` (its files ``NAME_0000.mcap``, ...):

* a copy of every log file under the same name, holding every original record byte for
  byte (chunks are copied, not recompressed) plus the new records on their own topics
  (``/reprocess/detections``, ``/reprocess/detections/annotations``, ``/reprocess/holes``,
  ``/reprocess/holes/geojson``; see :data:`TOPICS`) and a ``ground._reprocess`` metadata
  record; new channels and schemas take ids from 65280 up so they never collide with the
  ones the source registers. The originals are never opened for writing;
* ``NAME_holes.gpx|.kml|.geojson|.plan``: holes seen in at least ``min_sightings`` frames;
* ``NAME_report.html``: the offline flight report (:func:`ground._report.write_report`);
* ``NAME_reprocess.json``: the numbers of the run, and ``summary.json`` for all flights.

Ctrl-C (``KeyboardInterrupt``) or ``stop.set()`` stops reading; the frames already
detected are merged and every output is written for them (the MCAP files are valid).
"""

from __future__ import annotations

import base64
import concurrent.futures as cf
import dataclasses
import json
import logging
import math
import multiprocessing as mp
import os
import signal
import struct
import threading
import time
import zlib
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import IO, Any, Final, Literal

import numpy as np
import numpy.typing as npt
import pymap3d
import zstandard
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap_protobuf.schema import build_file_descriptor_set

from capture import (
    FlightLogError,
    HolePipeline,
    LoggedHoles,
    PoseBuffer,
    PoseUnavailable,
    ScanState,
    attitude_from_attitude,
    attitude_from_quaternion,
    gps_from_gps_raw_int,
    position_from_global_position_int,
    scan_records,
)
from capture import _mcapschemas as sch
from detect import DEFAULT, CameraIntrinsics, Detection, DetectParams, detect_holes
from geotag import CameraMount, Hole, VehiclePose
from ground._flightholes import flight_log_files, log_stem, render_thumbnail
from ground._report import write_report
from holescan_errors import InputError
from missions import HOLE_SUFFIXES, HoleFormat, mavlink, parser, write_hole_file

__all__ = [
    "TOPICS",
    "FlightResult",
    "HoleMatch",
    "Progress",
    "ReprocessOptions",
    "ReprocessResult",
    "group_flights",
    "match_points",
    "reprocess",
    "reprocess_flight",
    "write_hole_outputs",
]

_log = logging.getLogger(__name__)

TOPICS: Final = ("detections", "detections/annotations", "holes", "holes/geojson")
"""The topics reprocessing adds, under ``ReprocessOptions.topic_prefix``."""

_FIRST_NEW_ID: Final = 0xFF00
_MAV_AUTOPILOT_INVALID: Final = 8
_MSGID_HOME_POSITION: Final = 242
_NEW_CHUNK_BYTES: Final = 1 << 20
_BATCH_MS: Final = 250.0
_FLIGHT_HORIZON: Final = 60  # frames: a flight's detections are logged well within this
_Box = tuple[int, int, int, int]


# ----------------------------------------------------------------------------- options


@dataclasses.dataclass(frozen=True)
class ReprocessOptions:
    """How a flight is reprocessed.

    params : detector parameters (mode, searcher, thresholds).
    workers : detection processes; 0 detects in this process.
    frames : ``all`` frames of the log, or only those the flight's own detector processed
        (``flight``: the frames its ``/detections`` records name, merged in their order;
        with the flight's parameters this reproduces the flight's holes, exactly when
        the flight could pose every frame it detected on).
    batch_frames : at most this many frames per job sent to a worker (fewer when the
        detector is slow, so that a job takes about 0.25 s).
    min_sightings : holes written to the hole files (and counted as confirmed).
    formats : hole files to write.
    rel_alt_m, clearance_m : mission altitude for ``plan``/``wpl`` files.
    topic_prefix : where the new topics go in the MCAP copies.
    """

    params: DetectParams = DEFAULT
    workers: int = dataclasses.field(default_factory=lambda: os.cpu_count() or 1)
    frames: Literal["all", "flight"] = "all"
    batch_frames: int = 4
    min_sightings: int = 2
    formats: tuple[HoleFormat, ...] = ("gpx", "kml", "geojson", "plan")
    rel_alt_m: float = 10.0
    clearance_m: float = 5.0
    topic_prefix: str = "/reprocess"

    def __post_init__(self) -> None:
        if self.workers < 0 or self.batch_frames < 1 or self.min_sightings < 1:
            raise InputError("workers must be >= 0, batch_frames and min_sightings >= 1")
        if self.frames not in ("all", "flight"):
            raise InputError(f"frames must be 'all' or 'flight', got {self.frames!r}")
        if not self.topic_prefix.startswith("/") or self.topic_prefix.endswith("/"):
            raise InputError(f"topic_prefix must look like /name, got {self.topic_prefix!r}")


@dataclasses.dataclass(frozen=True)
class Progress:
    """Where a run is. ``bytes_*`` count the log files of the current flight."""

    flight: str
    flight_number: int
    flights: int
    frames_read: int
    frames_done: int
    bytes_read: int
    bytes_total: int
    elapsed_s: float

    @property
    def fraction(self) -> float:
        return self.bytes_read / self.bytes_total if self.bytes_total else 1.0

    @property
    def frames_per_s(self) -> float:
        return self.frames_done / self.elapsed_s if self.elapsed_s > 0 else 0.0

    @property
    def eta_s(self) -> float:
        """Seconds left for this flight, from the bytes read so far (NaN at the start)."""
        f = self.fraction
        return self.elapsed_s * (1.0 - f) / f if f > 0.001 else math.nan


@dataclasses.dataclass(frozen=True)
class HoleMatch:
    """A reference point (truth, or a hole of the flight) and the nearest found hole.

    reference : index into the reference list. found : index into the found list, or None
    when nothing lies within the distance. distance_m : horizontal distance (NaN if None).
    """

    reference: int
    found: int | None
    distance_m: float


@dataclasses.dataclass(frozen=True)
class FlightResult:
    """What :func:`reprocess_flight` did for one flight.

    name : the flight's name (log prefix). sources : its log files. outputs : the MCAP
    copies written. files : (kind, path) of the hole files, report and JSON summary.
    frames_read : complete frames in the log; frames_detected : frames detected and merged;
    frames_unposed : of those with detections, frames no pose could be found for.
    holes : every hole (sorted by id); confirmed : seen in >= ``min_sightings`` frames.
    flight_holes : the log's own final hole list (what the flight found).
    flight_matches : each confirmed flight hole and the reprocessed hole nearest to it
        (indices into the confirmed lists); flight_same_ids : how many of those pairs
        carry the same id.
    truncated : files that were cut off (read up to their last complete chunk).
    interrupted : stopped early (Ctrl-C); the outputs hold what was done.
    detect_ms_mean : worker time per frame. elapsed_s, frames_per_s : wall clock.
    """

    name: str
    sources: tuple[Path, ...]
    outputs: tuple[Path, ...]
    files: tuple[tuple[str, Path], ...]
    frames_read: int
    frames_detected: int
    frames_unposed: int
    detections: int
    detect_errors: int
    holes: tuple[Hole, ...]
    confirmed: tuple[Hole, ...]
    flight_holes: tuple[Hole, ...]
    flight_matches: tuple[HoleMatch, ...]
    flight_same_ids: int
    truncated: tuple[str, ...]
    interrupted: bool
    detect_ms_mean: float
    elapsed_s: float

    @property
    def frames_per_s(self) -> float:
        return self.frames_detected / self.elapsed_s if self.elapsed_s > 0 else 0.0

    def summary(self) -> dict[str, Any]:
        """The numbers, as JSON-ready values."""
        found = [m for m in self.flight_matches if m.found is not None]
        return {
            "flight": self.name,
            "sources": [str(p) for p in self.sources],
            "outputs": [str(p) for p in self.outputs],
            "files": {kind: str(path) for kind, path in self.files},
            "frames_read": self.frames_read,
            "frames_detected": self.frames_detected,
            "frames_unposed": self.frames_unposed,
            "detections": self.detections,
            "detect_errors": self.detect_errors,
            "holes": len(self.holes),
            "confirmed": len(self.confirmed),
            "flight_confirmed": len(self.flight_matches),
            "flight_reproduced": len(found),
            "flight_same_ids": self.flight_same_ids,
            "flight_max_offset_m": max((m.distance_m for m in found), default=None),
            "truncated": list(self.truncated),
            "interrupted": self.interrupted,
            "detect_ms_mean": round(self.detect_ms_mean, 2),
            "elapsed_s": round(self.elapsed_s, 2),
            "frames_per_s": round(self.frames_per_s, 2),
            "confirmed_holes": [sch.jsonable(h) for h in self.confirmed],
        }

    def lines(self) -> list[str]:
        """A short human summary."""
        cut = f", {len(self.truncated)} file(s) cut off" if self.truncated else ""
        stop = " INTERRUPTED" if self.interrupted else ""
        found = [m for m in self.flight_matches if m.found is not None]
        worst = max((m.distance_m for m in found), default=math.nan)
        out = [
            f"{self.name}:{stop} {self.frames_detected}/{self.frames_read} frames in "
            f"{self.elapsed_s:.1f} s ({self.frames_per_s:.1f} frames/s){cut}; "
            f"{len(self.confirmed)} holes seen >= 2 times ({len(self.holes)} in all)",
            f"  in-flight holes reproduced: {len(found)}/{len(self.flight_matches)}"
            + (f" (same id {self.flight_same_ids}, farthest {worst:.2f} m)" if found else ""),
        ]
        out += [f"  wrote {path} ({kind})" for kind, path in self.files]
        out += [f"  wrote {p} (mcap)" for p in self.outputs]
        return out


@dataclasses.dataclass(frozen=True)
class ReprocessResult:
    flights: tuple[FlightResult, ...]
    summary_path: Path | None
    pool_start_s: float

    @property
    def interrupted(self) -> bool:
        return any(f.interrupted for f in self.flights)

    def lines(self) -> list[str]:
        out = [line for f in self.flights for line in f.lines()]
        if self.summary_path is not None:
            out.append(f"summary: {self.summary_path}")
        return out


# ---------------------------------------------------------------------- hole matching


def match_points(
    reference: Sequence[tuple[float, float]],
    found: Sequence[tuple[float, float]],
    max_distance_m: float,
) -> list[HoleMatch]:
    """Pair each reference (lat_deg, lon_deg) with at most one found point, nearest pairs
    first (a found point serves one reference), within ``max_distance_m``.

    Returns one :class:`HoleMatch` per reference, in reference order.
    """
    pairs: list[tuple[float, int, int]] = []
    if reference and found:
        lat0, lon0 = reference[0]
        ref = np.array(
            [pymap3d.geodetic2enu(la, lo, 0.0, lat0, lon0, 0.0)[:2] for la, lo in reference]
        )
        fnd = np.array([pymap3d.geodetic2enu(la, lo, 0.0, lat0, lon0, 0.0)[:2] for la, lo in found])
        dist = np.hypot(ref[:, None, 0] - fnd[None, :, 0], ref[:, None, 1] - fnd[None, :, 1])
        pairs = sorted(
            (float(dist[i, j]), i, j)
            for i in range(len(reference))
            for j in range(len(found))
            if dist[i, j] <= max_distance_m
        )
    taken_ref: dict[int, tuple[int, float]] = {}
    taken_found: set[int] = set()
    for d, i, j in pairs:
        if i in taken_ref or j in taken_found:
            continue
        taken_ref[i] = (j, d)
        taken_found.add(j)
    return [
        HoleMatch(i, taken_ref[i][0], taken_ref[i][1])
        if i in taken_ref
        else HoleMatch(i, None, math.nan)
        for i in range(len(reference))
    ]


# ----------------------------------------------------------------- detection workers


@dataclasses.dataclass(frozen=True)
class _View:
    """A crop around a detection box: enough margin for the report's and KML thumbnails."""

    rgb: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.uint16]
    box_in_crop: _Box


@dataclasses.dataclass(frozen=True)
class _Result:
    frame_index: int
    detections: tuple[Detection, ...]
    views: dict[_Box, _View]
    detect_ms: float
    error: str | None


def _crop(rgb: npt.NDArray[np.uint8], depth: npt.NDArray[np.uint16], box: _Box) -> _View:
    x, y, w, h = box
    m = max(w, h) + 24
    height, width = depth.shape
    x0, y0 = max(x - m, 0), max(y - m, 0)
    x1, y1 = min(x + w + m, width), min(y + h + m, height)
    return _View(rgb[y0:y1, x0:x1].copy(), depth[y0:y1, x0:x1].copy(), (x - x0, y - y0, w, h))


def _init_worker() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what Ctrl-C does


def _detect_batch(
    camera: CameraIntrinsics, params: DetectParams, jobs: list[tuple[int, bytes, bytes]]
) -> list[_Result]:
    """Decode and detect a batch of frames (runs in a worker process)."""
    out = []
    for index, color, depth_msg in jobs:
        rgb = sch.image_from_raw(RawImage.FromString(color))
        depth = sch.image_from_raw(RawImage.FromString(depth_msg))
        t0 = time.perf_counter()
        try:
            dets = tuple(detect_holes(rgb, depth, camera, params))
            err = None
        except Exception as exc:  # reported and counted, as the flight's worker does
            dets, err = (), f"{type(exc).__name__}: {exc}"
        ms = (time.perf_counter() - t0) * 1000.0
        views = {}
        for d in dets:
            box = (int(d.box[0]), int(d.box[1]), int(d.box[2]), int(d.box[3]))
            if box[2] > 0 and box[3] > 0:
                views[box] = _crop(rgb, depth, box)
        out.append(_Result(index, dets, views, ms, err))
    return out


# ------------------------------------------------------------------ telemetry replay


class _TelemetryReplay:
    """Logged raw MAVLink -> :class:`PoseBuffer`, as :class:`capture.Telemetry` fills it."""

    def __init__(self) -> None:
        self._mav = parser()
        self._error = mavlink.MAVError
        self.poses = PoseBuffer(capacity=8192)
        self.target: tuple[int, int] | None = None
        self.home: tuple[float, float, float] | None = None
        self._last_boot_ns = 0
        self.packets = 0

    def feed(self, packet: bytes) -> bool:
        """Parse one logged packet; True when it added a position or attitude sample."""
        self.packets += 1
        try:
            msgs = self._mav.parse_buffer(packet) or []
        except self._error:
            return False
        added = False
        for msg in msgs:
            added |= self._handle(msg)
        return added

    def _handle(self, msg: Any) -> bool:
        mtype = msg.get_type()
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.target is None:
            if mtype == "HEARTBEAT" and msg.autopilot != _MAV_AUTOPILOT_INVALID:
                self.target = src
            return False
        if src != self.target:
            return False
        if mtype == "GLOBAL_POSITION_INT":
            pos = position_from_global_position_int(msg)
            self._last_boot_ns = max(self._last_boot_ns, pos.t_boot_ns)
            return self.poses.add_position(pos)
        if mtype in ("ATTITUDE", "ATTITUDE_QUATERNION"):
            try:
                att = (
                    attitude_from_attitude(msg)
                    if mtype == "ATTITUDE"
                    else attitude_from_quaternion(msg)
                )
            except ValueError:
                return False
            self._last_boot_ns = max(self._last_boot_ns, att.t_boot_ns)
            return self.poses.add_attitude(att)
        if mtype == "GPS_RAW_INT":
            self.poses.add_gps(gps_from_gps_raw_int(msg, self._last_boot_ns))
        elif mtype == "HOME_POSITION":
            self.home = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
        return False

    def pose_at(self, t_boot_ns: int | None) -> VehiclePose | None:
        if t_boot_ns is None:
            return None
        try:
            return self.poses.pose_at(t_boot_ns)
        except PoseUnavailable as err:
            _log.debug("no pose at boot %d: %s", t_boot_ns, err)
            return None


# ------------------------------------------------------------------- the MCAP copy


class _McapCopy:
    """A copy of one log file with new messages appended in new chunks.

    ``copy(record, start, end)`` copies a top-level record's bytes ``[start, end)`` from
    the source (records after the data section are left out: the summary is rebuilt);
    ``add(topic, ...)`` queues a new message; ``finish()`` writes the summary and
    renames the file into place. Nothing is recompressed but the new chunks.
    """

    def __init__(self, src: Path, dst: Path, topic_prefix: str, metadata: dict[str, str]):
        if dst.exists() and dst.resolve() == src.resolve():
            raise InputError(f"{dst} is the source log: choose another --out folder")
        self.dst = dst
        self._tmp = dst.with_name(f".{dst.name}.part")
        self._src: IO[bytes] = open(src, "rb")  # noqa: SIM115 (closed in finish/abort)
        self._out: IO[bytes] = open(self._tmp, "wb")  # noqa: SIM115
        self._prefix = topic_prefix
        self._metadata = metadata
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._counts: dict[int, int] = {}
        self._t_start, self._t_end = 2**64 - 1, 0
        self._messages = 0
        self._data_ended = False
        self._after_chunk: ChunkIndex | None = None
        self._new_channels: dict[str, int] = {}
        self._next_schema = self._next_channel = _FIRST_NEW_ID
        self._chunk = RecordBuilder()
        self._chunk_index: dict[int, list[tuple[int, int]]] = {}
        self._chunk_times = (2**64 - 1, 0)
        self._chunk_messages = 0
        self._zstd = zstandard.ZstdCompressor(level=3)

    # -- the source's records --------------------------------------------------------------

    def copy(self, rec: Any, start: int, end: int) -> None:
        if self._data_ended:
            return
        if isinstance(rec, DataEnd):
            self._data_ended = True
            return
        if isinstance(
            rec, Footer | Statistics | ChunkIndex | AttachmentIndex | MetadataIndex | SummaryOffset
        ):
            return
        if isinstance(rec, Chunk) and self._chunk.count >= _NEW_CHUNK_BYTES:
            self._flush_new_chunk()  # only here: a chunk's message indexes must follow it
        offset = self._out.tell()
        self._src.seek(start)
        self._out.write(self._src.read(end - start))
        if isinstance(rec, Chunk):
            index = ChunkIndex(
                message_start_time=rec.message_start_time,
                message_end_time=rec.message_end_time,
                chunk_start_offset=offset,
                chunk_length=end - start,
                message_index_offsets={},
                message_index_length=0,
                compression=rec.compression,
                compressed_size=len(rec.data),
                uncompressed_size=rec.uncompressed_size,
            )
            self._chunk_indexes.append(index)
            self._after_chunk = index
            return
        if isinstance(rec, MessageIndex) and self._after_chunk is not None:
            self._after_chunk.message_index_offsets[rec.channel_id] = offset
            self._after_chunk.message_index_length += end - start
            return
        self._after_chunk = None
        if isinstance(rec, Metadata):
            self._metadata_indexes.append(MetadataIndex(offset, end - start, rec.name))
        elif isinstance(rec, Attachment):
            self._attachment_indexes.append(
                AttachmentIndex(
                    offset,
                    end - start,
                    rec.log_time,
                    rec.create_time,
                    len(rec.data),
                    rec.name,
                    rec.media_type,
                )
            )

    def content(self, rec: Any) -> None:
        """Account for a Schema, Channel or Message of the source (in a chunk or not)."""
        if isinstance(rec, Message):
            self._count(rec.channel_id, rec.log_time)
        elif isinstance(rec, Schema | Channel):
            if isinstance(rec, Channel) and rec.topic.startswith(self._prefix + "/"):
                raise InputError(
                    f"{self.dst.name}: the log already has {rec.topic}: reprocess the original "
                    "flight log, or use another topic prefix"
                )
            if rec.id >= _FIRST_NEW_ID:
                raise InputError(
                    f"{self.dst.name}: {type(rec).__name__.lower()} id {rec.id} is one "
                    "reprocessing adds (a reprocessed log?): reprocess the original flight log"
                )
            if isinstance(rec, Schema):
                self.schemas.setdefault(rec.id, rec)
            else:
                self.channels.setdefault(rec.id, rec)

    def _count(self, channel_id: int, log_time: int) -> None:
        self._counts[channel_id] = self._counts.get(channel_id, 0) + 1
        self._messages += 1
        self._t_start = min(self._t_start, log_time)
        self._t_end = max(self._t_end, log_time)

    # -- new messages ----------------------------------------------------------------------

    def _channel(self, topic: str, proto: Any | None) -> int:
        cid = self._new_channels.get(topic)
        if cid is not None:
            return cid
        if proto is None:
            name, schema = sch.JSON_SCHEMAS[
                sch.TOPIC_DETECTIONS if topic.endswith("/detections") else sch.TOPIC_HOLES
            ]
            s = Schema(
                id=self._next_schema,
                name=name,
                encoding=SchemaEncoding.JSONSchema,
                data=sch.to_json(schema),
            )
            encoding = MessageEncoding.JSON
        else:
            fds = build_file_descriptor_set(type(proto)).SerializeToString()
            s = Schema(
                id=self._next_schema,
                name=proto.DESCRIPTOR.full_name,
                encoding=SchemaEncoding.Protobuf,
                data=fds,
            )
            encoding = MessageEncoding.Protobuf
        ch = Channel(
            id=self._next_channel,
            topic=topic,
            message_encoding=encoding,
            metadata={},
            schema_id=s.id,
        )
        self._next_schema += 1
        self._next_channel += 1
        self.schemas[s.id], self.channels[ch.id] = s, ch
        s.write(self._chunk)
        ch.write(self._chunk)
        self._new_channels[topic] = ch.id
        return ch.id

    def add(self, topic: str, obj: Any, t_unix_ns: int, sequence: int) -> None:
        """Queue a new message (a protobuf message, or JSON-able data) on ``topic``."""
        is_proto = hasattr(obj, "SerializeToString")
        cid = self._channel(topic, obj if is_proto else None)
        data = obj.SerializeToString() if is_proto else sch.to_json(obj)
        offset = self._chunk.count
        Message(
            channel_id=cid, log_time=t_unix_ns, data=data, publish_time=t_unix_ns, sequence=sequence
        ).write(self._chunk)
        self._chunk_index.setdefault(cid, []).append((t_unix_ns, offset))
        lo, hi = self._chunk_times
        self._chunk_times = (min(lo, t_unix_ns), max(hi, t_unix_ns))
        self._chunk_messages += 1
        self._count(cid, t_unix_ns)

    def _flush_new_chunk(self) -> None:
        if self._chunk.count == 0:
            return
        data = _bytes(self._chunk)
        lo, hi = self._chunk_times if self._chunk_messages else (0, 0)
        chunk = Chunk(
            compression="zstd",
            data=self._zstd.compress(data),
            message_start_time=lo,
            message_end_time=hi,
            uncompressed_crc=zlib.crc32(data),
            uncompressed_size=len(data),
        )
        b = RecordBuilder()
        chunk.write(b)
        start = self._out.tell()
        self._out.write(_bytes(b))
        index = ChunkIndex(
            message_start_time=lo,
            message_end_time=hi,
            chunk_start_offset=start,
            chunk_length=self._out.tell() - start,
            message_index_offsets={},
            message_index_length=0,
            compression="zstd",
            compressed_size=len(chunk.data),
            uncompressed_size=len(data),
        )
        for cid, entries in self._chunk_index.items():
            index.message_index_offsets[cid] = self._out.tell()
            MessageIndex(cid, entries).write(b)
            self._out.write(_bytes(b))
        index.message_index_length = self._out.tell() - start - index.chunk_length
        self._chunk_indexes.append(index)
        self._chunk_index = {}
        self._chunk_times = (2**64 - 1, 0)
        self._chunk_messages = 0
        self._after_chunk = None

    # -- the end ----------------------------------------------------------------------------

    def finish(self) -> Path:
        """Write the metadata record, the data end and a full summary; rename into place."""
        self._flush_new_chunk()
        b = RecordBuilder()
        offset = self._out.tell()
        Metadata("ground._reprocess", self._metadata).write(b)
        self._out.write(_bytes(b))
        self._metadata_indexes.append(
            MetadataIndex(offset, self._out.tell() - offset, "ground._reprocess")
        )
        DataEnd(0).write(b)
        self._out.write(_bytes(b))
        summary_start = self._out.tell()
        groups: list[tuple[int, list[Any]]] = [
            (Opcode.SCHEMA, [self.schemas[k] for k in sorted(self.schemas)]),
            (Opcode.CHANNEL, [self.channels[k] for k in sorted(self.channels)]),
            (Opcode.STATISTICS, [self._statistics()]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.ATTACHMENT_INDEX, self._attachment_indexes),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        ]
        offsets = []
        for opcode, records in groups:
            if not records:
                continue
            start = summary_start + b.count
            for rec in records:
                rec.write(b)
            offsets.append(SummaryOffset(opcode, start, summary_start + b.count - start))
        offsets_start = summary_start + b.count
        for so in offsets:
            so.write(b)
        summary = _bytes(b)
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offsets_start), crc)
        self._out.write(summary)
        Footer(summary_start, offsets_start, crc).write(b)
        self._out.write(_bytes(b))
        self._out.write(b"\x89MCAP0\r\n")
        self._out.flush()
        os.fsync(self._out.fileno())
        self._close()
        os.replace(self._tmp, self.dst)
        return self.dst

    def _statistics(self) -> Statistics:
        return Statistics(
            message_count=self._messages,
            schema_count=len(self.schemas),
            channel_count=len(self.channels),
            attachment_count=len(self._attachment_indexes),
            metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes),
            message_start_time=self._t_start if self._messages else 0,
            message_end_time=self._t_end,
            channel_message_counts=dict(sorted(self._counts.items())),
        )

    def _close(self) -> None:
        self._src.close()
        self._out.close()

    def abort(self) -> None:
        self._close()
        self._tmp.unlink(missing_ok=True)


# ------------------------------------------------------------------------ one flight


def group_flights(paths: Iterable[str | os.PathLike[str]]) -> list[tuple[Path, ...]]:
    """Group log files into flights, in the order given: the rotated parts of one prefix
    (``NAME_0000.mcap``, ``NAME_0001.mcap`` ...) are one flight, in part order; any other
    file is a flight of its own."""
    given = [Path(p) for p in paths]
    if not given:
        raise InputError("no flight log given")
    flights: dict[Path, set[Path]] = {}
    for p in given:
        files = flight_log_files(p)
        flights.setdefault(log_stem(files[0]), set()).update(files)
    return [tuple(sorted(files)) for files in flights.values()]


class _Flight:
    """State of one flight being reprocessed (single pass, see the module docstring)."""

    def __init__(
        self,
        files: tuple[Path, ...],
        out: Path,
        opts: ReprocessOptions,
        pool: cf.ProcessPoolExecutor | None,
    ) -> None:
        self.files = files
        self.name = log_stem(files[0]).name
        self.out = out
        self.opts = opts
        self.pool = pool
        self.camera: CameraIntrinsics | None = None
        self.depth_unit_m = 0.001
        self.mount = CameraMount()
        self.config: dict[str, str] = {}
        self.pipeline: HolePipeline | None = None
        self.telemetry = _TelemetryReplay()
        self.copy: _McapCopy | None = None
        self.outputs: list[Path] = []
        self.truncated: list[str] = []
        # frames
        self._parts: dict[int, dict[str, bytes]] = {}
        self._batch: list[tuple[int, bytes, bytes]] = []
        self._undecided: OrderedDict[int, tuple[bytes, bytes, int | None, int]] = OrderedDict()
        self._pose_queue: deque[tuple[int, int | None]] = deque()
        self._poses: dict[int, VehiclePose | None] = {}
        self._t_unix: dict[int, int] = {}
        self._order: deque[int] = deque()
        self._results: dict[int, _Result] = {}
        self._futures: deque[cf.Future[list[_Result]]] = deque()
        self._boot_minus_mono: int | None = None
        self.boot_to_unix_ns: int | None = None
        # flight's own records
        self.track: list[VehiclePose] = []
        self.flight_holes: tuple[Hole, ...] = ()
        self.first_pose: VehiclePose | None = None
        # results
        self.views: dict[int, _View] = {}
        self.frames_read = self.frames_detected = self.frames_unposed = 0
        self.detections = self.detect_errors = 0
        self.detect_ms = 0.0
        self._seq = dict.fromkeys(TOPICS, 0)

    # -- reading ----------------------------------------------------------------------------

    def read_part(self, path: Path, tick: Callable[[int], None], stop: threading.Event) -> bool:
        """Copy and process one file; False when stopped early."""
        self.copy = _McapCopy(
            path, self.out / path.name, self.opts.topic_prefix, self._metadata_record()
        )
        state = ScanState(path)
        channels: dict[int, Channel] = {}
        last_end = 0
        try:
            for rec in scan_records(path, state):
                if state.good_bytes != last_end:  # a top-level record (not chunk content)
                    if stop.is_set():  # before copying it: copied chunks are read whole
                        break
                    self.copy.copy(rec, last_end, state.good_bytes)
                    last_end = state.good_bytes
                    tick(last_end)
                    if isinstance(rec, Metadata):
                        self._on_metadata(rec)
                if isinstance(rec, Schema | Channel | Message):
                    self.copy.content(rec)
                if isinstance(rec, Channel):
                    channels.setdefault(rec.id, rec)
                elif isinstance(rec, Message):
                    channel = channels.get(rec.channel_id)
                    if channel is None:
                        raise FlightLogError(f"{path}: message on unknown channel")
                    self._on_message(channel.topic, rec)
                self._collect(block=False)
        except BaseException:
            self.copy.abort()
            self.copy = None
            raise
        if not stop.is_set():
            tick(state.size)  # all of it was looked at (a cut-off tail too)
        if not state.complete and not stop.is_set():
            why = state.describe_stop()
            _log.warning("%s (read up to there)", why)
            self.truncated.append(why)
        if self._parts:
            _log.warning("%s: %d frames incomplete at the end", path, len(self._parts))
            self._parts.clear()
        return not stop.is_set()

    def close_part(self) -> None:
        if self.copy is not None:
            self.outputs.append(self.copy.finish())
            self.copy = None

    def _metadata_record(self) -> dict[str, str]:
        p = self.opts.params
        return {
            "version": _dist_version("holescan"),
            "params": sch.to_json(p).decode(),
            "frames": self.opts.frames,
            "topic_prefix": self.opts.topic_prefix,
            "pose": "re-interpolated from /mavlink/raw at each frame's t_boot_ns",
        }

    def _on_metadata(self, rec: Metadata) -> None:
        md = dict(rec.metadata)
        if rec.name == "holescan.camera":
            self.depth_unit_m = float(md.get("depth_unit_m", "0.001"))
        elif rec.name == "holescan.mount":
            try:
                rot = json.loads(md["rotation_frd_from_camera"])
                offset = tuple(float(v) for v in json.loads(md["offset_frd_m"]))
                self.mount = CameraMount(
                    tuple(tuple(float(v) for v in row) for row in rot),  # type: ignore[arg-type]
                    offset,  # type: ignore[arg-type]
                )
            except (KeyError, ValueError, TypeError) as err:
                raise FlightLogError(f"unreadable holescan.mount metadata: {err}") from err
        elif rec.name == "holescan.config":
            self.config = md

    def _on_message(self, topic: str, msg: Message) -> None:
        if topic in (sch.TOPIC_FRAME_INFO, sch.TOPIC_COLOR, sch.TOPIC_DEPTH):
            parts = self._parts.setdefault(msg.sequence, {})
            parts[topic] = msg.data
            if len(parts) == 3:
                del self._parts[msg.sequence]
                self._on_frame(parts)
        elif topic == sch.TOPIC_MAVLINK_RAW:
            packet = base64.b64decode(sch.from_json(msg.data)["data"])
            if self.telemetry.feed(packet):
                self._pose_ready()
        elif topic == sch.TOPIC_POSE:
            pose = sch.decode_pose(sch.from_json(msg.data))
            self.track.append(pose)
            self.first_pose = self.first_pose or pose
        elif topic == sch.TOPIC_CAMERA_INFO and self.camera is None:
            cal = CameraCalibration.FromString(msg.data)
            self.camera = sch.camera_from_calibration(cal, self.depth_unit_m)
            self.pipeline = HolePipeline(self.camera, self.mount)
        elif topic == sch.TOPIC_DETECTIONS and self.opts.frames == "flight":
            self._decide(int(sch.from_json(msg.data)["frame_index"]))
        elif topic == sch.TOPIC_HOLES:
            logged = LoggedHoles(
                msg.publish_time, msg.sequence, tuple(sch.from_json(msg.data)["holes"])
            )
            try:
                self.flight_holes = logged.as_holes()
            except FlightLogError as err:
                _log.debug("in-flight hole list not comparable: %s", err)

    def _on_frame(self, parts: dict[str, bytes]) -> None:
        info = sch.from_json(parts[sch.TOPIC_FRAME_INFO])
        index, t_unix = int(info["index"]), int(info["t_unix_ns"])
        t_boot = info.get("t_boot_ns")
        t_mono = int(info["t_mono_ns"])
        if t_boot is not None:
            t_boot = int(t_boot)
            self._boot_minus_mono = t_boot - t_mono
            self.boot_to_unix_ns = t_unix - t_boot
        elif self._boot_minus_mono is not None:
            t_boot = t_mono + self._boot_minus_mono
        if info.get("pose") is not None and self.first_pose is None:
            self.first_pose = sch.decode_pose(info["pose"])
        self.frames_read += 1
        if self.camera is None:
            raise FlightLogError(f"{self.name}: a frame before any camera_info record")
        job = (index, parts[sch.TOPIC_COLOR], parts[sch.TOPIC_DEPTH])
        if self.opts.frames == "flight":
            self._undecided[index] = (job[1], job[2], t_boot, t_unix)
        else:
            self._dispatch(job, t_boot, t_unix)

    def _decide(self, detected_index: int) -> None:
        """The flight detected frame ``detected_index``: detect it now (the merge follows the
        order of the flight's ``/detections`` records, the order its tracker saw them in).
        Frames no record named within :data:`_FLIGHT_HORIZON` frames were skipped in flight."""
        job = self._undecided.pop(detected_index, None)
        if job is not None:
            color, depth, t_boot, t_unix = job
            self._dispatch((detected_index, color, depth), t_boot, t_unix)
        while self._undecided and next(iter(self._undecided)) < detected_index - _FLIGHT_HORIZON:
            self._undecided.popitem(last=False)

    def _dispatch(self, job: tuple[int, bytes, bytes], t_boot: int | None, t_unix: int) -> None:
        index = job[0]
        self._order.append(index)
        self._t_unix[index] = t_unix
        self._pose_queue.append((index, t_boot))
        self._pose_ready()
        self._batch.append(job)
        if len(self._batch) >= self._batch_size():
            self._submit()

    def _batch_size(self) -> int:
        """Frames per job: ``batch_frames``, fewer when frames are slow (paper mode), so
        that a job takes about :data:`_BATCH_MS` and a stop does not wait long for one."""
        if self.frames_detected == 0:
            return 1
        per_frame_ms = self.detect_ms / self.frames_detected
        return max(1, min(self.opts.batch_frames, int(_BATCH_MS / max(per_frame_ms, 1.0))))

    def _submit(self) -> None:
        if not self._batch:
            return
        assert self.camera is not None
        jobs, self._batch = self._batch, []
        if self.pool is None:
            for r in _detect_batch(self.camera, self.opts.params, jobs):
                self._results[r.frame_index] = r
            self._merge()
            return
        while len(self._futures) >= 2 * max(self.opts.workers, 1) + 1:
            self._collect(block=True)
        self._futures.append(self.pool.submit(_detect_batch, self.camera, self.opts.params, jobs))

    def _collect(self, block: bool) -> None:
        """Take finished batches (the oldest one waited for when ``block``); merge."""
        got = False
        while self._futures and (self._futures[0].done() or (block and not got)):
            fut = self._futures.popleft()
            if fut.cancelled():
                continue
            for r in fut.result():
                self._results[r.frame_index] = r
            got = True
        if got:
            self._merge()

    # -- poses and merging --------------------------------------------------------------------

    def _pose_ready(self, final: bool = False) -> None:
        """Pose queued frames whose time the telemetry has passed (all of them when final)."""
        newest = self.telemetry.poses.newest_t_boot_ns
        q = self._pose_queue
        while q and (final or q[0][1] is None or (newest is not None and q[0][1] <= newest)):
            index, t_boot = q.popleft()
            self._poses[index] = self.telemetry.pose_at(t_boot)

    def _merge(self) -> None:
        assert self.pipeline is not None
        while self._order and self._order[0] in self._results and self._order[0] in self._poses:
            index = self._order.popleft()
            r = self._results.pop(index)
            pose = self._poses.pop(index)
            t_unix = self._t_unix.pop(index)
            self.frames_detected += 1
            self.detect_ms += r.detect_ms
            if r.error is not None:
                self.detect_errors += 1
                _log.warning("detection failed on frame %d: %s", index, r.error)
                continue
            self.detections += len(r.detections)
            self._add(
                "detections",
                {
                    "frame_index": index,
                    "t_unix_ns": t_unix,
                    "detections": [sch.detection_json(d) for d in r.detections],
                },
                t_unix,
            )
            self._add(
                "detections/annotations", sch.annotations_message(r.detections, t_unix), t_unix
            )
            step = self.pipeline.add(index, r.detections, _constant(pose))
            if step.refused:
                self.frames_unposed += 1
            if not step.changed:
                continue
            for h in step.changed:
                view = r.views.get(tuple(int(v) for v in h.best_box))  # type: ignore[arg-type]
                if h.best_frame_index == index and view is not None:
                    self.views[h.id] = view
            holes = [sch.jsonable(h) for h in self.pipeline.holes()]
            self._add("holes", {"holes": holes}, t_unix)
            self._add("holes/geojson", sch.holes_geojson_message(holes), t_unix)

    def _add(self, topic: str, obj: Any, t_unix_ns: int) -> None:
        if self.copy is None:  # interrupted between files: nowhere to write
            return
        self.copy.add(f"{self.opts.topic_prefix}/{topic}", obj, t_unix_ns, self._seq[topic])
        self._seq[topic] += 1

    def finish_frames(self, interrupted: bool) -> None:
        """End of the log (or a stop): detect what was read, pose the rest, merge."""
        if interrupted:
            self._batch.clear()
            self._undecided.clear()
            for fut in self._futures:
                fut.cancel()
        else:
            self._undecided.clear()
            self._submit()
        while self._futures:
            self._collect(block=True)
        self._pose_ready(final=True)
        self._merge()
        if self._order:  # batches cancelled by a stop: those frames were not detected
            self._order.clear()
            self._results.clear()
            self._poses.clear()


def _bytes(builder: RecordBuilder) -> bytes:
    """What ``builder`` holds (and empty it)."""
    data: bytes = builder.end()  # type: ignore[no-untyped-call]
    return data


def _constant(pose: VehiclePose | None) -> Callable[[], VehiclePose | None]:
    return lambda: pose


def _hole_files(
    out: Path,
    name: str,
    holes: Sequence[Hole],
    opts: ReprocessOptions,
    thumbnails: Mapping[int, bytes],
    home: tuple[float, float, float] | None,
    boot_to_unix_ns: int | None,
) -> list[tuple[str, Path]]:
    written: list[tuple[str, Path]] = []
    if not holes:
        return written
    for fmt in opts.formats:
        path = out / f"{name}_holes{HOLE_SUFFIXES[fmt]}"
        write_hole_file(
            path,
            holes,
            fmt,
            home=home,
            thumbnails=thumbnails,
            boot_to_unix_ns=boot_to_unix_ns,
            rel_alt_m=opts.rel_alt_m,
            clearance_m=opts.clearance_m,
            name=f"holescan holes: {name}",
        )
        written.append((fmt, path))
    return written


def write_hole_outputs(
    out: Path,
    name: str,
    holes: Sequence[Hole],
    views: Mapping[int, tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], _Box]],
    track: Sequence[VehiclePose],
    *,
    opts: ReprocessOptions | None = None,
    home: tuple[float, float, float] | None = None,
    boot_to_unix_ns: int | None = None,
    truth: Sequence[tuple[str, float, float]] = (),
    facts: Mapping[str, str] | None = None,
    title: str | None = None,
) -> list[tuple[str, Path]]:
    """Write a flight's hole files (``NAME_holes.*``) and report (``NAME_report.html``).

    holes : the holes to write (confirmed ones). views : hole id -> (rgb, depth, box) of
    its best view, the box (x, y, w, h) in that picture's pixels. track : vehicle poses.
    truth : (name, lat_deg, lon_deg) drawn on the report's map. Returns (kind, path) pairs.
    """
    opts = opts or ReprocessOptions()
    jpegs = {
        hid: render_thumbnail(rgb, depth, box)[0]
        for hid, (rgb, depth, box) in views.items()
        if any(h.id == hid for h in holes)
    }
    written = _hole_files(out, name, holes, opts, jpegs, home, boot_to_unix_ns)
    report_holes = [
        dataclasses.replace(h, best_box=views[h.id][2]) if h.id in views else h for h in holes
    ]
    report_views = {h.id: (views[h.id][0], views[h.id][1]) for h in holes if h.id in views}
    path = write_report(
        out / f"{name}_report.html",
        title=title or f"holescan flight report: {name}",
        holes=report_holes,
        track=track,
        views=report_views,
        truth=truth,
        facts=facts,
    )
    written.append(("report", path))
    return written


def reprocess_flight(
    files: Sequence[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    opts: ReprocessOptions | None = None,
    *,
    pool: cf.ProcessPoolExecutor | None = None,
    progress: Callable[[Progress], None] | None = None,
    stop: threading.Event | None = None,
    flight_number: int = 1,
    flights: int = 1,
) -> FlightResult:
    """Reprocess one flight (its log files, in order) into folder ``out``.

    ``pool`` : the detection workers (:func:`reprocess` makes one); None detects in this
    process. See the module docstring for what is written.
    """
    opts = opts or ReprocessOptions()
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = tuple(Path(p) for p in files)
    for p in paths:
        if not p.is_file():
            raise FlightLogError(f"{p}: no such file")
    stop = stop or threading.Event()
    fl = _Flight(paths, out_dir, opts, pool)
    total = sum(p.stat().st_size for p in paths)
    t0 = time.monotonic()
    last = [0.0, 0.0, 0.0]  # time of the last progress report, bytes read, earlier files

    def tick(pos: int, force: bool = False) -> None:
        now = time.monotonic()
        pos += int(last[2])
        last[1] = pos
        if progress is not None and (force or now - last[0] >= 0.25):
            last[0] = now
            progress(
                Progress(
                    fl.name,
                    flight_number,
                    flights,
                    fl.frames_read,
                    fl.frames_detected,
                    pos,
                    total,
                    now - t0,
                )
            )

    interrupted = False
    try:
        for path in paths:
            if not fl.read_part(path, tick, stop):
                interrupted = True
                break
            last[2] += path.stat().st_size
            if path != paths[-1]:
                fl.close_part()
        fl.finish_frames(interrupted)
        fl.close_part()
    except BaseException:  # a second Ctrl-C or a failure: no half-written outputs
        if fl.copy is not None:
            fl.copy.abort()
        raise
    elapsed = time.monotonic() - t0
    last[2] = 0.0
    tick(int(last[1]), force=True)
    if fl.pipeline is None:
        raise FlightLogError(f"{paths[0]}: no camera_info record: not a holescan flight log")
    return _flight_outputs(fl, opts, interrupted, elapsed)


def _flight_outputs(
    fl: _Flight, opts: ReprocessOptions, interrupted: bool, elapsed: float
) -> FlightResult:
    assert fl.pipeline is not None
    holes = tuple(fl.pipeline.holes())
    confirmed = tuple(h for h in holes if h.sightings >= opts.min_sightings)
    flight_confirmed = [h for h in fl.flight_holes if h.sightings >= opts.min_sightings]
    matches = match_points(
        [(h.lat_deg, h.lon_deg) for h in flight_confirmed],
        [(h.lat_deg, h.lon_deg) for h in confirmed],
        2.0,
    )
    home = fl.telemetry.home
    if home is None and fl.first_pose is not None:
        p = fl.first_pose
        home = (p.lat_deg, p.lon_deg, p.alt_m - p.rel_alt_m)
    views = {hid: (v.rgb, v.depth, v.box_in_crop) for hid, v in fl.views.items()}
    facts = {
        "logs": ", ".join(p.name for p in fl.files),
        "reprocessed": f"{fl.frames_detected} of {fl.frames_read} frames"
        + (" (INTERRUPTED)" if interrupted else ""),
        "detector": f"{opts.params.mode.value}, searcher {opts.params.searcher.name}",
        "poses": "re-interpolated from the logged MAVLink telemetry",
        "in-flight holes reproduced": (
            f"{sum(m.found is not None for m in matches)} of {len(matches)}"
        ),
    }
    if fl.truncated:
        facts["cut off"] = "; ".join(fl.truncated)
    files = write_hole_outputs(
        fl.out,
        fl.name,
        confirmed,
        views,
        fl.track,
        opts=opts,
        home=home,
        boot_to_unix_ns=fl.boot_to_unix_ns,
        facts=facts,
        title=f"holescan reprocessed flight: {fl.name}",
    )
    result = FlightResult(
        name=fl.name,
        sources=fl.files,
        outputs=tuple(fl.outputs),
        files=(),
        frames_read=fl.frames_read,
        frames_detected=fl.frames_detected,
        frames_unposed=fl.frames_unposed,
        detections=fl.detections,
        detect_errors=fl.detect_errors,
        holes=holes,
        confirmed=confirmed,
        flight_holes=fl.flight_holes,
        flight_matches=tuple(matches),
        flight_same_ids=sum(
            m.found is not None and flight_confirmed[m.reference].id == confirmed[m.found].id
            for m in matches
        ),
        truncated=tuple(fl.truncated),
        interrupted=interrupted,
        detect_ms_mean=fl.detect_ms / max(fl.frames_detected, 1),
        elapsed_s=elapsed,
    )
    summary_path = fl.out / f"{fl.name}_reprocess.json"
    files.append(("summary", summary_path))
    result = dataclasses.replace(result, files=tuple(files))
    summary_path.write_text(json.dumps(result.summary(), indent=1, allow_nan=False) + "\n")
    return result


# -------------------------------------------------------------------------- many flights


def reprocess(
    logs: Iterable[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    opts: ReprocessOptions | None = None,
    *,
    progress: Callable[[Progress], None] | None = None,
    stop: threading.Event | None = None,
) -> ReprocessResult:
    """Reprocess every flight among ``logs`` (see :func:`group_flights`) into ``out``.

    Each flight's files go to ``out`` directly when there is one flight, else to
    ``out/NAME/``; ``out/summary.json`` lists every flight. Stops after the current flight
    on Ctrl-C (that flight's outputs hold what was done).

    Raises
    ------
    InputError : a missing file or one that is not a holescan flight log; output in the
        folder of the source logs under the same name.
    """
    opts = opts or ReprocessOptions()
    groups = group_flights(logs)
    names = [log_stem(g[0]).name for g in groups]
    if len(set(names)) != len(names):
        raise InputError(f"two flights share a name ({names}): reprocess them separately")
    for p in (p for g in groups for p in g):
        if not p.is_file():
            raise FlightLogError(f"{p}: no such file")
    out_dir = Path(out)
    stop = stop or threading.Event()
    results: list[FlightResult] = []
    t0 = time.monotonic()
    pool = None
    restore = _stop_on_sigint(stop)
    if opts.workers > 0:
        pool = cf.ProcessPoolExecutor(
            opts.workers, mp_context=mp.get_context("spawn"), initializer=_init_worker
        )
        # Start the workers now (imports take seconds), not inside the first flight's timing.
        list(pool.map(_ping, range(opts.workers)))
    pool_start_s = time.monotonic() - t0
    try:
        for i, files in enumerate(groups):
            target = out_dir if len(groups) == 1 else out_dir / names[i]
            res = reprocess_flight(
                files,
                target,
                opts,
                pool=pool,
                progress=progress,
                stop=stop,
                flight_number=i + 1,
                flights=len(groups),
            )
            results.append(res)
            if res.interrupted:
                break
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        restore()
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = out_dir / "summary.json"
    doc = {
        "holescan": _dist_version("holescan"),
        "pool_start_s": round(pool_start_s, 2),
        "flights": [r.summary() for r in results],
    }
    summary.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return ReprocessResult(tuple(results), summary, pool_start_s)


def _stop_on_sigint(stop: threading.Event) -> Callable[[], None]:
    """First Ctrl-C sets ``stop`` (a clean stop); a second one interrupts at once.

    Only in the main thread (elsewhere signals cannot be handled); returns the undo.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum: int, frame: Any) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        _log.warning("stopping: finishing the frames already detected (Ctrl-C again to abort)")
        stop.set()

    signal.signal(signal.SIGINT, handler)

    def restore() -> None:
        signal.signal(signal.SIGINT, previous)

    return restore


def _ping(_: int) -> int:
    """A no-op job: makes a pool worker start and import the detector."""
    import detect  # noqa: F401 (the import is the point)

    return os.getpid()
