"""Input checks shared by every detector: shapes, dtypes, sizes each mode can handle, a depth
image that holds data."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from holescan.detect._types import CameraIntrinsics
from holescan.errors import InputError, NoDepthError

#: Smallest frame side the detectors work on (their block grid is 4 px).
MIN_SIDE_PX = 4
#: Largest frame paper mode takes: ERS keeps ~54 bytes per pixel (10000x10000 asked for
#: 5.4 GB); 1920x1080 needs ~110 MB.
PAPER_MAX_PIXELS = 1920 * 1080


def check_size(height: int, width: int, *, paper: bool = False) -> None:
    """Raise :class:`InputError` for a frame size the detector cannot handle (the limits
    are in the message)."""
    if height < MIN_SIDE_PX or width < MIN_SIDE_PX:
        raise InputError(
            f"frame is {width}x{height}: the detector needs at least "
            f"{MIN_SIDE_PX}x{MIN_SIDE_PX} pixels"
        )
    if paper and height * width > PAPER_MAX_PIXELS:
        raise InputError(
            f"frame is {width}x{height} ({height * width:,} pixels): paper mode handles at most "
            f"{PAPER_MAX_PIXELS:,} pixels (1920x1080); downscale the frame and its camera, "
            "or use the default mode"
        )


def check_frame(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    *,
    paper: bool = False,
) -> None:
    """Raise :class:`InputError` (one line saying what to fix) unless the pair is usable.

    rgb : (H, W, 3) uint8; depth : (H, W) uint16 millimetres, 0 = no reading; H, W as camera.
    paper : also apply paper mode's size limit (:data:`PAPER_MAX_PIXELS`).
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
    check_size(depth.shape[0], depth.shape[1], paper=paper)
    if not depth.any():
        raise NoDepthError("depth image has no reading at all (all zero)")
