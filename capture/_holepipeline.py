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

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from detect import CameraIntrinsics, Detection
from geotag import (
    CameraMount,
    ErrorModel,
    Hole,
    HoleSighting,
    HoleTracker,
    VehiclePose,
    geotag_frame,
)

__all__ = ["FrameHoles", "HolePipeline", "PoseOf"]

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
