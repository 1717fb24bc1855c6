"""libOpenNI2 through the ``openni`` bindings: loading the library once, on a thread that
lives as long as the process uses it, its errors, intrinsics from the field of view, and
the copy and pairing of depth and colour frames."""

from __future__ import annotations

import ctypes
import logging
import math
import os
import threading
from collections import deque
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from holescan.capture.errors import SensorError
from holescan.detect import CameraIntrinsics
from holescan.errors import InputError

_log = logging.getLogger(__name__)

__all__ = [
    "FramePairer",
    "RawFrame",
    "camera_from_fov",
    "copy_frame",
    "error_text",
    "openni2_library",
    "openni_error_class",
]

_LIBRARY_NAME: Final = "libOpenNI2.so.0"
_LIBRARY_DIRS: Final = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib/arm-linux-gnueabihf",
    "/usr/lib",
    "/usr/local/lib",
)
_init_lock = threading.Lock()


def openni2_library() -> Any:
    """The ``openni.openni2`` bindings with libOpenNI2 loaded and initialised.

    The first call loads Debian's ``libOpenNI2.so.0`` and initialises OpenNI2 (process
    global); later calls return at once. Safe from several threads.

    Raises
    ------
    SensorError
        The ``openni`` bindings or libOpenNI2 (Debian ``libopenni2-0``) are missing.
    """
    with _init_lock:
        try:
            from openni import openni2
            from openni.utils import InitializationError, OpenNIError
        except ImportError as err:
            raise SensorError("the openni bindings are missing: pip install openni") from err
        if openni2.is_initialized():
            return openni2
        if openni2.loaded_dll_directory is None:
            libdir = next(
                (d for d in _LIBRARY_DIRS if os.path.isfile(os.path.join(d, _LIBRARY_NAME))),
                None,
            )
            if libdir is None:
                raise SensorError(
                    f"{_LIBRARY_NAME} not found in {', '.join(_LIBRARY_DIRS)}: "
                    "apt-get install libopenni2-0"
                )
            openni2._dll_name = _LIBRARY_NAME
            dirs: list[str] = [libdir]
        else:  # loaded before, then unloaded: initialise again
            dirs = [openni2.loaded_dll_directory]
        try:
            openni2.initialize(dirs)
        except (InitializationError, OpenNIError) as err:
            raise SensorError(f"OpenNI2 failed to initialise: {error_text(err)}") from err
        _log.debug("OpenNI2 %s initialised from %s", openni2.get_version(), dirs[0])
        return openni2


def error_text(err: BaseException) -> str:
    """The library's text from an OpenNIError (code, message, logfile) or any exception."""
    if len(err.args) >= 2:
        msg = err.args[1]
        text = msg.decode(errors="replace") if isinstance(msg, bytes) else str(msg)
        return text or f"status {err.args[0]}"
    return str(err)


def openni_error_class() -> type[Exception]:
    """The bindings' ``OpenNIError`` (imported when first needed: the bindings are optional)."""
    from openni.utils import OpenNIError

    return OpenNIError  # type: ignore[no-any-return]


def camera_from_fov(width: int, height: int, hfov: float, vfov: float) -> CameraIntrinsics:
    """Pinhole intrinsics from a field of view: f = W / (2 tan(hfov / 2)), centred.

    hfov, vfov : radians. The principal point is put at the image centre.
    """
    if not (0 < hfov < math.pi and 0 < vfov < math.pi):
        raise InputError(f"field of view must be in (0, pi) rad, got {hfov}, {vfov}")
    return CameraIntrinsics(
        width,
        height,
        width / (2.0 * math.tan(hfov / 2.0)),
        height / (2.0 * math.tan(vfov / 2.0)),
        (width - 1) / 2.0,
        (height - 1) / 2.0,
    )


@dataclass(frozen=True)
class RawFrame:
    """One frame copied out of OpenNI2."""

    index: int  # OpenNI frameIndex
    ts_us: int  # device clock
    t_mono_ns: int
    pixels: npt.NDArray[np.uint8] | npt.NDArray[np.uint16]


def copy_frame(frame: Any, width: int, height: int, channels: int, t_mono_ns: int) -> RawFrame:
    """Copy an OpenNI VideoFrame's pixels (honouring its stride) into a new array."""
    if frame.width != width or frame.height != height:
        raise ValueError(f"frame is {frame.width}x{frame.height}, stream is {width}x{height}")
    itemsize = 2 if channels == 1 else 1
    row = width * channels * itemsize
    stride = frame.stride or row
    if stride < row or frame.dataSize < stride * (height - 1) + row or not frame.data:
        raise ValueError(f"frame buffer of {frame.dataSize} bytes is too small")
    buf = (ctypes.c_uint8 * frame.dataSize).from_address(frame.data)
    flat = np.frombuffer(buf, dtype=np.uint8)
    rows = np.lib.stride_tricks.as_strided(flat, shape=(height, row), strides=(stride, 1))
    if channels == 1:
        pixels: Any = rows.copy().view("<u2").astype(np.uint16, copy=False)
    else:
        pixels = rows.reshape(height, width, channels).copy()
    return RawFrame(int(frame.frameIndex), int(frame.timestamp), t_mono_ns, pixels)


class FramePairer:
    """Match depth and colour frames whose timestamps lie within ``tolerance_us``."""

    def __init__(self, tolerance_us: int) -> None:
        self.tolerance_us = tolerance_us
        self.depth: deque[RawFrame] = deque()
        self.image: deque[RawFrame] = deque()
        self.dropped = 0

    def push(self, raw: RawFrame, *, is_depth: bool) -> list[tuple[RawFrame, RawFrame]]:
        (self.depth if is_depth else self.image).append(raw)
        pairs = []
        while self.depth and self.image:
            d, c = self.depth[0], self.image[0]
            if abs(d.ts_us - c.ts_us) <= self.tolerance_us:
                pairs.append((self.depth.popleft(), self.image.popleft()))
            else:  # the older one has no partner: drop it
                (self.depth if d.ts_us < c.ts_us else self.image).popleft()
                self.dropped += 1
        return pairs
