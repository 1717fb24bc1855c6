#!/usr/bin/env python3
"""Reprocessing benchmark: frames per second of ``holescan reprocess`` on a demo flight.

Run (from the repository root)::

    python benchmarks/bench_reprocess.py                   # flies a 40 s demo first
    python benchmarks/bench_reprocess.py FLIGHT_0000.mcap  # or reprocesses a given log
    python benchmarks/bench_reprocess.py --workers 1 --repeat 3

What runs: (1) without a log given, ``holescan demo`` flies ``--duration`` seconds of the
simulated sortie into a temporary folder (timed separately, not part of the figure);
(2) :func:`ground.reprocess` over the log ``--repeat`` times on a local Dask cluster of
``--workers`` processes (default: one per core; the cluster's start-up is reported apart;
``--workers 0``: in this process), the partition cache off;
(3) the figures: frames/s of each run (frames detected and merged / wall time from the
first task submitted to the last file written, sidecar MCAP and hole files included), the
workers' mean
detection time per frame, whether every confirmed in-flight hole was found again (and how
far from where the flight put it), and the load average of the machine during the runs
(other work on the machine slows the figure; it is printed to judge the number).

The target: >= 30 frames/s in the default mode on a 2-core machine. Exit status 1 when the
median run is slower.
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

TARGET_FPS = 30.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", type=Path, help="flight log(s) of one flight")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--duration", type=float, default=40.0, help="demo flight seconds")
    ap.add_argument("--mode", choices=("default", "paper"), default="default")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("distributed").setLevel(logging.ERROR)

    from holescan.demo import DemoOptions, run_demo
    from holescan.detect import DEFAULT, PAPER
    from holescan.ground import ReprocessOptions, reprocess

    work = Path(tempfile.mkdtemp(prefix="bench-reprocess-"))
    logs = list(args.logs)
    if not logs:
        t0 = time.monotonic()
        demo = run_demo(DemoOptions(out=work / "demo", duration_s=args.duration))
        logs = list(demo.log_files)
        print(
            f"demo flight: {demo.summary.counters.frames_captured} frames in "
            f"{demo.capture_s:.0f} s, {len(demo.confirmed)} holes confirmed "
            f"({time.monotonic() - t0:.0f} s with start-up and scoring)"
        )
    params = PAPER if args.mode == "paper" else DEFAULT
    opts = ReprocessOptions(params=params, workers=args.workers, cache=False)
    fps: list[float] = []
    loads: list[float] = []
    for i in range(args.repeat):
        load0 = os.getloadavg()[0]
        res = reprocess(logs, work / f"run{i}", opts)
        (f,) = res.flights
        loads.append((load0 + os.getloadavg()[0]) / 2)
        run_s = res.elapsed_s - res.engine.start_s
        fps.append(f.frames_detected / run_s)
        found = [m for m in f.flight_matches if m.found is not None]
        far = max((m.distance_m for m in found), default=float("nan"))
        print(
            f"run {i + 1}: {f.frames_detected} frames in {run_s:.2f} s = "
            f"{fps[-1]:.1f} frames/s (cluster start {res.engine.start_s:.1f} s, detect "
            f"{f.detect_ms_mean:.1f} ms/frame/worker, {args.workers} workers, load avg "
            f"{loads[-1]:.1f}); in-flight holes found again {len(found)}/"
            f"{len(f.flight_matches)}, farthest {far:.3f} m"
        )
    median = statistics.median(fps)
    verdict = "PASS" if median >= TARGET_FPS else "FAIL"
    print(
        f"{verdict}: median {median:.1f} frames/s over {len(fps)} runs (target >= "
        f"{TARGET_FPS:.0f}, {os.cpu_count()} cores, mean load average {statistics.mean(loads):.1f})"
    )
    print(f"outputs in {work}")
    return 0 if median >= TARGET_FPS else 1


if __name__ == "__main__":
    sys.exit(main())
