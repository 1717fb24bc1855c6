"""Pictures a person looks at: detections drawn over the colour and depth images."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect import CameraIntrinsics, Detection, DetectParams, Mode
from holescan.ground.images.files import write_rgb
from holescan.outputs import PathLike

__all__ = ["depth_colour", "draw_detections", "render_detections", "segmentation"]


def segmentation(
    depth: npt.NDArray[np.uint16], camera: CameraIntrinsics, params: DetectParams
) -> npt.NDArray[np.int32]:
    """The segmentation the detector scored: ERS superpixels (paper) or depth basins."""
    if params.mode is Mode.PAPER:
        from holescan.detect import paper_superpixels

        return paper_superpixels(depth, params)
    from holescan.detect import basin_labels

    return basin_labels(depth, camera, params)


def depth_colour(depth: npt.NDArray[np.uint16]) -> npt.NDArray[np.uint8]:
    """Depth as an RGB picture (near = bright); no reading = black."""
    valid = depth > 0
    out = np.zeros((*depth.shape, 3), np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth[valid], [1, 99])
        norm = np.clip((depth.astype(np.float32) - lo) / max(hi - lo, 1.0), 0, 1)
        grey = (255 * (1 - norm)).astype(np.uint8)
        out = cv2.cvtColor(cv2.applyColorMap(grey, cv2.COLORMAP_VIRIDIS), cv2.COLOR_BGR2RGB)
        out[~valid] = 0
    return out


def render_detections(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    labels: npt.NDArray[np.int32] | None,
    dets: list[Detection],
) -> npt.NDArray[np.uint8]:
    """Colour | depth side by side, segmentation edges in cyan, boxes with rank and score."""
    panels = []
    for base in (rgb.copy(), depth_colour(depth)):
        if labels is not None:
            edges = np.zeros(labels.shape, bool)
            edges[:, 1:] |= labels[:, 1:] != labels[:, :-1]
            edges[1:, :] |= labels[1:, :] != labels[:-1, :]
            base[edges] = (0, 255, 255)
        for i, d in enumerate(dets, 1):
            x, y, w, h = d.box
            colour = (255, 40, 40) if d.score >= 0.5 else (255, 200, 0)
            cv2.rectangle(base, (x, y), (x + w - 1, y + h - 1), colour, 2)
            label = f"#{i} {d.score:.2f} {d.major_m:.1f}x{d.minor_m:.1f}m"
            cv2.putText(
                base,
                label,
                (x + 2, max(12, y - 4)),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.45,
                (0, 0, 0),
                3,
                cv2.LINE_AA,
            )
            cv2.putText(
                base,
                label,
                (x + 2, max(12, y - 4)),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.45,
                colour,
                1,
                cv2.LINE_AA,
            )
        panels.append(base)
    return np.hstack(panels)


def draw_detections(
    path: Path,
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    params: DetectParams,
    dets: list[Detection],
    *,
    inputs: Iterable[PathLike] = (),
    force: bool = False,
) -> None:
    """Write :func:`render_detections` with the detector's segmentation to ``path`` (PNG or
    JPEG by extension; an existing file refused unless ``force``, never one of ``inputs``)."""
    image = render_detections(rgb, depth, segmentation(depth, camera, params), dets)
    write_rgb(path, image, inputs=inputs, force=force)
