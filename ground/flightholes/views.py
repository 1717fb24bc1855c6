"""The holes' best views in a flight log: crops around each hole's best box, kept while
the log is read, and the thumbnails drawn from them."""

from __future__ import annotations

import dataclasses
import logging
from collections import OrderedDict
from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt

from holescan.errors import InputError
from holescan.flightlog import LoggedDetections, LoggedFrame
from holescan.geotag import Hole, crop_view
from holescan.ground.images.overlay import depth_colour

_log = logging.getLogger(__name__)

__all__ = ["BestViews", "HoleThumbnail", "render_thumbnail"]

_BOX_COLOUR = (255, 40, 40)
_Box = tuple[int, int, int, int]


@dataclasses.dataclass(frozen=True)
class HoleThumbnail:
    """A hole's best view: colour | colourised depth around its box, side by side.

    jpeg : JPEG bytes. width, height : size of the picture, pixels.
    frame_index : :attr:`detect.Frame.index` of the view; box : (x, y, w, h) pixels in it.
    t_unix_ns : capture time of the frame, Unix clock.
    """

    jpeg: bytes
    width: int
    height: int
    frame_index: int
    box: _Box
    t_unix_ns: int


# ------------------------------------------------------------------------ thumbnails


@dataclasses.dataclass(frozen=True)
class _View:
    """Crop of one detection's surroundings, kept until it is rendered or forgotten."""

    rgb: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.uint16]
    box_in_crop: _Box
    frame_index: int
    box: _Box
    t_unix_ns: int
    t_boot_ns: int | None


def _crop(rec: LoggedFrame, box: _Box) -> _View | None:
    rgb, depth = rec.frame.rgb, rec.frame.depth
    try:
        rgb_c, box_in_crop = crop_view(rgb, box)
        depth_c, _ = crop_view(depth, box)
    except InputError:
        height, width = depth.shape
        _log.warning("box %s lies outside frame %d (%dx%d)", box, rec.frame.index, width, height)
        return None
    return _View(
        rgb=rgb_c.copy(),
        depth=depth_c.copy(),
        box_in_crop=box_in_crop,
        frame_index=rec.frame.index,
        box=tuple(int(v) for v in box),  # type: ignore[arg-type]
        t_unix_ns=rec.t_unix_ns,
        t_boot_ns=rec.t_boot_ns,
    )


def render_thumbnail(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    box: _Box,
    *,
    height_px: int = 160,
    quality: int = 85,
) -> tuple[bytes, int, int]:
    """Colour | colourised depth (:func:`ground.depth_colour`), box drawn, JPEG.

    Parameters
    ----------
    rgb : (H, W, 3) uint8 ndarray, RGB. depth : (H, W) uint16 ndarray, mm, 0 = no reading.
    box : (x, y, w, h) pixels to outline.
    height_px : height of the picture (small crops are enlarged at most 4x).
    quality : JPEG quality 1..100.

    Returns
    -------
    (jpeg bytes, width, height)
    """
    if rgb.shape[:2] != depth.shape or rgb.ndim != 3:
        raise InputError(f"rgb {rgb.shape} and depth {depth.shape} must be (H, W, 3) and (H, W)")
    height, width = depth.shape
    scale = min(height_px / height, 4.0)
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    x, y, w, h = (v * scale for v in box)
    corners = ((round(x), round(y)), (round(x + w) - 1, round(y + h) - 1))
    panels = []
    for base in (np.ascontiguousarray(rgb), depth_colour(depth)):
        pic = cv2.resize(base, size, interpolation=interp)
        cv2.rectangle(pic, *corners, _BOX_COLOUR, 2)
        panels.append(pic)
    gap = np.full((size[1], 4, 3), 255, np.uint8)
    small = np.hstack([panels[0], gap, panels[1]])
    ok, buf = cv2.imencode(
        ".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality]
    )
    if not ok:
        raise InputError("JPEG encoding of a thumbnail failed")
    return buf.tobytes(), small.shape[1], small.shape[0]


class BestViews:
    """Single-pass bookkeeping of the frames and crops a hole's best view may come from.

    Fed the log's records in order (:meth:`on_frame`, :meth:`on_detections`,
    :meth:`on_holes`): the frame comes before the records that name it, so recent frames
    are kept until their ``/detections`` record (the detection worker answers frames in
    order, so older frames waiting are ones it skipped), every detection box is cropped, and
    after each ``/holes`` record the crops no hole can pick any more (frames up to the
    newest sighting that are no hole's best view) are forgotten. :meth:`thumbnails` draws
    the final holes' pictures.
    """

    def __init__(self, max_pending_frames: int) -> None:
        self.max_pending = max_pending_frames
        self.pending: OrderedDict[int, LoggedFrame] = OrderedDict()
        self.views: dict[tuple[int, _Box], _View] = {}

    def _view(self, index: int, box: _Box) -> _View | None:
        key = (index, box)
        if key not in self.views and index in self.pending:
            view = _crop(self.pending[index], box)
            if view is not None:
                self.views[key] = view
        return self.views.get(key)

    def on_frame(self, rec: LoggedFrame) -> None:
        self.pending[rec.frame.index] = rec
        while len(self.pending) > self.max_pending:
            self.pending.popitem(last=False)

    def on_detections(self, rec: LoggedDetections) -> None:
        for det in rec.detections:
            self._view(rec.frame_index, tuple(int(v) for v in det.box))  # type: ignore[arg-type]
        for index in [i for i in self.pending if i < rec.frame_index]:
            del self.pending[index]  # skipped by the detection worker: no sighting ever

    def on_holes(self, holes: Sequence[Hole]) -> None:
        wanted = {
            (h.best_frame_index, tuple(h.best_box)) for h in holes if h.best_frame_index is not None
        }
        for index, box in wanted:
            self._view(index, box)  # type: ignore[arg-type]
        frontier = max((h.t_last_boot_ns for h in holes), default=None)
        for key, view in list(self.views.items()):
            newer = (
                view.t_boot_ns is not None and frontier is not None and view.t_boot_ns > frontier
            )
            if key not in wanted and not newer:
                del self.views[key]

    def thumbnails(self, holes: Sequence[Hole], height_px: int) -> dict[int, HoleThumbnail]:
        out = {}
        for h in holes:
            if h.best_frame_index is None:
                continue
            box = tuple(int(v) for v in h.best_box)
            view = self._view(h.best_frame_index, box)  # type: ignore[arg-type]
            if view is None:
                _log.warning(
                    "hole %d: its best view (frame %d) is not in the log: no thumbnail",
                    h.id,
                    h.best_frame_index,
                )
                continue
            jpeg, w, ht = render_thumbnail(
                view.rgb, view.depth, view.box_in_crop, height_px=height_px
            )
            out[h.id] = HoleThumbnail(jpeg, w, ht, view.frame_index, view.box, view.t_unix_ns)
        return out
