"""Reading flight logs back: typed records, also from files cut off mid-write.

A file is read front to back (as ``mcap``'s ``NonSeekingReader`` does, with every CRC
checked), so a file whose tail was lost in a crash yields every message up to its last
complete chunk; the summary at the end of a cleanly closed file is not needed.
"""

from __future__ import annotations

import base64
import dataclasses
import logging
import math
import os
from collections.abc import Collection, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal

from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf.message import DecodeError
from mcap.records import Channel, Message, Metadata, Schema

import holescan.flightlog.schemas as sch
from holescan.detect import CameraIntrinsics, Detection, Frame
from holescan.errors import InputError
from holescan.flightlog.detections import decode_detection
from holescan.flightlog.errors import FlightLogError, TruncatedLogError
from holescan.flightlog.images import decode_compressed
from holescan.flightlog.scan import ScanState, scan_records
from holescan.geotag import AnnounceGate, Hole, VehiclePose

__all__ = [
    "LogRecord",
    "LoggedCalibration",
    "LoggedDetections",
    "LoggedFrame",
    "LoggedHealth",
    "LoggedHoles",
    "LoggedMavlink",
    "LoggedPose",
    "McapSource",
    "decode_message",
    "log_files",
    "read_camera",
    "read_flight_log",
]

_log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class LoggedFrame:
    """An RGB-D frame with its clocks and the vehicle pose at capture (when logged).

    t_unix_ns : capture time, Unix clock. t_boot_ns : capture time on the autopilot clock.
    sequence : the writer's frame counter (gaps = frames the logger dropped).
    """

    frame: Frame
    t_unix_ns: int
    sequence: int
    t_boot_ns: int | None
    pose: VehiclePose | None


@dataclasses.dataclass(frozen=True)
class LoggedPose:
    t_unix_ns: int
    sequence: int
    pose: VehiclePose


@dataclasses.dataclass(frozen=True)
class LoggedMavlink:
    """A raw MAVLink packet; ``msgid``/``sysid``/``compid`` are -1 for non-MAVLink bytes."""

    t_unix_ns: int
    sequence: int
    packet: bytes
    name: str
    msgid: int
    sysid: int
    compid: int


@dataclasses.dataclass(frozen=True)
class LoggedDetections:
    t_unix_ns: int
    sequence: int
    frame_index: int
    detections: tuple[Detection, ...]


@dataclasses.dataclass(frozen=True)
class LoggedHoles:
    """The hole list as logged: one dict per hole (``lat_deg``, ``lon_deg``, ..., ``tier``)
    and the thresholds of the gate that decided the tiers (None: a log from before tiers
    were recorded)."""

    t_unix_ns: int
    sequence: int
    holes: tuple[dict[str, Any], ...]
    gate: dict[str, Any] | None = None

    def tiers(self) -> dict[int, str] | None:
        """Hole id -> the tier the vehicle gave it; None when the log did not record it."""
        if self.gate is None or not all("tier" in h for h in self.holes):
            return None
        return {int(h["id"]): str(h["tier"]) for h in self.holes}

    def announce_gate(self) -> AnnounceGate | None:
        """The flight's :class:`geotag.AnnounceGate` (None: not recorded)."""
        if self.gate is None:
            return None
        known = {f.name for f in dataclasses.fields(AnnounceGate)}
        try:
            return AnnounceGate(**{k: v for k, v in self.gate.items() if k in known})
        except (InputError, TypeError) as err:
            raise FlightLogError(f"unreadable logged gate {self.gate}: {err}") from err

    def as_holes(self) -> tuple[Hole, ...]:
        """The holes as :class:`geotag.Hole` records (when they were logged as such)."""
        fields = dataclasses.fields(Hole)
        names = {f.name for f in fields}
        required = {f.name for f in fields if f.default is dataclasses.MISSING}
        out = []
        for h in self.holes:
            if not required <= set(h) - {"tier"} <= names:  # logs from before p_hole and views
                raise FlightLogError(f"logged hole fields {sorted(h)} are not a geotag.Hole")
            box = h["best_box"]
            values: dict[str, Any] = {k: v for k, v in h.items() if k not in ("p_hole", "tier")}
            p = h.get("p_hole")
            values["p_hole"] = math.nan if p is None else float(p)
            out.append(Hole(**{**values, "best_box": tuple(box) if box is not None else box}))
        return tuple(out)


@dataclasses.dataclass(frozen=True)
class LoggedHealth:
    t_unix_ns: int
    sequence: int
    values: dict[str, Any]


