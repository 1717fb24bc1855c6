"""One entry point for every recording: :func:`open_recording` recognises the input by its
content and returns the frame source that reads it."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Final

from holescan.capture import OniSource
from holescan.detect import CameraIntrinsics, FrameSource
from holescan.errors import InputError
from holescan.flightlog import McapSource

__all__ = ["RECORDING_KINDS", "open_recording", "recording_kind"]

RECORDING_KINDS: Final = {
    "tum": "TUM RGB-D folder (rgb.txt, depth.txt)",
    "ros1": "ROS 1 bag",
    "ros2": "ROS 2 bag folder (metadata.yaml)",
    "oni": "OpenNI .oni recording",
    "mcap": "holescan flight log (.mcap)",
}
_MCAP_MAGIC: Final = b"\x89MCAP0\r\n"


def recording_kind(path: str | os.PathLike[str]) -> str:
    """Which of :data:`RECORDING_KINDS` ``path`` is, from its content (not its name).
    Raises :class:`InputError` (one line) when it is none of them."""
    from holescan.ground.recordings.rosbag import is_ros1_bag, is_ros2_bag
    from holescan.ground.recordings.tum import is_tum_folder

    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file or folder")
    if p.is_dir():
        if is_tum_folder(p):
            return "tum"
        if is_ros2_bag(p):
            return "ros2"
    else:
        if is_ros1_bag(p):
            return "ros1"
        try:
            with p.open("rb") as f:
                head = f.read(8)
        except OSError as err:
            raise InputError(f"{p}: cannot read: {err.strerror}") from err
        if head[:4] == b"NI10":
            return "oni"
        if head == _MCAP_MAGIC:
            return "mcap"
    kinds = ", ".join(RECORDING_KINDS.values())
    raise InputError(f"{p}: not a recording holescan reads (one of: {kinds})")


def open_recording(
    path: str | os.PathLike[str],
    *,
    camera: CameraIntrinsics | None = None,
    max_dt_s: float = 0.02,
) -> FrameSource:
    """The :class:`detect.FrameSource` that reads ``path``: a TUM RGB-D folder
    (:class:`TumSource`), a ROS 1 bag or ROS 2 bag folder (:class:`BagSource`), an
    OpenNI ``.oni`` file (:class:`capture.OniSource`) or a holescan flight log
    (:class:`flightlog.McapSource`).

    camera : intrinsics to use instead of the recording's own (TUM folders carry none).
    max_dt_s : largest colour-depth time difference of a pair (TUM folders, bags).
    Raises :class:`InputError` (one line) for anything else.
    """
    kind = recording_kind(path)
    source: FrameSource
    if kind == "tum":
        from holescan.ground.recordings.tum import TumSource

        source = TumSource(Path(path), camera, max_dt_s)
    elif kind in ("ros1", "ros2"):
        from holescan.ground.recordings.rosbag import BagSource

        source = BagSource(Path(path), camera=camera, max_dt_s=max_dt_s)
    elif kind == "oni":
        source = OniSource(path)
    else:
        source = McapSource(path)
    if camera is not None and kind in ("oni", "mcap"):
        source.camera = camera
    return source
