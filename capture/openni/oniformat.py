"""The ``.oni`` file layout (OpenNI2 ``OniDataRecords``): constants, record types, the
two nodes holescan writes and the encoders of their records. The layout is described in
:mod:`capture.openni.oniwriter`; :mod:`capture.openni.oniscan` reads it back."""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import Final

from holescan.detect import CameraIntrinsics

__all__ = [
    "CAMERA_PROPERTY",
    "DEPTH_NODE",
    "FILE_HEADER",
    "FILE_MAGIC",
    "FILE_VERSION",
    "IMAGE_NODE",
    "MAX_FIELDS_SIZE",
    "MAX_PAYLOAD",
    "NODES",
    "NODE_KINDS",
    "ONI_PIXEL_FORMAT_DEPTH_1_MM",
    "ONI_PIXEL_FORMAT_RGB888",
    "PROPERTY_RECORDS",
    "RECORD_HEADER",
    "RECORD_MAGIC",
    "SEEK_ENTRY",
    "U32_MAX",
    "U64_MAX",
    "NodeSpec",
    "RecordType",
    "encode_record",
    "node_added_record",
    "node_property_records",
]

FILE_MAGIC: Final = b"NI10"
FILE_VERSION: Final = (1, 0, 1, 0)
RECORD_MAGIC: Final = 0x0052494E  # "NIR\0"
FILE_HEADER: Final = struct.Struct("<4sBBHIQI")  # magic, version (u8 u8 u16 u32), max ts, max node
RECORD_HEADER: Final = struct.Struct("<IIIIIQ")  # magic, type, node, fields size, payload, undo pos
SEEK_ENTRY: Final = struct.Struct("<QIQ")  # timestamp us, configuration id, record position
U32_MAX: Final = 0xFFFFFFFF
U64_MAX: Final = 0xFFFFFFFFFFFFFFFF
_CODEC_NONE: Final = int.from_bytes(b"NONE", "little")
MAX_FIELDS_SIZE: Final = 1 << 20
# The player's record buffer holds at most 1600 x 1200 x 3 bytes of payload.
MAX_PAYLOAD: Final = 1600 * 1200 * 3
_MAX_DEPTH_MM: Final = 10000
CAMERA_PROPERTY: Final = "holescanCameraIntrinsics"  # fx, fy, cx, cy as 4 doubles (px)


class RecordType(enum.IntEnum):
    """The record types of OpenNI2's ``OniDataRecords.h``."""

    NODE_ADDED_1_0_0_4 = 0x02
    INT_PROPERTY = 0x03
    REAL_PROPERTY = 0x04
    STRING_PROPERTY = 0x05
    GENERAL_PROPERTY = 0x06
    NODE_REMOVED = 0x07
    NODE_DATA_BEGIN = 0x08
    NODE_STATE_READY = 0x09
    NEW_DATA = 0x0A
    END = 0x0B
    NODE_ADDED_1_0_0_5 = 0x0C
    NODE_ADDED = 0x0D
    SEEK_TABLE = 0x0E


PROPERTY_RECORDS: Final = frozenset(
    {
        RecordType.INT_PROPERTY,
        RecordType.REAL_PROPERTY,
        RecordType.STRING_PROPERTY,
        RecordType.GENERAL_PROPERTY,
    }
)
NODE_KINDS: Final = {1: "device", 2: "depth", 3: "image", 5: "ir"}
ONI_PIXEL_FORMAT_DEPTH_1_MM: Final = 100
ONI_PIXEL_FORMAT_RGB888: Final = 200


@dataclass(frozen=True)
class NodeSpec:
    """One stream (node) as holescan writes it: ids, pixel formats, bytes per pixel."""

    node_id: int
    name: str
    node_type: int
    oni_pixel_format: int
    xn_pixel_format: int  # OpenNI 1: 1 = RGB24, 4 = grayscale 16 bit
    xn_supported_formats: int  # bit field: bit 0 RGB24, bit 3 grayscale 16
    bytes_per_pixel: int


