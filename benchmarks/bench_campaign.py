#!/usr/bin/env python3
"""Campaign benchmark: the Dask engine's scaling, memory, overhead, and a 6-flight campaign.

Run (from the repository root; ~10-15 min on 2 busy cores)::

    nice python benchmarks/bench_campaign.py                 # flies two 30 s demo sorties
    nice python benchmarks/bench_campaign.py --logs A_0000.mcap B_0000.mcap --repeat 3

What runs:

1. two simulated sorties (``holescan demo`` flights over the same world, headings 0 and 90
   degrees), unless ``--logs`` names flights; not timed into any figure;
2. ``reprocess`` of the first flight with a local cluster of 1 and of 2 worker processes,
   ``--repeat`` times each, cache off: frames/s over the run without the cluster's start-up
   (reported apart), the scaling ratio (target >= 1.7), each worker's peak memory;
3. the scheduler's overhead per partition: (wall time x workers - the tasks' own time) /
   partitions in the 1-worker runs, and the round trip of 200 empty tasks;
4. the client-side merge alone: the same run again with every partition from the cache;
5. a campaign of ``--flights`` flights (the sorties, and the same again under other names)
   end to end on 2 workers;
6. a projection to N machines from the measured per-worker rate and overhead, against the
   two other limits: shared storage bandwidth and the client's merge rate.

The load average (1 min) is printed with every figure: this machine is shared.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

TARGET_SCALING = 1.7


def load() -> float:
    return os.getloadavg()[0]


def fly(work: Path, duration_s: float) -> list[list[Path]]:
    from holescan.demo import DEMO_SORTIE, DemoOptions, run_demo

    flights = []
    for name, heading in (("a", 0.0), ("b", 90.0)):
        t0 = time.monotonic()
        sortie = dataclasses.replace(DEMO_SORTIE, heading_deg=heading)
        demo = run_demo(DemoOptions(out=work / name, duration_s=duration_s, sortie=sortie))
        frames = demo.summary.counters.frames_captured
        print(f"sortie {name}: {frames} frames flown in {time.monotonic() - t0:.0f} s")
        flights.append(list(demo.log_files))
    return flights


def copies(flights: list[list[Path]], n: int, work: Path) -> list[Path]:
    """``n`` flights named ``flightK``: the given ones, then the same again (hard links)."""
    out: list[Path] = []
    for k in range(n):
        folder = work / f"flight{k}"
        folder.mkdir(parents=True, exist_ok=True)
        for i, p in enumerate(flights[k % len(flights)]):
            dst = folder / f"flight{k}_{i:04d}.mcap"
            try:
                os.link(p, dst)
            except OSError:
                shutil.copyfile(p, dst)
            out.append(dst)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", nargs="*", type=Path, help="first log file of each flight")
    ap.add_argument("--duration", type=float, default=30.0, help="demo sortie seconds")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--flights", type=int, default=6)
    ap.add_argument("--partition-mib", type=float, default=32.0)
    ap.add_argument("--campaign-only", action="store_true", help="only step 5")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("distributed").setLevel(logging.ERROR)

    from holescan.ground import ReprocessOptions, flight_log_files, reprocess

    work = Path(tempfile.mkdtemp(prefix="bench-campaign-"))
    if args.logs:
        flights = [list(flight_log_files(p)) for p in args.logs]
    else:
        flights = fly(work / "fly", args.duration)
    first = flights[0]
    size = sum(p.stat().st_size for p in first)
    if args.campaign_only:
        campaign(flights, args, work)
        return 0

    print(f"\n== scaling (flight of {size / 1e6:.0f} MB, {args.repeat} runs each) ==")
    rates: dict[int, list[float]] = {}
    peaks: dict[int, list[float]] = {}
    overheads: list[float] = []
    task_rates: list[float] = []  # frames per second of task time (reading + detecting)
    frames = partitions = 0
    for workers in (1, 2):
        for i in range(args.repeat):
            opts = ReprocessOptions(workers=workers, cache=False, partition_mib=args.partition_mib)
            l0 = load()
            res = reprocess(first, work / f"w{workers}r{i}", opts)
            (f,) = res.flights
            frames, partitions = f.frames_detected, f.partitions
            run_s = res.elapsed_s - res.engine.start_s
            rates.setdefault(workers, []).append(frames / run_s)
            per_worker: dict[str, float] = {}
            task_s = 0.0
            for r in res.engine.results:
                per_worker[r.worker] = max(per_worker.get(r.worker, 0.0), r.peak_rss_mib)
                task_s += r.read_s + r.detect_s
            peaks.setdefault(workers, []).append(max(per_worker.values()))
            if workers == 1:
                overheads.append((run_s - task_s) / partitions)
                task_rates.append(frames / task_s)
            print(
                f"{workers} worker(s) run {i + 1}: {frames} frames, {partitions} partitions in "
                f"{run_s:.1f} s + {res.engine.start_s:.1f} s cluster start = "
                f"{rates[workers][-1]:.1f} frames/s; peak RSS per worker "
                f"{', '.join(f'{v:.0f}' for v in per_worker.values())} MiB; load {l0:.1f}-"
                f"{load():.1f}"
            )
    r1, r2 = statistics.median(rates[1]), statistics.median(rates[2])
    print(
        f"median frames/s: 1 worker {r1:.1f}, 2 workers {r2:.1f}: scaling {r2 / r1:.2f}x "
        f"(target >= {TARGET_SCALING}; {os.cpu_count()} cores shared, load now {load():.1f})"
    )
    print(
        f"peak memory per worker: median {statistics.median(peaks[1]):.0f} MiB (1 worker), "
        f"{statistics.median(peaks[2]):.0f} MiB (2 workers)"
    )

    print("\n== scheduler overhead ==")
    per_part = statistics.median(overheads)
    print(
        f"per partition, in the 1-worker runs (wall - task time) / partitions: "
        f"median {per_part * 1000:.1f} ms ({frames / max(partitions, 1):.1f} frames/partition)"
    )
    empty_ms = empty_task_ms()
    print(f"round trip of an empty task (200 through 1 worker): {empty_ms:.2f} ms each")

    print("\n== client-side merge alone (every partition from the cache) ==")
    opts = ReprocessOptions(workers=1, partition_mib=args.partition_mib)
    reprocess(first, work / "cached", opts)
    t0 = time.monotonic()
    res = reprocess(first, work / "cached", opts)
    merge_s = time.monotonic() - t0
    merge_rate = frames / merge_s
    print(
        f"{frames} frames merged and written in {merge_s:.2f} s = {merge_rate:.0f} frames/s "
        f"({res.engine.cached} partitions cached); load {load():.1f}"
    )

    campaign(flights, args, work)

    print("\n== projection ==")
    r_task = statistics.median(task_rates)
    part_frames = frames / max(partitions, 1)
    eff = part_frames / (part_frames / r_task + per_part)  # per worker, with the overhead
    print(
        f"per worker: {r_task:.1f} frames/s of task time, {eff:.1f} with {per_part * 1000:.0f} "
        f"ms overhead per {part_frames:.1f}-frame partition"
    )
    bytes_per_frame = size / max(frames, 1)
    for bw_name, bw in (("1 GbE NFS", 110e6), ("10 GbE", 1.1e9)):
        print(f"storage limit over {bw_name}: {bw / bytes_per_frame:.0f} frames/s")
    print(f"client merge limit: {merge_rate:.0f} frames/s")
    for machines in (1, 2, 4, 8, 16):
        cores = machines * 2
        compute = cores * eff
        limit = min(compute, 110e6 / bytes_per_frame, merge_rate)
        print(
            f"{machines:2d} machines x 2 cores: compute {compute:6.0f} frames/s, with 1 GbE "
            f"storage and the client merge {limit:6.0f} frames/s; 360,000 frames in "
            f"{360_000 / limit / 60:.0f} min"
        )
    print(f"outputs in {work}")
    return 0


def campaign(flights: list[list[Path]], args: argparse.Namespace, work: Path) -> None:
    from holescan.ground import ReprocessOptions, run_campaign

    print(f"\n== campaign of {args.flights} flights, 2 workers ==")
    logs = copies(flights, args.flights, work / "copies")
    total = sum(p.stat().st_size for p in logs)
    l0 = load()
    opts = ReprocessOptions(workers=2, cache=False, partition_mib=args.partition_mib)
    t0 = time.monotonic()
    camp = run_campaign(logs, work / "campaign", opts)
    wall = time.monotonic() - t0
    n = sum(f.frames_detected for f in camp.flights)
    several = sum(len(h.flights) > 1 for h in camp.campaign)
    print(
        f"{len(camp.flights)} flights, {n} frames, {total / 1e6:.0f} MB in {wall:.1f} s end to "
        f"end ({camp.engine.start_s:.1f} s cluster start, {camp.engine.computed} partitions) = "
        f"{n / wall:.1f} frames/s; {len(camp.campaign)} campaign holes, {several} seen by "
        f"several flights; load {l0:.1f}-{load():.1f}"
    )


def empty_task_ms(n: int = 200) -> float:
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        client.wait_for_workers(1)
        client.gather(client.map(abs, range(10)))
        t0 = time.perf_counter()
        client.gather(client.map(abs, range(1000, 1000 + n)))
        return (time.perf_counter() - t0) * 1000 / n


if __name__ == "__main__":
    sys.exit(main())
