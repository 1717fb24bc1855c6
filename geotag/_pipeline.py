"""One frame's detections -> vehicle pose -> sightings on the Earth -> the hole list.

The step every consumer of detections shares, so that a flight and its reprocessing
compute holes the same way: the capture daemon (:class:`capture._daemon.Flight`) feeds it
the detection worker's results with the pose interpolated from live telemetry, and
:mod:`ground._reprocess` feeds it detections of logged frames with the pose
re-interpolated from the logged telemetry. Pure: no clocks, files or sockets (the pose is
asked for through a callable, and only when the frame has detections, because in flight
getting it may wait for telemetry).
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect import CameraIntrinsics, Detection
from holescan.errors import InputError
from holescan.geotag._camera import CameraMount
from holescan.geotag._merge import Hole, HoleTracker
from holescan.geotag._project import ErrorModel, HoleSighting, geotag_frame
from holescan.geotag._types import VehiclePose

_log = logging.getLogger(__name__)

__all__ = [
    "BestViews",
    "FrameHoles",
    "HolePipeline",
    "HoleView",
    "PoseOf",
    "crop_view",
    "view_jpeg",
]

PoseOf = Callable[[], VehiclePose | None]
"""Returns the vehicle pose at the frame's capture time, or None when it is unknown."""


@dataclass(frozen=True)
class FrameHoles:
    """What one frame's detections did to the hole list.

    frame_index : the frame. detections : how many it had.
    posed : a pose was available (False when there were no detections: it was not asked).
    sightings : the detections placed on the Earth (those without a rim depth are left out).
    changed : the holes these sightings created or moved, sorted by id.
    """

    frame_index: int
    detections: int
    posed: bool
    sightings: tuple[HoleSighting, ...]
    changed: tuple[Hole, ...]

    @property
    def refused(self) -> bool:
        """The frame had detections but no pose: nothing could be placed."""
        return self.detections > 0 and not self.posed


class HolePipeline:
    """Merge frames' detections into numbered holes (one :class:`geotag.HoleTracker`).

    Parameters
    ----------
    camera : intrinsics of the frames the detections come from.
    mount : how the camera sits on the vehicle.
    tracker : the tracker to feed (default: a new one with default merge parameters).
    errors : error model of the sightings (default :class:`geotag.ErrorModel`).

    Feed frames in capture order (the tracker's ids follow first sightings).
    """

    def __init__(
        self,
        camera: CameraIntrinsics,
        mount: CameraMount,
        *,
        tracker: HoleTracker | None = None,
        errors: ErrorModel | None = None,
    ) -> None:
        self.camera = camera
        self.mount = mount
        self.tracker = tracker if tracker is not None else HoleTracker()
        self.errors = errors

    def add(self, frame_index: int, detections: Sequence[Detection], pose_of: PoseOf) -> FrameHoles:
        """Place one frame's detections and merge them into the holes.

        ``pose_of`` is called once, and only when there are detections.
        """
        n = len(detections)
        if not n:
            return FrameHoles(frame_index, 0, False, (), ())
        pose = pose_of()
        if pose is None:
            return FrameHoles(frame_index, n, False, (), ())
        sightings = geotag_frame(
            detections, self.camera, self.mount, pose, frame_index=frame_index, errors=self.errors
        )
        changed = self.tracker.update(sightings) if sightings else []
        return FrameHoles(frame_index, n, True, tuple(sightings), tuple(changed))

    def holes(self) -> list[Hole]:
        """Every hole so far, sorted by id."""
        return self.tracker.holes()


Box = tuple[int, int, int, int]


