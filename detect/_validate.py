"""Input checks shared by every detector: shapes, dtypes, a depth image that holds data."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from detect._types import CameraIntrinsics
from holescan_errors import InputError


def check_frame(
    rgb: npt.NDArray[np.uint8], depth: npt.NDArray[np.uint16], camera: CameraIntrinsics
) -> None:
    """Raise :class:`InputError` (one line saying what to fix) unless the pair is usable.

    rgb : (H, W, 3) uint8; depth : (H, W) uint16 millimetres, 0 = no reading; H, W as camera.
    """
    if not isinstance(rgb, np.ndarray) or rgb.ndim != 3 or rgb.shape[2] != 3:
        shape = getattr(rgb, "shape", None)
        raise InputError(f"rgb must be an (H, W, 3) array, got shape {shape}")
    if rgb.dtype != np.uint8:
        raise InputError(f"rgb must be uint8, got {rgb.dtype}")
    if not isinstance(depth, np.ndarray) or depth.ndim != 2:
        raise InputError(
            f"depth must be an (H, W) array, got shape {getattr(depth, 'shape', None)}"
        )
    if depth.dtype != np.uint16:
        raise InputError(
            f"depth must be uint16 millimetres (0 = no reading), got {depth.dtype}; "
            "8-bit or float depth images are not metric depth"
        )
    if rgb.shape[:2] != depth.shape:
        raise InputError(f"rgb {rgb.shape[:2]} and depth {depth.shape} differ in size")
    if depth.shape != (camera.height, camera.width):
        raise InputError(
            f"image is {depth.shape[1]}x{depth.shape[0]} but the camera is "
            f"{camera.width}x{camera.height}; pass the matching camera.json"
        )
    if not depth.any():
        raise InputError("depth image has no reading at all (all zero)")
