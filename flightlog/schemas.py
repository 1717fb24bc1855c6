"""What the flight log stores on which topic, and how records become MCAP messages and back.

Pure conversions (no files, no clocks): Foxglove protobuf messages for what Foxglove
Studio shows (images, calibration, transforms, GPS, annotations, GeoJSON) and JSON
(MCAP ``jsonschema`` channels) for holescan's own records, which must round-trip exactly.

Frames of reference written to ``/tf``: ``world`` is ENU (x east, y north, z up) with its
origin at the first logged vehicle position (the ``holescan.world_origin`` metadata);
``base_link`` is the vehicle body FLU (x forward, y left, z up, the ROS convention);
``camera`` is the optical frame (x right, y down, z forward) of the depth-registered RGB
image.
"""

from __future__ import annotations

import base64
import dataclasses
import enum
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.GeoJSON_pb2 import GeoJSON
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp
from scipy.spatial.transform import Rotation

from holescan.detect import CameraIntrinsics, FeatureScores
from holescan.errors import InputError
from holescan.flightlog.images import image_from_raw, raw_image_message
from holescan.geotag import VehiclePose, dcm_from_euler

__all__ = [
    "BODY_FRAME",
    "CAMERA_FRAME",
    "JSON_SCHEMAS",
    "TOPIC_CAMERA_INFO",
    "TOPIC_COLOR",
    "TOPIC_DEPTH",
    "TOPIC_DETECTIONS",
    "TOPIC_DETECTION_ANNOTATIONS",
    "TOPIC_FRAME_INFO",
    "TOPIC_HEALTH",
    "TOPIC_HOLES",
    "TOPIC_HOLES_GEOJSON",
    "TOPIC_LOCATION",
    "TOPIC_MAVLINK_RAW",
    "TOPIC_POSE",
    "TOPIC_TF",
    "WORLD_FRAME",
    "calibration_message",
    "camera_from_calibration",
    "camera_mount_transform",
    "decode_pose",
    "float_or_nan",
    "float_or_none",
    "from_json",
    "holes_geojson_message",
    "holes_record",
    "image_from_raw",
    "jsonable",
    "location_message",
    "mavlink_header",
    "mavlink_json",
    "pose_json",
    "raw_image_message",
    "timestamp",
    "to_json",
    "transform_message",
    "vehicle_transform",
]

TOPIC_COLOR: Final = "/camera/color/image_raw"
TOPIC_DEPTH: Final = "/camera/depth/image_raw"
TOPIC_FRAME_INFO: Final = "/camera/frame_info"
TOPIC_CAMERA_INFO: Final = "/camera/color/camera_info"
TOPIC_TF: Final = "/tf"
TOPIC_LOCATION: Final = "/mavlink/location"
TOPIC_POSE: Final = "/mavlink/pose"
TOPIC_MAVLINK_RAW: Final = "/mavlink/raw"
TOPIC_DETECTION_ANNOTATIONS: Final = "/detections/annotations"
TOPIC_DETECTIONS: Final = "/detections"
TOPIC_HOLES: Final = "/holes"
TOPIC_HOLES_GEOJSON: Final = "/holes/geojson"
TOPIC_HEALTH: Final = "/health"

CAMERA_FRAME: Final = "camera"
BODY_FRAME: Final = "base_link"
WORLD_FRAME: Final = "world"

