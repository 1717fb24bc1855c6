"""The MCAP flight log: everything a flight saw, written as it happens, read back, repaired.

Modules, from the bytes up:

* :mod:`~flightlog.format`: the MCAP format written down once (magic, record
  framing, footer, chunk fields, summary section, compression names);
* :mod:`~flightlog.schemas`: which topic holds what, and the conversions of
  holescan's records to Foxglove protobuf / JSON messages and back;
  :mod:`~flightlog.images` how the pixels are stored (JPEG/PNG colour, zstd/PNG
  depth as ``foxglove.CompressedImage``, or raw);
  :mod:`~flightlog.detections` and :mod:`~flightlog.metadata` the same for
  detections and the ``holescan.mount`` record;
* :mod:`~flightlog.mcapfile`: :class:`McapFile`, the one lifecycle of an MCAP file
  being written (create, lazy schemas and channels, fsync, ``.part`` and rename);
* :mod:`~flightlog.writer`: :class:`FlightLogWriter`, the flight's writer thread
  (its :mod:`~flightlog.options`: :class:`LogOptions`, :class:`WriterStats`);
* :mod:`~flightlog.scan`: the damage-tolerant front-to-back record scanner;
* :mod:`~flightlog.reader`: typed records back (:func:`read_flight_log`,
  :class:`McapSource`);
* :mod:`~flightlog.layout`: a log's chunk index and reading one chunk (for work
  split along chunks);
* :mod:`~flightlog.diskspace` (:class:`DiskSpace`) and :mod:`~flightlog.storage`
  (finished logs in a folder, their measured rate, the retention rule);
* :mod:`~flightlog.info` (:func:`log_info`) and :mod:`~flightlog.recover`
  (:func:`recover_log`): what a log holds, and repairing one.
"""

from holescan.flightlog.detections import annotations_message, decode_detection, detection_json
from holescan.flightlog.diskspace import DiskSpace, SystemDiskSpace
from holescan.flightlog.errors import (
    ChunkDamagedError,
    FlightLogError,
    RecordError,
    TruncatedLogError,
)
from holescan.flightlog.images import ImageEncoder, decode_compressed
from holescan.flightlog.info import LogInfo, TopicInfo, log_info
from holescan.flightlog.layout import (
    ChunkSpan,
    LogLayout,
    decode_messages,
    open_log,
    read_chunk,
    read_log_layout,
)
from holescan.flightlog.mcapfile import JsonSchema, McapFile
from holescan.flightlog.metadata import errors_from_metadata, mount_from_metadata, mount_metadata
from holescan.flightlog.options import LogOptions, WriterStats, log_file_path
from holescan.flightlog.reader import (
    LoggedCalibration,
    LoggedDetections,
    LoggedFrame,
    LoggedHealth,
    LoggedHoles,
    LoggedMavlink,
    LoggedPose,
    LogRecord,
    McapSource,
    read_camera,
    read_flight_log,
)
from holescan.flightlog.recover import RecoveryReport, recover_log
from holescan.flightlog.scan import DamagedRegion, ScanState, scan_records
from holescan.flightlog.schemas import (
    JSON_SCHEMAS,
    TOPIC_CAMERA_INFO,
    TOPIC_COLOR,
    TOPIC_DEPTH,
    TOPIC_DETECTION_ANNOTATIONS,
    TOPIC_DETECTIONS,
    TOPIC_FRAME_INFO,
    TOPIC_HEALTH,
    TOPIC_HOLES,
    TOPIC_HOLES_GEOJSON,
    TOPIC_LOCATION,
    TOPIC_MAVLINK_RAW,
    TOPIC_POSE,
    TOPIC_TF,
    holes_geojson_message,
    jsonable,
    to_json,
)
from holescan.flightlog.storage import (
    FlightLogSet,
    flight_logs,
    measured_rate,
    remove_oldest_finished,
)
from holescan.flightlog.writer import FlightLogWriter

__all__ = [
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
    "ChunkDamagedError",
    "ChunkSpan",
    "DamagedRegion",
    "DiskSpace",
    "FlightLogError",
    "FlightLogSet",
    "FlightLogWriter",
    "ImageEncoder",
    "JsonSchema",
    "LogInfo",
    "LogLayout",
    "LogOptions",
    "LogRecord",
    "LoggedCalibration",
    "LoggedDetections",
    "LoggedFrame",
    "LoggedHealth",
    "LoggedHoles",
    "LoggedMavlink",
    "LoggedPose",
    "McapFile",
    "McapSource",
    "RecordError",
    "RecoveryReport",
    "ScanState",
    "SystemDiskSpace",
    "TopicInfo",
    "TruncatedLogError",
    "WriterStats",
    "annotations_message",
    "decode_compressed",
    "decode_detection",
    "decode_messages",
    "detection_json",
    "errors_from_metadata",
    "flight_logs",
    "holes_geojson_message",
    "jsonable",
    "log_file_path",
    "log_info",
    "measured_rate",
    "mount_from_metadata",
    "mount_metadata",
    "open_log",
    "read_camera",
    "read_chunk",
    "read_flight_log",
    "read_log_layout",
    "recover_log",
    "remove_oldest_finished",
    "scan_records",
    "to_json",
]
