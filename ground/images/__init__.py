"""Image files (colour, 16-bit depth in millimetres, camera JSON; :mod:`.files`) and the
detector's overlays drawn on them (:mod:`.overlay`), for ``holescan detect``."""

from holescan.ground.images.files import read_camera, read_depth, read_rgb, write_depth, write_rgb
from holescan.ground.images.overlay import (
    depth_colour,
    draw_detections,
    render_detections,
    segmentation,
)

__all__ = [
    "depth_colour",
    "draw_detections",
    "read_camera",
    "read_depth",
    "read_rgb",
    "render_detections",
    "segmentation",
    "write_depth",
    "write_rgb",
]