DEPTH_NODE: Final = NodeSpec(1, "Depth", 2, ONI_PIXEL_FORMAT_DEPTH_1_MM, 4, 1 << 3, 2)
IMAGE_NODE: Final = NodeSpec(2, "Image", 3, ONI_PIXEL_FORMAT_RGB888, 1, 1 << 0, 3)
NODES: Final = (DEPTH_NODE, IMAGE_NODE)


# --------------------------------------------------------------------------- encoding


def _string_field(text: str) -> bytes:
    raw = text.encode("ascii") + b"\0"
    return struct.pack("<I", len(raw)) + raw


def encode_record(
    kind: RecordType, node_id: int, fields: bytes = b"", *, payload_size: int = 0, undo: int = 0
) -> bytes:
    size = RECORD_HEADER.size + len(fields)
    return RECORD_HEADER.pack(RECORD_MAGIC, kind, node_id, size, payload_size, undo) + fields


def _general_property(node_id: int, name: str, data: bytes) -> bytes:
    fields = _string_field(name) + struct.pack("<I", len(data)) + data
    return encode_record(RecordType.GENERAL_PROPERTY, node_id, fields)


def _int_property(node_id: int, name: str, value: int) -> bytes:
    fields = _string_field(name) + struct.pack("<IQ", 8, value)
    return encode_record(RecordType.INT_PROPERTY, node_id, fields)


def node_added_record(
    node: NodeSpec, frames: int, min_ts_us: int, max_ts_us: int, seek_table_pos: int
) -> bytes:
    fields = _string_field(node.name) + struct.pack(
        "<IIIQQQ", node.node_type, _CODEC_NONE, frames, min_ts_us, max_ts_us, seek_table_pos
    )
    return encode_record(RecordType.NODE_ADDED, node.node_id, fields)


def node_property_records(node: NodeSpec, camera: CameraIntrinsics, fps: int) -> bytes:
    """The stream properties the player needs, in the order the library's recorder writes them."""
    w, h = camera.width, camera.height
    mode = struct.pack("<III", w, h, fps)
    hfov = 2.0 * math.atan(w / (2.0 * camera.fx))
    vfov = 2.0 * math.atan(h / (2.0 * camera.fy))
    nid = node.node_id
    parts = [
        _int_property(nid, "oniRequiredFrameSize", w * h * node.bytes_per_pixel),
        _int_property(nid, "xnIsGenerating", 1),
    ]
    if node is DEPTH_NODE:
        parts.append(_int_property(nid, "xnDeviceMaxDepth", _MAX_DEPTH_MM))
    parts += [
        _int_property(nid, "xnSupportedMapOutputModesCount", 1),
        _general_property(nid, "xnSupportedMapOutputModes", mode),
        _general_property(nid, "xnMapOutputMode", mode),
        _general_property(
            nid, "xnSupportedPixelFormats", struct.pack("<I", node.xn_supported_formats)
        ),
        _int_property(nid, "xnPixelFormat", node.xn_pixel_format),
        _int_property(nid, "oniPixelFormat", node.oni_pixel_format),
        _general_property(nid, "xnFOV", struct.pack("<dd", hfov, vfov)),
        _int_property(nid, "Cropping", 1),
        # Without xnCropping the player silently drops every frame (FIELD-NOTES.md).
        _general_property(nid, "xnCropping", struct.pack("<iHHHH", 0, 0, 0, 0, 0)),
        _int_property(nid, "Mirror", 1),
        _int_property(nid, "xnMirror", 0),
        # Ignored by OpenNI; lets holescan restore the exact principal point.
        _general_property(
            nid, CAMERA_PROPERTY, struct.pack("<dddd", camera.fx, camera.fy, camera.cx, camera.cy)
        ),
    ]
    return b"".join(parts)
