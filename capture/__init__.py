"""The flight side: frame sources, telemetry, the MCAP flight log and the capture daemon."""

from capture._clock import ClockEstimate, ClockSync, ClockUnavailable
from capture._errors import SensorError
from capture._frame import Frame, FrameSource
from capture._mavlink import (
    DEFAULT_RATES_HZ,
    Telemetry,
    TelemetryError,
    TelemetryStats,
    TelemetryTimeoutError,
)
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
from capture._posebuffer import AttitudeSample, GpsFix, PoseBuffer, PoseUnavailable, PositionSample
from capture._simautopilot import SimAutopilot, SimPath
from capture._usb import UsbDeviceInfo, find_xtion, reset_xtion

__all__ = [
    "DEFAULT_RATES_HZ",
    "AttitudeSample",
    "ClockEstimate",
    "ClockSync",
    "ClockUnavailable",
    "FlightLogError",
    "FlightLogWriter",
    "Frame",
    "FrameSource",
    "GpsFix",
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
    "PoseBuffer",
    "PoseUnavailable",
    "PositionSample",
    "RecoveryReport",
    "SensorError",
    "SimAutopilot",
    "SimPath",
    "Telemetry",
    "TelemetryError",
    "TelemetryStats",
    "TelemetryTimeoutError",
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
