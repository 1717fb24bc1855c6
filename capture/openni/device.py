"""Frame sources through the real OpenNI2 library: the live Xtion and ``.oni`` playback.

Both open a depth (DEPTH_1_MM) and a colour (RGB888) stream on one OpenNI2 device, copy
each frame out of the library's buffer, and pair depth with colour by timestamp (within
half a frame period) into :class:`detect.Frame` records.

The library's pitfalls (FIELD-NOTES.md, Debian libopenni2-0 2.2.0.33) shape this module:
``seek()`` never returns (never called here); ``read_frame()`` blocks forever at the end of
a file (always ``wait_for_any_stream`` with a timeout first, and stop at the frame count);
playback speed 0 drops frames, and speed 1.0 can overwrite the last frame with the first
one of the replay (measured): files are stepped manually (speed -1, one record per wait) and
paced in Python when real time is wanted; closing
the device with streams open segfaults (stop and close the streams, then the device).
OpenNI2 is initialised once per process, lazily, on the first source opened.
"""

from __future__ import annotations

import abc
import dataclasses
import logging
import math
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from holescan.capture._usb import XTION_VENDOR_ID, find_xtion
from holescan.capture.errors import SensorError
from holescan.capture.openni.library import (
    FramePairer,
    camera_from_fov,
    copy_frame,
    error_text,
    openni2_library,
    openni_error_class,
)
from holescan.capture.openni.oniformat import ONI_PIXEL_FORMAT_DEPTH_1_MM, ONI_PIXEL_FORMAT_RGB888
from holescan.capture.openni.oniscan import OniInfo, scan_oni
from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import HolescanError, InputError

__all__ = ["OniSource", "OpenNI2Device"]

_log = logging.getLogger(__name__)


