"""``detect_holes``: one entry point for both detector modes."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from holescan.detect._default import detect_default
from holescan.detect._types import DEFAULT, CameraIntrinsics, Detection, DetectParams, Mode
from holescan.detect._validate import check_size


def detect_holes(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    params: DetectParams = DEFAULT,
) -> list[Detection]:
    """Find access holes in one registered RGB-D frame.

    Parameters
    ----------
    rgb : (H, W, 3) uint8 ndarray, RGB order, registered to ``depth``.
    depth : (H, W) uint16 ndarray, millimetres, 0 = no reading.
    camera : intrinsics of the (H, W) images.
    params : ``DEFAULT`` (holescan's detector) or ``PAPER`` (Kong et al. 2015), or a variant.

    Returns
    -------
    list of Detection, highest score first.

    Raises
    ------
    holescan.errors.InputError
        Wrong shapes or dtypes, sizes that do not match ``camera``, no depth at all.
    """
    if isinstance(depth, np.ndarray) and depth.ndim == 2:  # (other shapes: the mode says)
        check_size(depth.shape[0], depth.shape[1], paper=params.mode is Mode.PAPER)
    if params.mode is Mode.PAPER:
        # Imported here: paper mode compiles ERS with numba on first use.
        from holescan.detect._paper import detect_paper

        return detect_paper(rgb, depth, camera, params)
    return detect_default(rgb, depth, camera, params)
