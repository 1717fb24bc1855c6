"""Median milliseconds per 640x480 frame for each detector mode, on one core.

    python benchmarks/bench_detect.py [DATASET] [--frames N] [--modes default,paper,baseline]

Without DATASET, renders N synthetic frames first (seeded). Pins itself to one CPU core and
one OpenCV/BLAS thread, warms each mode up (numba compilation is not counted), then times
every frame and prints the median, 90th percentile and mean of the wall time, and the
median of the CPU time of this thread (on a machine shared with other jobs, wall time
includes waiting for the core; CPU time is what the detector itself costs).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[var] = "1"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", nargs="?", type=Path)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--modes", default="default,paper,baseline")
    args = ap.parse_args(argv)

    import cv2

    cv2.setNumThreads(1)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    from dataclasses import replace

    from holescan.detect import DEFAULT, PAPER, detect_baseline, detect_holes
    from holescan.ground import load_dataset, load_image_pair

    root = args.dataset
    if root is None:
        from holescan.sim import synth_dataset

        root = Path(tempfile.mkdtemp(prefix="holescan-bench-"))
        print(f"rendering {args.frames} synthetic frames into {root} ...", flush=True)
        synth_dataset(root, args.frames, seed=11)
    ds = load_dataset(root)
    frames = [load_image_pair(ds, im) for im in ds.images[: args.frames]]
    cam = ds.camera
    runners = {
        "default": lambda r, d: detect_holes(r, d, cam, DEFAULT),
        "baseline": lambda r, d: detect_baseline(r, d, cam),
    }
    for k in (9, 20):
        runners[f"paper K={k}"] = lambda r, d, k=k: detect_holes(
            r, d, cam, replace(PAPER, superpixels=k)
        )
    wanted = args.modes.split(",")
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}; one core, {len(frames)} frames "
        f"{cam.width}x{cam.height}"
    )
    print("| mode | median ms | p90 ms | mean ms | frames/s (median) | median CPU ms |")
    print("|---|---|---|---|---|---|")
    for name, run in runners.items():
        if name.split()[0] not in wanted:
            continue
        run(*frames[0])  # warm-up (numba compiles ERS on first use)
        times, cpu = [], []
        for rgb, depth in frames:
            t0, c0 = time.perf_counter(), time.thread_time()
            run(rgb, depth)
            times.append((time.perf_counter() - t0) * 1000.0)
            cpu.append((time.thread_time() - c0) * 1000.0)
        times.sort()
        med = statistics.median(times)
        p90 = times[int(0.9 * (len(times) - 1))]
        print(
            f"| {name} | {med:.1f} | {p90:.1f} | {statistics.fmean(times):.1f} | "
            f"{1000.0 / med:.0f} | {statistics.median(cpu):.1f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