class _OpenNISource(abc.ABC):
    """Depth + colour streams of one OpenNI2 device, read and paired into Frames."""

    camera: CameraIntrinsics
    _error: type[HolescanError] = SensorError

    def __init__(self, timeout_s: float) -> None:
        if timeout_s <= 0:
            raise InputError(f"timeout_s must be > 0, got {timeout_s}")
        self.timeout_s = timeout_s
        self._lib: Any = None
        self._device: Any = None
        self._depth: Any = None
        self._color: Any = None
        self._size = (0, 0)
        self._fps = 30
        self._expected: tuple[int, int] | None = None  # frames to read (depth, colour)
        self._first_index: int | None = None
        self._realtime = False
        self.frames_dropped = 0

    # -- subclass hooks
    @abc.abstractmethod
    def _describe(self) -> str:
        """What the source reads, for messages."""

    @abc.abstractmethod
    def _open_device(self, lib: Any) -> Any:
        """Open the OpenNI2 device (a file or a sensor)."""

    @abc.abstractmethod
    def _configure(self, device: Any, depth: Any, color: Any) -> None:
        """Set up the device and its depth and colour streams before they start."""

    # -- lifecycle
    def __enter__(self) -> _OpenNISource:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:
        """Open the device and start both streams (called by ``with``)."""
        if self._device is not None:
            return
        lib = openni2_library()
        openni_error = openni_error_class()
        device = self._open_device(lib)
        self._lib, self._device = lib, device
        try:
            self._depth = device.create_depth_stream()
            self._color = device.create_color_stream()
            if self._depth is None or self._color is None:
                raise self._error(f"{self._describe()} lacks a depth or a colour stream")
            self._configure(device, self._depth, self._color)
            self._depth.start()
            self._color.start()
        except openni_error as err:
            self.close()
            raise self._error(f"{self._describe()}: {error_text(err)}") from err
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Stop and close the streams, then the device (this order never crashed)."""
        lib = self._lib
        # After OpenNI2 was unloaded (at interpreter exit) every handle is already closed.
        alive = lib is not None and lib.is_initialized()
        openni_error = openni_error_class() if lib is not None else Exception
        for stream in (self._depth, self._color):
            if stream is not None and alive and stream:  # a false handle is closed
                try:
                    stream.stop()
                    stream.close()
                except openni_error as err:
                    _log.warning("closing a stream of %s: %s", self._describe(), error_text(err))
        self._depth = self._color = None
        if self._device is not None and alive and self._device:
            try:
                self._device.close()
            except openni_error as err:
                _log.warning("closing %s: %s", self._describe(), error_text(err))
        self._device = None

    def _check_modes(self) -> None:
        """Both streams are the same size and in the pixel formats Frame needs."""
        dm, cm = self._depth.get_video_mode(), self._color.get_video_mode()
        if int(dm.pixelFormat.value) != ONI_PIXEL_FORMAT_DEPTH_1_MM:
            raise self._error(f"{self._describe()}: depth is {dm.pixelFormat}, need DEPTH_1_MM")
        if int(cm.pixelFormat.value) != ONI_PIXEL_FORMAT_RGB888:
            raise self._error(f"{self._describe()}: colour is {cm.pixelFormat}, need RGB888")
        if (dm.resolutionX, dm.resolutionY) != (cm.resolutionX, cm.resolutionY):
            raise self._error(
                f"{self._describe()}: depth {dm.resolutionX}x{dm.resolutionY} and colour "
                f"{cm.resolutionX}x{cm.resolutionY} differ (depth not registered to colour)"
            )
        self._size = (int(dm.resolutionX), int(dm.resolutionY))
        self._fps = int(cm.fps) if cm.fps > 0 else 30

    def _fov_camera(self) -> CameraIntrinsics:
        w, h = self._size
        return camera_from_fov(
            w, h, self._color.get_horizontal_fov(), self._color.get_vertical_fov()
        )

    # -- frames
    def __iter__(self) -> Iterator[Frame]:
        """Frames in order; iterate once per ``open`` (a file ends after its last frame)."""
        if self._device is None:
            raise self._error(f"{self._describe()} is not open: use it in a with block")
        lib, depth, color = self._lib, self._depth, self._color
        openni_error = openni_error_class()
        w, h = self._size
        pairer = FramePairer(tolerance_us=500_000 // self._fps)
        counts = [0, 0]
        extra = 0
        clock_start: tuple[int, int] | None = None  # (monotonic ns, sensor us) for pacing
        while (
            self._expected is None or counts[0] < self._expected[0] or counts[1] < self._expected[1]
        ):
            try:
                ready = lib.wait_for_any_stream([depth, color], self.timeout_s)
            except openni_error as err:
                raise self._error(f"{self._describe()}: {error_text(err)}") from err
            if ready is None:
                raise self._stalled(counts)
            is_depth = ready is depth
            try:
                vf = ready.read_frame()
            except openni_error as err:
                raise self._error(f"{self._describe()}: {error_text(err)}") from err
            t_mono_ns = time.monotonic_ns()
            try:
                raw = copy_frame(vf, w, h, 1 if is_depth else 3, t_mono_ns)
            except ValueError as err:
                raise self._error(f"{self._describe()}: {err}") from err
            finally:
                vf.close()
            k = 0 if is_depth else 1
            if self._expected is not None and counts[k] >= self._expected[k]:
                extra += 1  # a replay after the end: the other stream is short
                if extra > 4:
                    raise self._stalled(counts)
                continue
            if self._expected is not None and raw.index != counts[k] + 1:
                raise self._error(
                    f"{self._describe()}: OpenNI2 delivered {'depth' if is_depth else 'colour'} "
                    f"frame {raw.index} where {counts[k] + 1} was due"
                )
            counts[k] += 1
            if is_depth and self._first_index is None:
                self._first_index = raw.index
            for d, c in pairer.push(raw, is_depth=is_depth):
                if self._realtime:
                    if clock_start is None:
                        clock_start = (time.monotonic_ns(), d.ts_us)
                    due_ns = clock_start[0] + (d.ts_us - clock_start[1]) * 1000
                    time.sleep(max(0, due_ns - time.monotonic_ns()) / 1e9)
                    d = dataclasses.replace(d, t_mono_ns=time.monotonic_ns())
                yield Frame(
                    index=d.index - (self._first_index or 0),
                    rgb=c.pixels,  # type: ignore[arg-type]
                    depth=d.pixels,  # type: ignore[arg-type]
                    t_mono_ns=d.t_mono_ns,
                    t_sensor_ns=d.ts_us * 1000,
                )
            if pairer.dropped != self.frames_dropped:
                self.frames_dropped = pairer.dropped
                _log.debug("%s: %d unpaired frames dropped", self._describe(), pairer.dropped)

    def _stalled(self, counts: list[int]) -> HolescanError:
        return self._error(
            f"{self._describe()}: no frame for {self.timeout_s:g} s "
            f"(after {counts[0]} depth and {counts[1]} colour frames)"
        )


class OniSource(_OpenNISource):
    """Play an ``.oni`` recording through libOpenNI2, every frame in order.

    A :class:`detect.FrameSource`: use as a context manager and iterate; iteration ends
    after the last frame. The file is checked first (:func:`capture.scan_oni`), so a
    missing, truncated or corrupt file raises :class:`InputError` before the library sees
    it.

    Parameters
    ----------
    path : str or Path
        The recording: a depth stream (DEPTH_1_MM) and a colour stream (RGB888) of the same
        size, depth registered to colour.
    timeout_s : float
        How long to wait for the library's next frame before declaring the file broken.
    realtime : bool
        Pace frames at the recording's timestamps instead of delivering them as fast as
        they are read. No frame is dropped either way.

    Attributes
    ----------
    camera : CameraIntrinsics
        Exact intrinsics when holescan wrote the file; else from the colour stream's field
        of view, f = W / (2 tan(hfov / 2)), principal point at the centre.
    info : OniInfo
        What :func:`scan_oni` found in the file.

    Frames: ``index`` = OpenNI frame id - 1; ``t_sensor_ns`` = the depth frame's timestamp
    (us) x 1000; ``t_mono_ns`` = ``time.monotonic_ns()`` when the depth frame was read (or,
    with ``realtime``, when it was due).
    """

    _error = InputError

    def __init__(
        self, path: str | os.PathLike[str], *, timeout_s: float = 2.0, realtime: bool = False
    ) -> None:
        super().__init__(timeout_s)
        self.path = Path(path)
        self.info: OniInfo = scan_oni(self.path)
        self._realtime = realtime
        depth, image = self.info.stream("depth"), self.info.stream("image")
        self._exact_camera = image.camera or depth.camera
        self.camera = self._exact_camera or _scan_fov_camera(self.info)

    def __enter__(self) -> OniSource:
        self.open()
        return self

    def _describe(self) -> str:
        return str(self.path)

    def _open_device(self, lib: Any) -> Any:
        try:
            return lib.Device.open_file(os.fsencode(self.path))
        except openni_error_class() as err:
            raise InputError(f"{self.path}: OpenNI2 cannot play it: {error_text(err)}") from err

    def _configure(self, device: Any, depth: Any, color: Any) -> None:
        device.playback.repeat = True  # stop at the frame count instead (FIELD-NOTES.md)
        device.playback.speed = -1.0  # manual: one record per wait, none dropped
        self._check_modes()
        n_depth = int(depth.get_number_of_frames())
        n_color = int(color.get_number_of_frames())
        found = (self.info.stream("depth").frames_found, self.info.stream("image").frames_found)
        if (n_depth, n_color) != found:
            _log.warning(
                "%s: OpenNI2 counts %s frames, the file holds %s",
                self.path,
                (n_depth, n_color),
                found,
            )
        self._expected = (min(n_depth, found[0]), min(n_color, found[1]))
        if self._exact_camera is None:
            self.camera = self._fov_camera()


def _scan_fov_camera(info: OniInfo) -> CameraIntrinsics:
    s = info.stream("image")
    if not (s.width > 0 and s.height > 0 and math.isfinite(s.hfov) and math.isfinite(s.vfov)):
        raise InputError(f"{info.path}: the colour stream has no video mode or field of view")
    return camera_from_fov(s.width, s.height, s.hfov, s.vfov)


class OpenNI2Device(_OpenNISource):
    """The live Asus Xtion through OpenNI2: depth registered to colour, frame sync on.

    A :class:`detect.FrameSource`: use as a context manager and iterate; iteration runs
    until the source is closed.

    Parameters
    ----------
    uri : str, optional
        OpenNI2 device URI (e.g. ``"1d27/0601@1/5"``); None opens the first sensor, after
        checking on USB that an Xtion is attached.
    width, height, fps : int
        Video mode of both streams (the Xtion: 640x480 or 320x240 at 30 fps).
    timeout_s : float
        A gap of this long without frames raises :class:`SensorError` (the daemon then
        resets the sensor with :func:`capture.reset_xtion` and opens it again).

    Attributes
    ----------
    camera : CameraIntrinsics
        From the colour stream's field of view (depth is registered to colour).

    Frames: ``index`` counts depth frames from the first one (gaps = dropped frames);
    ``t_sensor_ns`` = the depth frame's device timestamp (us) x 1000; ``t_mono_ns`` =
    ``time.monotonic_ns()`` when the depth frame was read.
    """

    _error = SensorError

    def __init__(
        self,
        uri: str | None = None,
        *,
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        timeout_s: float = 2.0,
    ) -> None:
        super().__init__(timeout_s)
        self.uri = uri
        self._mode = (width, height, fps)
        self.camera = CameraIntrinsics.xtion(width, height)  # replaced from the FOV on open

    def __enter__(self) -> OpenNI2Device:
        self.open()
        return self

    def _describe(self) -> str:
        return f"Xtion {self.uri}" if self.uri else "Xtion"

    def open(self) -> None:
        """Check USB for an Xtion (when no ``uri``), open it and start both streams."""
        if self._device is None and self.uri is None and not find_xtion():
            raise SensorError(
                f"no Xtion found on USB (vendor {XTION_VENDOR_ID:#06x}): check its cable and "
                "power; `lsusb -d 1d27:` should list it"
            )
        super().open()

    def _open_device(self, lib: Any) -> Any:
        try:
            device = lib.Device(self.uri.encode() if self.uri else None)
        except openni_error_class() as err:
            raise SensorError(f"OpenNI2 cannot open {self._describe()}: {error_text(err)}") from err
        if device.is_file():
            device.close()
            raise InputError(f"{self.uri} is a recording: use OniSource")
        return device

    def _configure(self, device: Any, depth: Any, color: Any) -> None:
        lib = self._lib
        w, h, fps = self._mode
        for stream, fmt in ((depth, ONI_PIXEL_FORMAT_DEPTH_1_MM), (color, ONI_PIXEL_FORMAT_RGB888)):
            modes = stream.get_sensor_info().videoModes
            match = [
                m
                for m in modes
                if (m.resolutionX, m.resolutionY, m.fps) == (w, h, fps)
                and int(m.pixelFormat.value) == fmt
            ]
            if not match:
                have = sorted(
                    {(m.resolutionX, m.resolutionY, m.fps, int(m.pixelFormat.value)) for m in modes}
                )
                raise SensorError(f"{self._describe()} has no {w}x{h}@{fps} mode {fmt}: {have}")
            cur = stream.get_video_mode()
            if (cur.resolutionX, cur.resolutionY, cur.fps, int(cur.pixelFormat.value)) != (
                w,
                h,
                fps,
                fmt,
            ):
                stream.set_video_mode(match[0])
            if stream.is_property_supported(lib.c_api.ONI_STREAM_PROPERTY_MIRRORING):
                stream.set_mirroring_enabled(False)
        mode = lib.IMAGE_REGISTRATION_DEPTH_TO_COLOR
        if device.is_image_registration_mode_supported(mode):
            device.set_image_registration_mode(mode)
        else:
            _log.warning("%s cannot register depth to colour", self._describe())
        device.set_depth_color_sync_enabled(True)
        self._check_modes()
        self.camera = self._fov_camera()