_INT: Final = {"type": "integer"}
_NUM: Final = {"type": "number"}
_NUM_OR_NULL: Final = {"type": ["number", "null"]}
_POSE_SCHEMA: Final[dict[str, Any]] = {
    "type": "object",
    "description": "geotag.VehiclePose: autopilot boot clock, WGS84 degrees, metres, radians",
    "properties": {
        name: (_INT if name in ("t_boot_ns", "age_ns") else _NUM_OR_NULL)
        for name in (f.name for f in dataclasses.fields(VehiclePose))
    },
    "required": [f.name for f in dataclasses.fields(VehiclePose)],
}
_XYZ: Final = {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}
_DETECTION_SCHEMA: Final[dict[str, Any]] = {
    "type": "object",
    "properties": {
        "box": {"type": "array", "items": _INT, "minItems": 4, "maxItems": 4},
        "score": _NUM,
        "features": {
            "type": "object",
            "properties": {f.name: _NUM for f in dataclasses.fields(FeatureScores)},
        },
        "depth_rel_m": _NUM,
        "major_m": _NUM,
        "minor_m": _NUM,
        "rim_depth_m": _NUM,
        "beyond_range": {"type": "boolean"},
        "relative_brightness": {"type": ["number", "null"]},
        "p_hole": {"type": ["number", "null"]},
        "opening_m": {"oneOf": [_XYZ, {"type": "null"}]},
        "rim_normal": {"oneOf": [_XYZ, {"type": "null"}]},
        "rim_seen": {"type": ["number", "null"]},
        "border_cut": {"type": "boolean"},
        "inside_on_plane": {"type": ["number", "null"]},
        "inside_behind": {"type": ["number", "null"]},
    },
}

JSON_SCHEMAS: Final[dict[str, tuple[str, dict[str, Any]]]] = {
    TOPIC_FRAME_INFO: (
        "holescan.FrameInfo",
        {
            "type": "object",
            "description": "Clocks and telemetry of the RGB-D frame with the same sequence",
            "properties": {
                "index": _INT,
                "t_mono_ns": _INT,
                "t_sensor_ns": _INT,
                "t_unix_ns": _INT,
                "t_boot_ns": {"type": ["integer", "null"]},
                "pose": {"oneOf": [_POSE_SCHEMA, {"type": "null"}]},
            },
            "required": ["index", "t_mono_ns", "t_sensor_ns", "t_unix_ns"],
        },
    ),
    TOPIC_POSE: ("holescan.VehiclePose", _POSE_SCHEMA),
    TOPIC_MAVLINK_RAW: (
        "holescan.MavlinkRaw",
        {
            "type": "object",
            "description": "One MAVLink packet as received (v1 or v2), base64",
            "properties": {
                "msgid": _INT,
                "name": {"type": "string"},
                "sysid": _INT,
                "compid": _INT,
                "data": {"type": "string", "contentEncoding": "base64"},
            },
            "required": ["data"],
        },
    ),
    TOPIC_DETECTIONS: (
        "holescan.Detections",
        {
            "type": "object",
            "properties": {
                "frame_index": _INT,
                "t_unix_ns": _INT,
                "detections": {"type": "array", "items": _DETECTION_SCHEMA},
            },
            "required": ["frame_index", "t_unix_ns", "detections"],
        },
    ),
    TOPIC_HOLES: (
        "holescan.Holes",
        {
            "type": "object",
            "description": "The current list of geotagged holes (lat_deg, lon_deg, ...)",
            "properties": {"holes": {"type": "array", "items": {"type": "object"}}},
            "required": ["holes"],
        },
    ),
    TOPIC_HEALTH: (
        "holescan.Health",
        {
            "type": "object",
            "description": "Daemon and logger health: frame drops, queue depths, clock offset",
            "properties": {"source": {"type": "string"}},
            "additionalProperties": True,
        },
    ),
}


# --------------------------------------------------------------------------- JSON helpers


def jsonable(obj: Any) -> Any:
    """``obj`` as plain JSON types: dataclasses and mappings become dicts, enums their
    value, tuples/arrays lists, NaN/inf ``None`` (JSON has no NaN)."""
    if obj is None or isinstance(obj, bool | int | str):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, np.ndarray):
        return [jsonable(v) for v in obj.tolist()]
    if isinstance(obj, enum.Enum):
        return jsonable(obj.value)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, Sequence | set | frozenset):
        return [jsonable(v) for v in obj]
    raise InputError(f"cannot log a {type(obj).__name__} as JSON: pass numbers, strings, dicts")


