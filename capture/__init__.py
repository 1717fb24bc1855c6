"""The flight side: frame sources, telemetry, the MCAP flight log and the capture daemon."""

from capture._errors import SensorError
from capture._frame import Frame, FrameSource
from capture._mcaplog import FlightLogError, FlightLogWriter, LogOptions, WriterStats
from capture._mcapread import (
    LoggedCalibration,
    LoggedDetections,
    LoggedFrame,
    LoggedHealth,
    LoggedHoles,
    LoggedMavlink,
    LoggedPose,
    LogRecord,
    McapSource,
    TruncatedLogError,
    read_flight_log,
)
from capture._mcaptools import LogInfo, RecoveryReport, TopicInfo, log_info, recover_log
from capture._oni import OniInfo, OniStreamInfo, OniWriter, export_oni, scan_oni, write_oni
from capture._openni import OniSource, OpenNI2Device, camera_from_fov
from capture._usb import UsbDeviceInfo, find_xtion, reset_xtion

__all__ = [
    "FlightLogError",
    "FlightLogWriter",
    "Frame",
    "FrameSource",
    "LogInfo",
    "LogOptions",
    "LogRecord",
    "LoggedCalibration",
    "LoggedDetections",
    "LoggedFrame",
    "LoggedHealth",
    "LoggedHoles",
    "LoggedMavlink",
    "LoggedPose",
    "McapSource",
    "OniInfo",
    "OniSource",
    "OniStreamInfo",
    "OniWriter",
    "OpenNI2Device",
    "RecoveryReport",
    "SensorError",
    "TopicInfo",
    "TruncatedLogError",
    "UsbDeviceInfo",
    "WriterStats",
    "camera_from_fov",
    "export_oni",
    "find_xtion",
    "log_info",
    "read_flight_log",
    "recover_log",
    "reset_xtion",
    "scan_oni",
    "write_oni",
]
