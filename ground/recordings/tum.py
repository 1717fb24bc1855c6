"""TUM RGB-D benchmark folders as a frame source.

A TUM RGB-D sequence folder (Sturm et al., IROS 2012) holds ``rgb.txt`` and ``depth.txt``
(``timestamp filename`` per line, ``#`` comments; timestamps in seconds), ``rgb/*.png``
(8-bit colour) and ``depth/*.png`` (16-bit, 5000 per metre, 0 = no reading). Colour and
depth are not synchronised: each colour image is paired with the depth image nearest in
time, within a tolerance, each depth image used once (as the benchmark's ``associate.py``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np

from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import InputError
from holescan.ground.images import read_depth, read_rgb

__all__ = ["TUM_DEPTH_PER_M", "TUM_FR1", "TumPair", "TumSource", "associate", "is_tum_folder"]

TUM_DEPTH_PER_M: Final = 5000.0
TUM_FR1: Final = CameraIntrinsics(640, 480, 517.3, 516.5, 318.6, 255.3)
"""The colour camera of the benchmark's "freiburg1" sequences (its published calibration);
the depth is registered to it. Other sequences: pass their camera."""


@dataclass(frozen=True)
class TumPair:
    """One association: the colour and depth files and their times (ns, the recording's
    clock)."""

    rgb: Path
    depth: Path
    t_rgb_ns: int
    t_depth_ns: int


def is_tum_folder(path: Path) -> bool:
    """A folder with ``rgb.txt`` and ``depth.txt``."""
    return path.is_dir() and (path / "rgb.txt").is_file() and (path / "depth.txt").is_file()


def _read_list(path: Path) -> list[tuple[int, Path]]:
    """``(t_ns, file)`` per line of a TUM ``rgb.txt`` / ``depth.txt``."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as err:
        raise InputError(f"{path}: cannot read: {err.strerror}") from err
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) < 2:
            raise InputError(f"{path}:{n}: expected 'timestamp filename', got {line.strip()!r}")
        try:
            t_s = float(fields[0])
        except ValueError:
            t_s = math.nan
        if not (math.isfinite(t_s) and t_s >= 0):
            raise InputError(f"{path}:{n}: timestamp must be seconds >= 0, got {fields[0]!r}")
        rows.append((round(t_s * 1e9), path.parent / fields[1]))
    return rows


def associate(
    rgb: list[tuple[int, Path]], depth: list[tuple[int, Path]], max_dt_ns: int
) -> list[TumPair]:
    """Pair colour and depth images nearest in time, at most ``max_dt_ns`` apart, each
    image used once (closest pairs first), in colour time order.

    Examples
    --------
    >>> a, b, c = Path("a"), Path("b"), Path("c")
    >>> [(p.rgb.name, p.depth.name) for p in associate([(0, a), (100, b)], [(90, c)], 20)]
    [('b', 'c')]
    """
    d_times = np.array([t for t, _ in depth], dtype=np.int64)
    order = np.argsort(d_times)
    d_sorted = d_times[order]
    candidates = []
    for i, (t, _) in enumerate(rgb):
        k = int(np.searchsorted(d_sorted, t))
        for j in (k - 1, k):
            if 0 <= j < len(d_sorted) and abs(int(d_sorted[j]) - t) <= max_dt_ns:
                candidates.append((abs(int(d_sorted[j]) - t), i, int(order[j])))
    used_rgb: set[int] = set()
    used_depth: set[int] = set()
    pairs = []
    for _, i, j in sorted(candidates):
        if i in used_rgb or j in used_depth:
            continue
        used_rgb.add(i)
        used_depth.add(j)
        pairs.append(TumPair(rgb[i][1], depth[j][1], rgb[i][0], depth[j][0]))
    return sorted(pairs, key=lambda p: p.t_rgb_ns)


class TumSource:
    """A :class:`detect.FrameSource` over a TUM RGB-D folder.

    Parameters
    ----------
    folder : the sequence folder (``rgb.txt``, ``depth.txt``, ``rgb/``, ``depth/``).
    camera : intrinsics of the colour camera (default :data:`TUM_FR1`; at another image
        size, the Xtion's at that size).
    max_dt_s : largest colour-depth time difference of a pair (default 0.02 s, as the
        benchmark's ``associate.py``).

    Frames: ``index`` = position among the pairs; ``t_sensor_ns`` = ``t_mono_ns`` = the
    colour timestamp (ns); depth converted to millimetres (value / 5, rounded).
    """

    def __init__(
        self,
        folder: str | Path,
        camera: CameraIntrinsics | None = None,
        max_dt_s: float = 0.02,
    ) -> None:
        self.folder = Path(folder)
        if not is_tum_folder(self.folder):
            raise InputError(f"{self.folder}: not a TUM RGB-D folder (no rgb.txt and depth.txt)")
        if not (math.isfinite(max_dt_s) and max_dt_s >= 0):
            raise InputError(f"max_dt_s must be seconds >= 0, got {max_dt_s}")
        rgb = _read_list(self.folder / "rgb.txt")
        depth = _read_list(self.folder / "depth.txt")
        self.pairs = associate(rgb, depth, round(max_dt_s * 1e9))
        if not self.pairs:
            raise InputError(
                f"{self.folder}: no colour image has a depth image within {max_dt_s} s "
                f"({len(rgb)} colour, {len(depth)} depth listed)"
            )
        first = read_depth(self.pairs[0].depth)
        h, w = first.shape
        self.camera = camera or (TUM_FR1 if (w, h) == (640, 480) else CameraIntrinsics.xtion(w, h))

    def __enter__(self) -> TumSource:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def __iter__(self) -> Iterator[Frame]:
        shape = (self.camera.height, self.camera.width)
        for index, pair in enumerate(self.pairs):
            rgb = read_rgb(pair.rgb)
            raw = read_depth(pair.depth)
            if rgb.shape[:2] != shape or raw.shape != shape:
                raise InputError(
                    f"{pair.rgb.name} / {pair.depth.name}: images {rgb.shape[1]}x{rgb.shape[0]}"
                    f" and {raw.shape[1]}x{raw.shape[0]}, camera {shape[1]}x{shape[0]}"
                )
            mm = np.round(raw.astype(np.float64) * (1000.0 / TUM_DEPTH_PER_M)).astype(np.uint16)
            yield Frame(index, rgb, mm, pair.t_rgb_ns, pair.t_rgb_ns)