def to_json(obj: Any) -> bytes:
    """Compact UTF-8 JSON of :func:`jsonable` ``obj``."""
    return json.dumps(jsonable(obj), separators=(",", ":"), allow_nan=False).encode()


def from_json(data: bytes) -> Any:
    return json.loads(data)


def float_or_nan(value: Any) -> float:
    """A JSON number back as a float: ``null`` (how :func:`jsonable` writes NaN) is NaN."""
    return math.nan if value is None else float(value)


def float_or_none(value: Any) -> float | None:
    """An optional JSON number: ``null`` stays None."""
    return None if value is None else float(value)


# ------------------------------------------------------------------------ frames, camera


def timestamp(t_ns: int) -> Timestamp:
    """The protobuf ``Timestamp`` of ``t_ns`` nanoseconds since the Unix epoch."""
    return Timestamp(seconds=t_ns // 1_000_000_000, nanos=t_ns % 1_000_000_000)


def calibration_message(camera: CameraIntrinsics, t_unix_ns: int) -> CameraCalibration:
    """``foxglove.CameraCalibration`` (pinhole, no distortion) of ``camera``."""
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    return CameraCalibration(
        timestamp=timestamp(t_unix_ns),
        frame_id=CAMERA_FRAME,
        width=camera.width,
        height=camera.height,
        distortion_model="plumb_bob",
        D=[0.0] * 5,
        K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    )


def camera_from_calibration(msg: CameraCalibration, depth_unit_m: float) -> CameraIntrinsics:
    k = list(msg.K)
    return CameraIntrinsics(int(msg.width), int(msg.height), k[0], k[4], k[2], k[5], depth_unit_m)


# ------------------------------------------------------------------ transforms and poses

_FLU_FROM_FRD: Final = np.diag([1.0, -1.0, -1.0])
_ENU_FROM_NED: Final = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def transform_message(
    parent: str,
    child: str,
    translation_m: Sequence[float] | npt.NDArray[np.float64],
    rotation: npt.NDArray[np.float64],
    t_unix_ns: int,
) -> FrameTransform:
    """``foxglove.FrameTransform``: pose of ``child`` in ``parent`` (rotation parent<-child)."""
    x, y, z, w = (float(v) for v in Rotation.from_matrix(rotation).as_quat())
    tx, ty, tz = (float(v) for v in translation_m)
    return FrameTransform(
        timestamp=timestamp(t_unix_ns),
        parent_frame_id=parent,
        child_frame_id=child,
        translation=Vector3(x=tx, y=ty, z=tz),
        rotation=Quaternion(x=x, y=y, z=z, w=w),
    )


def camera_mount_transform(
    rotation_frd_cam: npt.NDArray[np.float64], offset_frd_m: Sequence[float], t_unix_ns: int
) -> FrameTransform:
    """``base_link`` (FLU) -> ``camera`` (optical) from a mount given in the FRD body frame."""
    rot = _FLU_FROM_FRD @ np.asarray(rotation_frd_cam, dtype=np.float64)
    offset = _FLU_FROM_FRD @ np.asarray(offset_frd_m, dtype=np.float64)
    return transform_message(BODY_FRAME, CAMERA_FRAME, offset, rot, t_unix_ns)


def vehicle_transform(pose: VehiclePose, enu_m: Sequence[float], t_unix_ns: int) -> FrameTransform:
    """``world`` (ENU) -> ``base_link`` (FLU) from the vehicle's NED/FRD attitude."""
    rot = _ENU_FROM_NED @ dcm_from_euler(pose.roll, pose.pitch, pose.yaw) @ _FLU_FROM_FRD
    return transform_message(WORLD_FRAME, BODY_FRAME, enu_m, rot, t_unix_ns)


def location_message(pose: VehiclePose, t_unix_ns: int) -> LocationFix:
    """``foxglove.LocationFix``: WGS84 position, altitude MSL, horizontal variance from eph."""
    cov: list[float] = [0.0] * 9
    cov_type = LocationFix.PositionCovarianceType.UNKNOWN
    if math.isfinite(pose.eph_m):
        var = pose.eph_m**2
        cov = [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, 4.0 * var]
        cov_type = LocationFix.PositionCovarianceType.APPROXIMATED
    return LocationFix(
        timestamp=timestamp(t_unix_ns),
        frame_id=BODY_FRAME,
        latitude=pose.lat_deg,
        longitude=pose.lon_deg,
        altitude=pose.alt_m,
        position_covariance=cov,
        position_covariance_type=cov_type,
    )


def pose_json(pose: VehiclePose) -> dict[str, Any]:
    out: dict[str, Any] = jsonable(pose)
    return out


def decode_pose(obj: Mapping[str, Any]) -> VehiclePose:
    """Inverse of :func:`pose_json` (``null`` floats come back as NaN)."""
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(VehiclePose):
        if f.name in obj:
            value = obj[f.name]
            kwargs[f.name] = (
                int(value) if f.name in ("t_boot_ns", "age_ns") else float_or_nan(value)
            )
    return VehiclePose(**kwargs)


# --------------------------------------------------------------------------------- holes


def holes_record(
    holes: Sequence[Any], tiers: Mapping[int, str] | None = None, gate: Any = None
) -> dict[str, Any]:
    """The ``/holes`` record: ``{"holes": [...], "gate": {...}}``.

    holes : records or mappings with at least ``lat_deg`` and ``lon_deg`` (and ``id`` when
        ``tiers`` is given). tiers : hole id -> the tier the vehicle gave it (``announced``,
        ``review``, ``candidate``), written as each hole's ``tier`` (missing ids:
        ``candidate``). gate : the :class:`geotag.AnnounceGate` that decided the tiers; its
        thresholds are written as ``gate`` (logs without it predate recorded tiers).
    """
    records = [jsonable(h) for h in holes]
    for rec in records:
        if not isinstance(rec, dict) or "lat_deg" not in rec or "lon_deg" not in rec:
            raise InputError("each hole needs lat_deg and lon_deg fields")
        if tiers is not None:
            rec["tier"] = tiers.get(rec.get("id", -1), "candidate")
    doc: dict[str, Any] = {"holes": records}
    if gate is not None:
        doc["gate"] = jsonable(gate)
    return doc


def holes_geojson_message(holes: Sequence[Mapping[str, Any]]) -> GeoJSON:
    """``foxglove.GeoJSON`` FeatureCollection: one Point (lon, lat order) per hole; the
    hole's other fields become the feature's properties."""
    features = []
    for hole in holes:
        props = {k: v for k, v in hole.items() if k not in ("lat_deg", "lon_deg")}
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": [hole["lon_deg"], hole["lat_deg"]]},
                "properties": props,
            }
        )
    doc = {"type": "FeatureCollection", "features": features}
    return GeoJSON(geojson=json.dumps(doc, separators=(",", ":"), allow_nan=False))


# ------------------------------------------------------------------------------- MAVLink


def mavlink_header(packet: bytes) -> tuple[int, int, int]:
    """(msgid, sysid, compid) from a raw MAVLink v1 (0xFE) or v2 (0xFD) packet; -1s when
    the bytes are not a MAVLink packet."""
    if len(packet) >= 10 and packet[0] == 0xFD:
        return (int.from_bytes(packet[7:10], "little"), packet[5], packet[6])
    if len(packet) >= 6 and packet[0] == 0xFE:
        return (packet[5], packet[3], packet[4])
    return (-1, -1, -1)


def mavlink_json(packet: bytes, name: str) -> dict[str, Any]:
    msgid, sysid, compid = mavlink_header(packet)
    return {
        "msgid": msgid,
        "name": name,
        "sysid": sysid,
        "compid": compid,
        "data": base64.b64encode(packet).decode("ascii"),
    }
