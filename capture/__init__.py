"""The flight side: frame sources, telemetry, the MCAP flight log and the capture daemon."""

from capture._errors import SensorError
from capture._frame import Frame, FrameSource
from capture._oni import OniInfo, OniStreamInfo, OniWriter, scan_oni, write_oni
from capture._openni import OniSource, OpenNI2Device, camera_from_fov
from capture._usb import UsbDeviceInfo, find_xtion, reset_xtion

__all__ = [
    "Frame",
    "FrameSource",
    "OniInfo",
    "OniSource",
    "OniStreamInfo",
    "OniWriter",
    "OpenNI2Device",
    "SensorError",
    "UsbDeviceInfo",
    "camera_from_fov",
    "find_xtion",
    "reset_xtion",
    "scan_oni",
    "write_oni",
]
