"""How fast an ``.oni`` recording plays through libOpenNI2 when it is not paced.

:class:`capture.OniSource` steps the file manually (playback speed -1: one record per wait,
none dropped); without ``realtime`` nothing waits for the recorded frame times, so
reprocessing and ``holescan detect`` read a recording as fast as the library hands it over.
This writes VGA RGB-D frames (random pixels: nothing for a codec to gain) with
:func:`capture.write_oni`, plays the file back ``--repeat`` times and prints the median
frames per second (and that every frame came back). It is the figure
``tests/capture/openni/test_openni_source.py`` leaves to a benchmark.

    python benchmarks/bench_oni.py [--frames 60] [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout

from holescan.capture import OniSource, write_oni
from holescan.detect import CameraIntrinsics, Frame


def frames(cam: CameraIntrinsics, n: int) -> list[Frame]:
    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        depth = rng.integers(0, 65536, (cam.height, cam.width), dtype=np.uint16)
        rgb = rng.integers(0, 256, (cam.height, cam.width, 3), dtype=np.uint8)
        out.append(Frame(i, rgb, depth, 0, 1_000_000_000 + i * 33_333_333))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    cam = CameraIntrinsics.xtion(640, 480)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.oni"
        write_oni(path, frames(cam, args.frames), cam)
        rates = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            with OniSource(path) as src:
                n = sum(1 for _ in src)
            dt = time.perf_counter() - t0
            if n != args.frames:
                print(f"played {n} of {args.frames} frames", file=sys.stderr)
                return 1
            rates.append(n / dt)
    fps = statistics.median(rates)
    print(
        f".oni playback, not paced: {args.frames} VGA RGB-D frames, median {fps:.0f} frames/s "
        f"({fps / 30:.1f}x the Xtion's 30 fps) over {args.repeat} runs, open and close included"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