@dataclasses.dataclass(frozen=True)
class LoggedCalibration:
    t_unix_ns: int
    sequence: int
    camera: CameraIntrinsics


LogRecord = (
    LoggedFrame
    | LoggedPose
    | LoggedMavlink
    | LoggedDetections
    | LoggedHoles
    | LoggedHealth
    | LoggedCalibration
)


def _iter_messages(
    path: str | os.PathLike[str], state: ScanState, topics: Collection[str] | None
) -> Iterator[tuple[Channel, Schema | None, Message, dict[str, dict[str, str]]]]:
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    metadata: dict[str, dict[str, str]] = {}
    for record in scan_records(path, state):
        if isinstance(record, Message):
            channel = channels.get(record.channel_id)
            if channel is None:
                raise FlightLogError(f"{path}: message on unknown channel {record.channel_id}")
            if topics is None or channel.topic in topics:
                yield channel, schemas.get(channel.schema_id), record, metadata
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Metadata):
            metadata[record.name] = dict(record.metadata)


# ------------------------------------------------------------------------ typed reader

_TOPICS_BY_KIND: dict[type[Any], tuple[str, ...]] = {
    LoggedFrame: (sch.TOPIC_FRAME_INFO, sch.TOPIC_COLOR, sch.TOPIC_DEPTH),
    LoggedPose: (sch.TOPIC_POSE,),
    LoggedMavlink: (sch.TOPIC_MAVLINK_RAW,),
    LoggedDetections: (sch.TOPIC_DETECTIONS,),
    LoggedHoles: (sch.TOPIC_HOLES,),
    LoggedHealth: (sch.TOPIC_HEALTH,),
    LoggedCalibration: (sch.TOPIC_CAMERA_INFO,),
}


def _depth_unit(metadata: Mapping[str, Mapping[str, str]]) -> float:
    return float(metadata.get("holescan.camera", {}).get("depth_unit_m", "0.001"))


def log_files(paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]]) -> list[Path]:
    """The files of one flight, each once (the same file given twice is an error)."""
    if isinstance(paths, str | os.PathLike):
        return [Path(paths)]
    out = [Path(p) for p in paths]
    if not out:
        raise FlightLogError("no flight log files given")
    seen: dict[Path, Path] = {}
    for p in out:
        key = p.resolve()
        if key in seen:
            raise FlightLogError(f"{p} is given twice (as {seen[key]}): name each file once")
        seen[key] = p
    return out


def read_flight_log(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    *,
    kinds: Collection[type[Any]] | None = None,
    strict: bool = False,
) -> Iterator[LogRecord]:
    """Iterate over the typed records of one flight log file or of its rotated files.

    Parameters
    ----------
    paths : a file, or the files of one flight in order (``PREFIX_0000.mcap``, ...).
    kinds : record classes to yield (e.g. ``{LoggedFrame}``); default all. Leaving
        :class:`LoggedFrame` out skips decoding images.
    strict : raise :class:`TruncatedLogError` on a file cut off before its end instead of
        logging a warning and stopping at its last complete chunk.

    Yields
    ------
    LoggedFrame, LoggedPose, LoggedMavlink, LoggedDetections, LoggedHoles, LoggedHealth,
    LoggedCalibration, in the order they were written.
    """
    wanted = set(_TOPICS_BY_KIND) if kinds is None else set(kinds)
    topics = {t for kind in wanted for t in _TOPICS_BY_KIND.get(kind, ())}
    for path in log_files(paths):
        state = ScanState(path)
        pending: dict[int, dict[str, Any]] = {}
        for channel, schema, msg, metadata in _iter_messages(path, state, topics):
            rec = decode_message(channel.topic, schema, msg, metadata, pending)
            if rec is not None:
                yield rec
        if pending:
            _log.warning("%s: %d frames incomplete at the end", path, len(pending))
        if not state.whole:
            if strict:
                raise TruncatedLogError(state.describe_stop())
            _log.warning("%s (read the rest)", state.describe_stop())


def _check_schema(topic: str, schema: Schema | None, expected: str) -> None:
    if schema is None or schema.name != expected:
        got = None if schema is None else schema.name
        raise FlightLogError(f"topic {topic} has schema {got}, expected {expected}")


