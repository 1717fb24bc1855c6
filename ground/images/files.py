"""Reading and writing the PNG pairs of a frame: 8-bit RGB and 16-bit depth in millimetres.

Files are read and written as bytes here and decoded/encoded in memory (``cv2.imdecode`` /
``cv2.imencode``): OpenCV's own file functions crash on a file name that is not UTF-8, and
libpng's warnings, written straight to the process's stderr, are kept off it. Written
through the output-path rule (:func:`outputs.atomic_output`): an existing file is refused
unless ``force``, an input is never written, a crash leaves no half-written image.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError
from holescan.outputs import PathLike, atomic_output

__all__ = ["read_camera", "read_depth", "read_rgb", "write_depth", "write_rgb"]


@contextlib.contextmanager
def _quiet_native_stderr() -> Iterator[None]:
    """Send what C libraries (libpng) write to file descriptor 2 to /dev/null meanwhile."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):
        yield
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 2)
        finally:
            os.close(devnull)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _read_bytes(path: Path) -> bytes:
    p = Path(path)
    try:
        return p.read_bytes()
    except FileNotFoundError as err:
        raise InputError(f"{_shown(p)}: no such file") from err
    except IsADirectoryError as err:
        raise InputError(f"{_shown(p)}: is a folder, not an image") from err
    except OSError as err:
        raise InputError(f"{_shown(p)}: cannot read: {err.strerror}") from err


def _shown(p: Path) -> str:
    """The path as text that can be printed (undecodable bytes as escapes)."""
    return os.fsencode(p).decode("utf-8", "backslashreplace")


def _decode(path: Path) -> npt.NDArray[Any]:
    data = _read_bytes(path)
    with _quiet_native_stderr():
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if img is None:
        raise InputError(f"{_shown(Path(path))}: not a readable image")
    return np.asarray(img)


def read_rgb(path: Path) -> npt.NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB from an 8-bit colour image file (PNG, JPEG...)."""
    img = _decode(path)
    if img.dtype != np.uint8:
        raise InputError(f"{_shown(Path(path))}: colour image must be 8-bit, got {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    else:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img, dtype=np.uint8)


def read_depth(path: Path) -> npt.NDArray[np.uint16]:
    """(H, W) uint16 depth in millimetres (0 = no reading) from a 16-bit single-channel PNG."""
    img = _decode(path)
    name = _shown(Path(path))
    if img.ndim != 2:
        raise InputError(
            f"{name}: depth must be a single-channel image, got {img.shape[2]} channels"
        )
    if img.dtype != np.uint16:
        raise InputError(
            f"{name}: depth must be a 16-bit PNG in millimetres, got {img.dtype} "
            "(an 8-bit or float image is not metric depth)"
        )
    return np.asarray(img, dtype=np.uint16)


def _encode_to(
    path: Path, img: npt.NDArray[Any], *, inputs: Iterable[PathLike] = (), force: bool = False
) -> None:
    p = Path(path)
    suffix = p.suffix.lower() or ".png"
    try:
        with _quiet_native_stderr():
            ok, buf = cv2.imencode(suffix, img)
    except cv2.error as err:
        raise InputError(f"{_shown(p)}: cannot encode the image as {suffix!r}") from err
    if not ok:
        raise InputError(f"{_shown(p)}: cannot encode the image as {suffix!r}")
    with atomic_output(p, inputs=inputs, force=force) as f:
        f.write(buf.tobytes())


def write_rgb(
    path: Path,
    rgb: npt.NDArray[np.uint8],
    *,
    inputs: Iterable[PathLike] = (),
    force: bool = False,
) -> None:
    """(H, W, 3) uint8 RGB to an image file (format by extension; PNG if none)."""
    _encode_to(path, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), inputs=inputs, force=force)


def write_depth(path: Path, depth: npt.NDArray[np.uint16], *, force: bool = False) -> None:
    """(H, W) uint16 depth in millimetres to a 16-bit PNG."""
    if depth.dtype != np.uint16 or depth.ndim != 2:
        raise InputError(f"depth to write must be (H, W) uint16, got {depth.shape} {depth.dtype}")
    _encode_to(path, depth, force=force)


def read_camera(path: Path) -> CameraIntrinsics:
    """Camera intrinsics from a ``camera.json``: width, height, fx, fy, cx, cy[, depth_unit_m]."""
    import json

    name = _shown(Path(path))
    try:
        raw = json.loads(_read_bytes(path))
    except (ValueError, RecursionError) as err:
        raise InputError(f"{name}: not a readable JSON camera file ({err})") from err
    keys = ("width", "height", "fx", "fy", "cx", "cy")
    if not isinstance(raw, dict) or any(k not in raw for k in keys):
        raise InputError(f"{name}: camera file needs keys {', '.join(keys)}")
    try:
        w, h = raw["width"], raw["height"]
        if isinstance(w, bool) or isinstance(h, bool) or int(w) != w or int(h) != h:
            raise ValueError(f"width and height must be whole numbers, got {w!r}, {h!r}")
        return CameraIntrinsics(
            int(w),
            int(h),
            float(raw["fx"]),
            float(raw["fy"]),
            float(raw["cx"]),
            float(raw["cy"]),
            float(raw.get("depth_unit_m", 0.001)),
        )
    except (TypeError, ValueError, OverflowError) as err:
        raise InputError(f"{name}: bad camera values ({err})") from err