def crop_view(
    image: npt.NDArray[Any], box: Box, *, margin_px: int = 24, margin_frac: float = 0.5
) -> tuple[npt.NDArray[Any], Box]:
    """The part of ``image`` around ``box`` and the box in the crop's pixels.

    The one cropper of a hole's view (the flight's cards, the hole files' thumbnails, the
    report): a margin of ``margin_frac`` of the box's larger side, at least ``margin_px``,
    clipped to the image. The crop is a view into ``image`` (copy it to keep it).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray (colour, or depth in mm).
    box : (x, y, w, h) pixels, w and h > 0.

    Raises
    ------
    holescan.errors.InputError
        An empty box, or one entirely outside the image.

    Examples
    --------
    >>> import numpy as np
    >>> crop, b = crop_view(np.zeros((480, 640), np.uint16), (300, 200, 40, 20), margin_px=10)
    >>> crop.shape, b
    ((60, 80), (20, 20, 40, 20))
    """
    x, y, w, h = (int(v) for v in box)
    H, W = image.shape[:2]
    m = max(margin_px, round(margin_frac * max(w, h)))
    x0, y0 = max(x - m, 0), max(y - m, 0)
    x1, y1 = min(x + w + m, W), min(y + h + m, H)
    if w <= 0 or h <= 0 or x1 <= x0 or y1 <= y0:
        raise InputError(f"box {box} is empty or outside the {W} x {H} image")
    return image[y0:y1, x0:x1], (x - x0, y - y0, w, h)


def view_jpeg(
    rgb: npt.NDArray[np.uint8],
    box: Box,
    *,
    size_px: int = 96,
    max_bytes: int = 2800,
    qualities: Sequence[int] = (70, 55, 40, 28, 18),
) -> bytes:
    """A hole's best view as a small JPEG for the radio: crop, box drawn, longer side
    ``size_px``, the best quality of ``qualities`` that fits ``max_bytes``.

    rgb : (H, W, 3) uint8 ndarray, RGB order. box : (x, y, w, h) pixels.
    """
    crop, (bx, by, bw, bh) = crop_view(rgb, box, margin_frac=0.6)
    h, w = crop.shape[:2]
    scale = size_px / max(h, w)
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    small = cv2.resize(np.ascontiguousarray(crop), size, interpolation=cv2.INTER_AREA)
    p0 = (round(bx * scale), round(by * scale))
    p1 = (round((bx + bw) * scale) - 1, round((by + bh) * scale) - 1)
    cv2.rectangle(small, p0, p1, (255, 64, 0), 1)
    bgr = cv2.cvtColor(small, cv2.COLOR_RGB2BGR)
    data = b""
    for q in qualities:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(q)])
        if not ok:
            raise InputError("JPEG encoding of a hole view failed")
        data = buf.tobytes()
        if len(data) <= max_bytes:
            break
    return data


@dataclass(frozen=True)
class HoleView:
    """A hole's best view as sent to the ground: ``jpeg`` (:func:`view_jpeg`) and the
    detector's explanation of that detection (:meth:`detect.Detection.explain`)."""

    frame_index: int
    jpeg: bytes
    why: str


class BestViews:
    """Each hole's best view, encoded when it changes (thread-safe).

    The capture thread offers every frame's colour image (:meth:`add_frame`; the last
    ``keep_frames`` are kept by reference, frames being immutable: the detection worker
    lags a few frames behind); the results thread, after merging a frame's detections,
    calls :meth:`update` and the holes whose best view is that frame get a new
    :class:`HoleView` (JPEG via :func:`view_jpeg`, the detection's explanation).
    """

    def __init__(self, keep_frames: int = 48) -> None:
        self.keep_frames = keep_frames
        self._frames: OrderedDict[int, npt.NDArray[np.uint8]] = OrderedDict()
        self._views: dict[int, HoleView] = {}
        self._lock = threading.Lock()

    def add_frame(self, index: int, rgb: npt.NDArray[np.uint8]) -> None:
        with self._lock:
            self._frames[index] = rgb
            while len(self._frames) > self.keep_frames:
                self._frames.popitem(last=False)

    def update(
        self, frame_index: int, detections: Sequence[Detection], changed: Sequence[Hole]
    ) -> None:
        with self._lock:
            rgb = self._frames.get(frame_index)
        if rgb is None:
            return
        for h in changed:
            if h.best_frame_index != frame_index:
                continue
            why = next((d.explain() for d in detections if d.box == h.best_box), "")
            try:
                view = HoleView(frame_index, view_jpeg(rgb, h.best_box), why)
            except Exception as err:  # a picture is nice to have; never stop the flight
                _log.warning("view of hole %d not encoded: %s", h.id, err)
                continue
            with self._lock:
                self._views[h.id] = view

    def get(self, hole_id: int) -> HoleView | None:
        with self._lock:
            return self._views.get(hole_id)
