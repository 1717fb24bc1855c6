"""A recording and a CSV of its hole boxes as an annotated dataset, for ``holescan eval``.

CSV rows are ``frame,x,y,w,h`` as ``holescan dataset import-csv`` takes them (an optional
header row; x, y the top-left pixel, 1-based unless ``origin=0``). ``frame`` names a frame
of the recording by its index (``12``), as ``frame_000012``, or, in a TUM folder, by its
colour image (``rgb/1305031102.175304.png`` or its stem). Frames no row names have no hole.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError
from holescan.ground.datasets import Sample, load_dataset, read_box_csv, write_dataset
from holescan.ground.recordings.source import open_recording
from holescan.ground.recordings.tum import TumSource

__all__ = ["frame_name", "recording_dataset"]


def frame_name(index: int) -> str:
    """The dataset name of frame ``index`` (``frame_000012``)."""
    return f"frame_{index:06d}"


def recording_dataset(
    recording: str | os.PathLike[str],
    boxes_csv: str | os.PathLike[str],
    root: str | os.PathLike[str],
    *,
    camera: CameraIntrinsics | None = None,
    max_dt_s: float = 0.02,
    origin: int = 1,
) -> Path:
    """Write every frame of ``recording`` with the boxes of ``boxes_csv`` as a dataset folder
    at ``root`` (a new or empty folder: a scratch copy for evaluation). Returns ``root``.
    Raises :class:`InputError` for a row naming no frame or a box past the image."""
    rows = read_box_csv(Path(boxes_csv), origin)
    source = open_recording(recording, camera=camera, max_dt_s=max_dt_s)
    aliases: dict[str, int] = {}
    if isinstance(source, TumSource):
        for i, pair in enumerate(source.pairs):
            rel = pair.rgb.relative_to(source.folder).as_posix()
            aliases.update({rel: i, pair.rgb.name: i, pair.rgb.stem: i})
    cam = source.camera
    boxes: dict[int, list[tuple[float, float, float, float]]] = {}
    for r in rows:
        key = r.file.strip()
        index = aliases.get(key)
        if index is None and key.isdigit():
            index = int(key)
        if index is None and key.startswith("frame_") and key[6:].isdigit():
            index = int(key[6:])
        where = f"{boxes_csv}, line {r.line}"
        if index is None:
            raise InputError(f"{where}: {r.file!r} names no frame (a frame index, frame_NNNNNN)")
        x, y, w, h = r.box
        if x + w > cam.width or y + h > cam.height:
            raise InputError(f"{where}: box reaches past the {cam.width}x{cam.height} image")
        boxes.setdefault(index, []).append(r.box)
    seen: set[int] = set()

    def samples() -> Iterator[Sample]:  # one frame in memory at a time
        with source:
            for frame in source:
                seen.add(frame.index)
                b = boxes.get(frame.index, [])
                yield Sample(frame_name(frame.index), frame.rgb, frame.depth, b, [False] * len(b))

    write_dataset(Path(root), cam, samples())
    missing = sorted(set(boxes) - seen)
    if missing:
        raise InputError(f"{boxes_csv}: frame(s) {missing[:5]} are not in {recording}")
    return load_dataset(Path(root)).root