def _decode_image(topic: str, schema: Schema | None, data: bytes) -> Any:
    """The pixels of one logged image, raw (older logs, ``raw`` settings) or compressed."""
    name = None if schema is None else schema.name
    try:
        if name == "foxglove.CompressedImage":
            kind: Literal["color", "depth"] = "depth" if topic == sch.TOPIC_DEPTH else "color"
            return decode_compressed(CompressedImage.FromString(data), kind)
        _check_schema(topic, schema, "foxglove.RawImage")
        return sch.image_from_raw(RawImage.FromString(data))
    except DecodeError as err:
        raise FlightLogError(f"damaged {name} message on {topic}: {err}") from err


def decode_message(
    topic: str,
    schema: Schema | None,
    msg: Message,
    metadata: Mapping[str, Mapping[str, str]],
    pending: dict[int, dict[str, Any]],
) -> LogRecord | None:
    """The typed record of one logged message on ``topic``, or None when it completes
    nothing yet (a frame is three messages: its parts wait in ``pending``, keyed by
    sequence, until the last one comes) or the topic is not one holescan reads.

    metadata : the file's metadata records so far (``holescan.camera`` gives the depth
    unit of a camera_info). Raises :class:`FlightLogError` on a schema other than the one
    the topic is written with.
    """
    t, seq = msg.publish_time, msg.sequence
    if topic in (sch.TOPIC_COLOR, sch.TOPIC_DEPTH, sch.TOPIC_FRAME_INFO):
        parts = pending.setdefault(seq, {})
        if topic == sch.TOPIC_FRAME_INFO:
            parts[topic] = sch.from_json(msg.data)
        else:
            parts[topic] = _decode_image(topic, schema, msg.data)
        if len(parts) < 3:
            return None
        del pending[seq]
        info = parts[sch.TOPIC_FRAME_INFO]
        frame = Frame(
            index=int(info["index"]),
            rgb=parts[sch.TOPIC_COLOR],
            depth=parts[sch.TOPIC_DEPTH],
            t_mono_ns=int(info["t_mono_ns"]),
            t_sensor_ns=int(info["t_sensor_ns"]),
        )
        pose = info.get("pose")
        t_boot = info.get("t_boot_ns")
        return LoggedFrame(
            frame=frame,
            t_unix_ns=int(info["t_unix_ns"]),
            sequence=seq,
            t_boot_ns=None if t_boot is None else int(t_boot),
            pose=None if pose is None else sch.decode_pose(pose),
        )
    if topic == sch.TOPIC_POSE:
        return LoggedPose(t, seq, sch.decode_pose(sch.from_json(msg.data)))
    if topic == sch.TOPIC_MAVLINK_RAW:
        obj = sch.from_json(msg.data)
        packet = base64.b64decode(obj["data"])
        msgid, sysid, compid = sch.mavlink_header(packet)
        return LoggedMavlink(t, seq, packet, str(obj.get("name", "")), msgid, sysid, compid)
    if topic == sch.TOPIC_DETECTIONS:
        obj = sch.from_json(msg.data)
        dets = tuple(decode_detection(d) for d in obj["detections"])
        return LoggedDetections(int(obj["t_unix_ns"]), seq, int(obj["frame_index"]), dets)
    if topic == sch.TOPIC_HOLES:
        obj = sch.from_json(msg.data)
        return LoggedHoles(t, seq, tuple(obj["holes"]), obj.get("gate"))
    if topic == sch.TOPIC_HEALTH:
        return LoggedHealth(t, seq, sch.from_json(msg.data))
    if topic == sch.TOPIC_CAMERA_INFO:
        _check_schema(topic, schema, "foxglove.CameraCalibration")
        cal = CameraCalibration.FromString(msg.data)
        return LoggedCalibration(t, seq, sch.camera_from_calibration(cal, _depth_unit(metadata)))
    return None


# ------------------------------------------------------------------------- frame source


def read_camera(path: str | os.PathLike[str]) -> CameraIntrinsics:
    """The camera intrinsics a flight log was written with (its first camera_info)."""
    for rec in read_flight_log(path, kinds={LoggedCalibration}):
        assert isinstance(rec, LoggedCalibration)
        return rec.camera
    raise FlightLogError(f"{path}: no {sch.TOPIC_CAMERA_INFO} message (not a holescan log?)")


class McapSource:
    """A :class:`detect.FrameSource` replaying the frames of a flight log.

    ``camera`` comes from the log's first ``/camera/color/camera_info``.
    """

    def __init__(self, paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]]):
        self._paths = log_files(paths)
        self.camera = read_camera(self._paths[0])

    def __enter__(self) -> McapSource:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def __iter__(self) -> Iterator[Frame]:
        for rec in read_flight_log(self._paths, kinds={LoggedFrame}):
            assert isinstance(rec, LoggedFrame)
            yield rec.frame
