"""The detector over every frame of a recording (``holescan detect RECORDING``)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from holescan.detect import Detection, DetectParams, FrameSource, detect_holes
from holescan.errors import InputError

__all__ = ["FrameDetections", "detect_recording"]


@dataclass(frozen=True)
class FrameDetections:
    """The detector's candidates in one frame of a recording.

    index : the frame's index in its source. t_sensor_ns : its time on the recording's
    clock, ns. no_depth : the frame has no depth reading at all (nothing to detect).
    """

    index: int
    t_sensor_ns: int
    detections: tuple[Detection, ...]
    no_depth: bool = False


def detect_recording(
    source: FrameSource,
    params: DetectParams,
    *,
    every: int = 1,
    max_frames: int | None = None,
) -> Iterator[FrameDetections]:
    """Detect in every ``every``-th frame of ``source`` (an open frame source), at most
    ``max_frames`` frames, in order."""
    if every < 1:
        raise InputError(f"every must be >= 1 frame, got {every}")
    if max_frames is not None and max_frames < 1:
        raise InputError(f"max_frames must be >= 1, got {max_frames}")
    done = 0
    for n, frame in enumerate(source):
        if n % every:
            continue
        if not frame.depth.any():
            yield FrameDetections(frame.index, frame.t_sensor_ns, (), no_depth=True)
        else:
            dets = detect_holes(frame.rgb, frame.depth, source.camera, params)
            yield FrameDetections(frame.index, frame.t_sensor_ns, tuple(dets))
        done += 1
        if max_frames is not None and done >= max_frames:
            return
