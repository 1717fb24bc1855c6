"""Unread depth and the detector's output on real Kinect v1 frames (docs/real-recordings.md).

    python benchmarks/real_frames.py FOLDER

FOLDER holds the three sample frames Open3D's test data carried (``TUM_color.png`` +
``TUM_depth.png``, ``NYU_color.ppm`` + ``NYU_depth.pgm``, ``SUN_color.jpg`` +
``SUN_depth.png``; any of the three pairs may be missing). Each is decoded in its own
convention (TUM depth 5000 per metre; NYU v2 raw 11-bit disparity, little-endian; SUN RGB-D
mm rotated by 3 bits), then the border bands and unread fractions
(:func:`ground.recordings.depthstats.unread_stats`) and the default detector's candidates
are printed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from holescan.detect import DEFAULT, CameraIntrinsics, detect_holes
from holescan.ground.recordings.depthstats import unread_stats

Pair = tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], CameraIntrinsics]
KINECT = CameraIntrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)  # TUM's "ROS default"
NYU = CameraIntrinsics(640, 480, 518.86, 519.47, 325.58, 253.74)  # NYU v2 toolbox, colour


def _rgb(path: Path) -> npt.NDArray[np.uint8]:
    return np.asarray(cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB))


def tum(folder: Path) -> Pair:
    raw = cv2.imread(str(folder / "TUM_depth.png"), cv2.IMREAD_UNCHANGED)
    mm = np.round(raw.astype(np.float64) / 5.0).astype(np.uint16)
    return _rgb(folder / "TUM_color.png"), mm, KINECT


def nyu(folder: Path) -> Pair:
    data = (folder / "NYU_depth.pgm").read_bytes()
    header_end = data.index(b"\n", data.index(b"65535")) + 1
    d = np.frombuffer(data[header_end:], "<u2").reshape(480, 640).astype(np.float64)
    with np.errstate(divide="ignore"):
        z = np.where(d < 1092, 351.3 / (1092.5 - d) * 1000.0, 0.0)
    z[d >= 2047] = 0
    return _rgb(folder / "NYU_color.ppm"), np.round(z).astype(np.uint16), NYU


def sun(folder: Path) -> Pair:
    v = cv2.imread(str(folder / "SUN_depth.png"), cv2.IMREAD_UNCHANGED).astype(np.uint32)
    mm = (((v >> 3) | (v << 13)) & 0xFFFF).astype(np.uint16)
    return _rgb(folder / "SUN_color.jpg"), mm, KINECT


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    args = ap.parse_args()
    print("| frame | unread | left px | right px | top px | bottom px | unread inside bands |")
    print("|---|---|---|---|---|---|---|")
    found = []
    for name, read, first in (
        ("TUM", tum, "TUM_depth.png"),
        ("NYU", nyu, "NYU_depth.pgm"),
        ("SUN", sun, "SUN_depth.png"),
    ):
        if not (args.folder / first).is_file():
            continue
        rgb, depth, camera = read(args.folder)
        s = unread_stats(depth)
        print(
            f"| {name} | {s.unread:.1%} | {s.left} | {s.right} | {s.top} | {s.bottom} "
            f"| {s.inside:.1%} |"
        )
        found.append((name, rgb, depth, camera))
    for name, rgb, depth, camera in found:
        print(f"\n{name}:")
        for d in detect_holes(rgb, depth, camera, DEFAULT):
            print(f"  box {d.box}: {d.explain()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
