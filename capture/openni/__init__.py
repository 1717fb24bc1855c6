"""OpenNI2: the Asus Xtion and ``.oni`` recordings.

* :mod:`~capture.openni.device`: the frame sources through libOpenNI2, the live
  :class:`OpenNI2Device` and :class:`OniSource` playback;
* :mod:`~capture.openni.library`: loading libOpenNI2 once, its errors, copying and pairing
  its depth and colour frames;
* :mod:`~capture.openni.oniformat`: the ``.oni`` file layout; :mod:`~capture.openni.oniwriter`
  writes it in pure Python (:class:`OniWriter`, :func:`export_oni` of a flight log) and
  :mod:`~capture.openni.oniscan` checks a file before playback (:func:`scan_oni`).
"""

from holescan.capture.openni.device import OniSource, OpenNI2Device
from holescan.capture.openni.library import (
    FramePairer,
    RawFrame,
    camera_from_fov,
    openni2_library,
)
from holescan.capture.openni.oniscan import OniInfo, OniStreamInfo, scan_oni
from holescan.capture.openni.oniwriter import OniWriter, export_oni, write_oni

__all__ = [
    "FramePairer",
    "OniInfo",
    "OniSource",
    "OniStreamInfo",
    "OniWriter",
    "OpenNI2Device",
    "RawFrame",
    "camera_from_fov",
    "export_oni",
    "openni2_library",
    "scan_oni",
    "write_oni",
]
