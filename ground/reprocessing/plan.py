"""Planning a run on the client: flights, their logs' chunk indexes, and the partitions.

Only the layout of each log is read here (its summary, or its record headers when it was
cut off; see :func:`flightlog.read_log_layout`), plus the first chunks until the camera
calibration is found. Every check that can fail on the input (a missing file, a file
that is not MCAP, a log without a camera) fails here, before any work is submitted.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import Any, Final

from mcap.records import Message

from holescan.detect import CameraIntrinsics, DetectParams
from holescan.errors import InputError
from holescan.flightlog import (
    TOPIC_CAMERA_INFO,
    TOPIC_COLOR,
    TOPIC_DEPTH,
    TOPIC_DETECTIONS,
    TOPIC_FRAME_INFO,
    TOPIC_HOLES,
    TOPIC_MAVLINK_RAW,
    TOPIC_POSE,
    ChunkDamagedError,
    ChunkSpan,
    FlightLogError,
    LoggedCalibration,
    LoggedPose,
    LogLayout,
    decode_messages,
    errors_from_metadata,
    mount_from_metadata,
    open_log,
    read_chunk,
    read_log_layout,
)
from holescan.geotag import CameraMount, ErrorModel
from holescan.ground.flightholes.read import flight_log_files, log_stem
from holescan.ground.reprocessing.options import ReprocessOptions

__all__ = [
    "FlightPlan",
    "LogRef",
    "PartitionTask",
    "group_flights",
    "is_url",
    "partition_flight",
    "plan_flight",
    "ref_name",
]

LogRef = Path | str
"""A log file: a local path, or a URL (``s3://``, ``http://``...) as a string."""
_URL_PART: Final = re.compile(r"^(?P<stem>.*?)(_\d{4})?\.mcap$")


def is_url(ref: str | os.PathLike[str]) -> bool:
    """A URL fsspec opens (``file://`` counts as a local path)."""
    return isinstance(ref, str) and "://" in ref and not ref.startswith("file://")


def ref_name(ref: LogRef) -> str:
    """The file name of a path or URL."""
    return ref.rstrip("/").rsplit("/", 1)[-1] if isinstance(ref, str) else ref.name


def _local(ref: str | os.PathLike[str]) -> LogRef:
    if is_url(ref):
        return str(ref)
    return Path(str(ref).removeprefix("file://") if isinstance(ref, str) else ref)


FRAME_TOPICS: Final = (TOPIC_FRAME_INFO, TOPIC_COLOR, TOPIC_DEPTH)
TASK_TOPICS: Final = (*FRAME_TOPICS, TOPIC_MAVLINK_RAW, TOPIC_POSE, TOPIC_DETECTIONS, TOPIC_HOLES)
"""The topics a partition task reads (the rest of a log is left undecoded)."""
_NEIGHBOURS: Final = 2  # chunks either side a task may read to complete its frames
_CACHE_VERSION: Final = "holescan-partition-1"


@dataclasses.dataclass(frozen=True)
class PartitionTask:
    """One task: the chunks ``chunks`` of one log file, and what is needed to read them.

    key : the cache key (log content hash, chunk range, detector settings).
    flight, number : the flight's position in the run and the partition's within the
        flight (merge order). url : the log. layout : its channels, schemas and metadata
        (no chunk list). before, after : neighbouring chunks, read only to complete frames
        whose first part lies in ``chunks``.
    """

    key: str
    flight: int
    number: int
    url: str
    chunks: tuple[ChunkSpan, ...]
    before: tuple[ChunkSpan, ...]
    after: tuple[ChunkSpan, ...]
    layout: LogLayout
    camera: CameraIntrinsics
    params: DetectParams
    storage_options: Mapping[str, Any]
    mount: CameraMount = dataclasses.field(default_factory=CameraMount)
    map_anchor: tuple[float, float, float] | None = None
    """The search map's local frame (lat, lon, alt) for the run; None: no map."""
    map_cell_m: float = 0.02
    map_every: int = 3

    @property
    def bytes(self) -> int:
        return sum(c.length for c in self.chunks)


@dataclasses.dataclass(frozen=True)
class FlightPlan:
    """One flight: its log files (in part order) and what their layouts say.

    camera : from the first ``camera_info`` (None when no complete chunk holds one: the
    log was cut off at its very start). start_ns : log time of its first chunk.
    mount, errors : the camera mount and the sightings' error model the flight logged.
    problems : files cut off or damaged, in words.
    """

    name: str
    files: tuple[LogRef, ...]
    layouts: tuple[LogLayout, ...]
    camera: CameraIntrinsics | None
    mount: CameraMount
    errors: ErrorModel
    config: Mapping[str, str]
    start_ns: int
    problems: tuple[str, ...]
    first_pose: tuple[float, float, float] | None = None
    """(lat, lon, ground altitude) of the first logged pose: the run's map frame."""

    @property
    def bytes(self) -> int:
        return sum(c.length for lay in self.layouts for c in lay.chunks)


def group_flights(paths: Iterable[str | os.PathLike[str]]) -> list[tuple[LogRef, ...]]:
    """Group log files into flights, in the order given: the rotated parts of one prefix
    (``NAME_0000.mcap``, ``NAME_0001.mcap`` ...) are one flight, in part order (a local
    ``NAME_0000.mcap`` brings the parts that follow it; URLs are taken as given); any other
    file is a flight of its own. Raises :class:`InputError` when a local file is missing."""
    given = [_local(p) for p in paths]
    if not given:
        raise InputError("no flight log given")
    flights: dict[str, set[LogRef]] = {}
    for p in given:
        if isinstance(p, str):
            match = _URL_PART.match(p)
            flights.setdefault(match["stem"] if match else p, set()).add(p)
            continue
        files = flight_log_files(p)
        flights.setdefault(str(log_stem(files[0])), set()).update(files)
    groups = [tuple(sorted(files, key=str)) for files in flights.values()]
    missing = [str(p) for g in groups for p in g if isinstance(p, Path) and not p.is_file()]
    if missing:
        raise InputError(f"{', '.join(missing)}: no such file")
    names = [flight_name(g) for g in groups]
    if len(set(names)) != len(names):
        raise InputError(f"two flights share a name ({names}): rename one of them")
    return groups


def flight_name(files: Sequence[LogRef]) -> str:
    """``NAME`` of ``NAME_0000.mcap`` (or of ``NAME.mcap``)."""
    first = files[0]
    if isinstance(first, Path):
        return log_stem(first).name
    match = _URL_PART.match(ref_name(first))
    return match["stem"] if match else ref_name(first)


def _camera(layout: LogLayout, opts: ReprocessOptions) -> CameraIntrinsics | None:
    topics = layout.topics()
    cid = topics.get(TOPIC_CAMERA_INFO)
    if cid is None:
        return None
    with open_log(layout.url, opts.storage_options) as f:
        for span in layout.chunks:
            try:
                records = read_chunk(f, span)
            except ChunkDamagedError:
                continue
            msgs = [
                (layout.channels[cid], r)
                for r in records
                if isinstance(r, Message) and r.channel_id == cid
            ]
            for rec in decode_messages(msgs, layout, {}):
                if isinstance(rec, LoggedCalibration):
                    return rec.camera
    return None


def _first_pose(
    layout: LogLayout, opts: ReprocessOptions, max_chunks: int = 64
) -> tuple[float, float, float] | None:
    """(lat, lon, altitude of the ground below) of the first pose logged, within the first
    ``max_chunks`` chunks (the search map's frame; None when none is found there)."""
    pid = layout.topics().get(TOPIC_POSE)
    if pid is None:
        return None
    with open_log(layout.url, opts.storage_options) as f:
        for span in layout.chunks[:max_chunks]:
            try:
                records = read_chunk(f, span)
            except ChunkDamagedError:
                continue
            msgs = [
                (layout.channels[pid], r)
                for r in records
                if isinstance(r, Message) and r.channel_id == pid
            ]
            for rec in decode_messages(msgs, layout, {}):
                if isinstance(rec, LoggedPose):
                    p = rec.pose
                    return (p.lat_deg, p.lon_deg, p.alt_m - p.rel_alt_m)
    return None


def plan_flight(files: Sequence[LogRef], opts: ReprocessOptions) -> FlightPlan:
    """Read the layouts of one flight's files. Raises :class:`InputError` for a file that
    is not MCAP, or a log with chunks but no camera calibration (not a holescan log)."""
    layouts: list[LogLayout] = []
    problems: list[str] = []
    camera: CameraIntrinsics | None = None
    for path in files:
        try:
            layout = read_log_layout(
                path, topics=(*TASK_TOPICS, TOPIC_CAMERA_INFO), storage_options=opts.storage_options
            )
        except FlightLogError as err:
            raise InputError(str(err)) from err
        for ch in layout.channels.values():
            if ch.topic.startswith(opts.topic_prefix + "/"):
                raise InputError(
                    f"{path}: the log already has {ch.topic}: reprocess the original flight log"
                )
        if not layout.complete:
            problems.append(
                f"{path}: {layout.stop_reason}; read up to its last complete chunk "
                f"(`holescan log recover {path}` repairs it)"
            )
        if camera is None:
            camera = _camera(layout, opts)
        layouts.append(layout)
    name = flight_name(files)
    if camera is None and any(lay.chunks for lay in layouts):
        raise InputError(f"{files[0]}: no camera_info record: not a holescan flight log")
    if camera is None:
        problems.append(f"{name}: no complete chunk: nothing to reprocess")
    metadata: dict[str, Mapping[str, str]] = {}
    for lay in layouts:
        for key, value in lay.metadata.items():
            metadata.setdefault(key, value)
    try:
        mount = mount_from_metadata(metadata)
        errors = errors_from_metadata(metadata)
    except FlightLogError as err:
        raise InputError(f"{files[0]}: {err}") from err
    starts = [c.start_time_ns for lay in layouts for c in lay.chunks]
    first = None
    if opts.map_cell_m is not None:
        for lay in layouts:
            first = _first_pose(lay, opts)
            if first is not None:
                break
    return FlightPlan(
        name=name,
        files=tuple(files),
        layouts=tuple(layouts),
        camera=camera,
        mount=mount,
        errors=errors,
        config=dict(metadata.get("holescan.config", {})),
        start_ns=min(starts, default=0),
        problems=tuple(problems),
        first_pose=first,
    )


def partition_key(layout: LogLayout, first: ChunkSpan, last: ChunkSpan, settings: Any) -> str:
    """Cache key of the chunks ``first``..``last`` of a log under detector ``settings`` (and
    this version of holescan: another version may detect otherwise)."""
    doc: list[Any] = [_CACHE_VERSION, _dist_version("holescan"), layout.content_hash]
    doc += [first.offset, last.offset, settings]
    return hashlib.blake2b(json.dumps(doc).encode(), digest_size=16).hexdigest()


def partition_flight(
    plan: FlightPlan,
    flight: int,
    opts: ReprocessOptions,
    map_anchor: tuple[float, float, float] | None = None,
) -> list[PartitionTask]:
    """Split a flight's logs along their chunk indexes into tasks of about
    ``opts.partition_bytes`` (whole chunks; a partition never spans two files).
    ``map_anchor``: the run's search-map frame (None: no map)."""
    if plan.camera is None:
        return []
    tasks: list[PartitionTask] = []
    limit = opts.partition_bytes
    for layout in plan.layouts:
        slim = dataclasses.replace(layout, chunks=())
        chunks = layout.chunks
        start = 0
        while start < len(chunks):
            end, size = start, 0
            while end < len(chunks) and (size == 0 or size + chunks[end].length <= limit):
                size += chunks[end].length
                end += 1
            tasks.append(
                PartitionTask(
                    key=partition_key(
                        layout,
                        chunks[start],
                        chunks[end - 1],
                        {
                            **opts.settings_key(),
                            "map_anchor": map_anchor,
                            "mount": repr(plan.mount),
                        },
                    ),
                    flight=flight,
                    number=len(tasks),
                    url=layout.url,
                    chunks=chunks[start:end],
                    before=chunks[max(0, start - _NEIGHBOURS) : start],
                    after=chunks[end : end + _NEIGHBOURS],
                    layout=slim,
                    camera=plan.camera,
                    params=opts.params,
                    storage_options=opts.storage_options,
                    mount=plan.mount,
                    map_anchor=map_anchor if opts.map_cell_m is not None else None,
                    map_cell_m=opts.map_cell_m or 0.02,
                    map_every=opts.map_every,
                )
            )
            start = end
    return tasks
