"""The frame record every frame source yields, and the FrameSource protocol.

Here, in the pure core, because every floor passes frames: the sources (the Xtion, ``.oni``
recordings, flight logs, the simulator), the flight log that stores them and the detector
that reads them."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from holescan.detect._types import CameraIntrinsics

__all__ = ["Frame", "FrameSource"]


@dataclass(frozen=True, eq=False)
class Frame:
    """One registered RGB-D pair.

    index : frame number from the source, from 0, increasing (gaps = dropped frames).
    rgb : (H, W, 3) uint8 ndarray, RGB order.
    depth : (H, W) uint16 ndarray, millimetres, 0 = no reading; registered to ``rgb``.
    t_mono_ns : companion computer's ``time.monotonic_ns()`` when the frame arrived.
    t_sensor_ns : the sensor's own timestamp (device clock), ns.
    """

    index: int
    rgb: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.uint16]
    t_mono_ns: int
    t_sensor_ns: int


class FrameSource(Protocol):
    """Anything that yields frames: the OpenNI2 device, an ``.oni`` file, an MCAP log, the sim.

    Use as a context manager; iterate to get frames; iteration ends at end of recording.
    A live source raises :class:`holescan.capture.SensorError` when frames stop arriving.
    """

    camera: CameraIntrinsics

    def __enter__(self) -> FrameSource: ...

    def __exit__(self, *exc: object) -> None: ...

    def __iter__(self) -> Iterator[Frame]: ...
