"""Reading and writing the PNG pairs of a frame: 8-bit RGB and 16-bit depth in millimetres."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from detect import CameraIntrinsics
from holescan_errors import InputError


def read_rgb(path: Path) -> npt.NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB from an 8-bit colour image file (PNG, JPEG...)."""
    if not Path(path).is_file():
        raise InputError(f"{path}: no such file")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(f"{path}: not a readable image")
    if img.dtype != np.uint8:
        raise InputError(f"{path}: colour image must be 8-bit, got {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    else:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img)


def read_depth(path: Path) -> npt.NDArray[np.uint16]:
    """(H, W) uint16 depth in millimetres (0 = no reading) from a 16-bit single-channel PNG."""
    if not Path(path).is_file():
        raise InputError(f"{path}: no such file")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(f"{path}: not a readable image")
    if img.ndim != 2:
        raise InputError(
            f"{path}: depth must be a single-channel image, got {img.shape[2]} channels"
        )
    if img.dtype != np.uint16:
        raise InputError(
            f"{path}: depth must be a 16-bit PNG in millimetres, got {img.dtype} "
            "(an 8-bit or float image is not metric depth)"
        )
    return img


def write_rgb(path: Path, rgb: npt.NDArray[np.uint8]) -> None:
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise InputError(f"{path}: could not write image")


def write_depth(path: Path, depth: npt.NDArray[np.uint16]) -> None:
    if depth.dtype != np.uint16 or depth.ndim != 2:
        raise InputError(f"depth to write must be (H, W) uint16, got {depth.shape} {depth.dtype}")
    if not cv2.imwrite(str(path), depth):
        raise InputError(f"{path}: could not write image")


def read_camera(path: Path) -> CameraIntrinsics:
    """Camera intrinsics from a ``camera.json``: width, height, fx, fy, cx, cy[, depth_unit_m]."""
    import json

    try:
        raw = json.loads(Path(path).read_text())
    except FileNotFoundError as err:
        raise InputError(f"{path}: no such file") from err
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: not a readable JSON camera file ({err})") from err
    keys = ("width", "height", "fx", "fy", "cx", "cy")
    if not isinstance(raw, dict) or any(k not in raw for k in keys):
        raise InputError(f"{path}: camera file needs keys {', '.join(keys)}")
    try:
        return CameraIntrinsics(
            int(raw["width"]),
            int(raw["height"]),
            float(raw["fx"]),
            float(raw["fy"]),
            float(raw["cx"]),
            float(raw["cy"]),
            float(raw.get("depth_unit_m", 0.001)),
        )
    except (TypeError, ValueError) as err:
        raise InputError(f"{path}: bad camera values ({err})") from err
