#!/usr/bin/env python3
"""The on-board live map's cost: per frame on one core, and what it does to capture and
detection beside it; the tiles' sizes per tile and per hectare.

Run (from the repository root, ~2 minutes)::

    python benchmarks/bench_livemap.py [--frames 300] [--seconds 20]

1. Renders ``--frames`` consecutive 30 fps frames of the simulated sortie (10 x 10 m world,
   3 m altitude) from the autopilot's true poses (not timed).
2. **Fusing alone**: each frame fused into the coarse map (:meth:`capture.LiveMap.fuse`)
   at pixel strides 4, 8 and 16, thread CPU time per frame: median and p99; and cutting the
   changed tiles (:meth:`capture.LiveMap.publish`).
3. **Live, beside capture and detection**: a 30 fps capture loop (the frames played in a
   loop for ``--seconds``) offering every frame to the detection worker process and to the
   live map's thread, against the same loop without the map: the map's CPU per captured
   frame amortised (its thread CPU over frames captured), frames fused, the capture loop's
   lateness (median / p99 / max), the detector's frames/s and what handing a frame to the
   detection worker costs the capture thread (median / p99, us).
4. The tiles' bytes (coverage PNG, orthophoto JPEG; median per tile, MAVLink frames of the
   image transmission protocol included) and per hectare of seen ground.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from collections.abc import Collection

import numpy as np

from holescan.capture import DetectionWorker, LiveMap, LiveMapConfig
from holescan.detect import DEFAULT, CameraIntrinsics, Frame
from holescan.geotag import CameraMount, VehiclePose
from holescan.missions import CARD_PAYLOAD
from holescan.sim import (
    Conditions,
    SimAutopilot,
    SortieParams,
    camera_pose_in_world,
    lap_frames,
    make_sortie_world,
    random_conditions,
    render,
    survey_path,
)

FPS = 30.0


def render_frames(n: int) -> tuple[list[tuple[Frame, VehiclePose]], CameraIntrinsics]:
    p = SortieParams(size_m=(10.0, 10.0), fps=FPS)
    world = make_sortie_world(p)
    _, path = survey_path(world, p)
    path, _ = lap_frames(path, FPS)
    ap = SimAutopilot("udpout:127.0.0.1:9", path, uptime_at_start_s=p.clock_offset_s)
    cam, mount = CameraIntrinsics.xtion(), CameraMount()
    out = []
    for k in range(n):
        t_boot = round(p.clock_offset_s * 1e9) + round(k * 1e9 / FPS)
        pose = ap.truth_pose(t_boot)
        rng = np.random.default_rng(k)
        cond = random_conditions(rng, Conditions())
        rgb, depth, _ = render(world, camera_pose_in_world(pose, mount, p.anchor), cam, rng, cond)
        out.append((Frame(k, rgb, depth, 0, 0), pose))
    return out, cam


def pct(v: Collection[float], q: float) -> float:
    return float(np.percentile(list(v), q)) if v else math.nan


def fuse_alone(frames: list[tuple[Frame, VehiclePose]], cam: CameraIntrinsics) -> LiveMap:
    print("fusing alone (thread CPU per frame, one core):")
    keep = None
    for stride in (4, 8, 16):
        lm = LiveMap(cam, CameraMount(), LiveMapConfig(pixel_stride=stride))
        for f, pose in frames:
            lm.fuse(f, pose)
        c = list(lm.stats.fuse_cpu_ms)[1:]  # the first builds the grid
        t0 = time.thread_time()
        n = lm.publish()
        pub = (time.thread_time() - t0) * 1000.0
        print(
            f"  stride {stride:2d} ({640 // stride} x {480 // stride} samples): median "
            f"{statistics.median(c):.2f} ms, p99 {pct(c, 99):.2f} ms; cutting {n} tiles "
            f"{pub:.1f} ms"
        )
        if stride == 8:
            keep = lm
    assert keep is not None
    return keep


def live(
    frames: list[tuple[Frame, VehiclePose]], cam: CameraIntrinsics, seconds: float, with_map: bool
) -> dict[str, float]:
    period = 1.0 / FPS
    late: list[float] = []
    worker_offer_ns: list[int] = []
    lm = LiveMap(cam, CameraMount(), LiveMapConfig()) if with_map else None
    with DetectionWorker(cam, DEFAULT) as worker:
        if lm is not None:
            lm.__enter__()
        t0 = time.monotonic()
        i = 0
        cpu0 = time.process_time()
        while time.monotonic() - t0 < seconds:
            due = t0 + i * period
            now = time.monotonic()
            if now < due:
                time.sleep(due - now)
            f, pose = frames[i % len(frames)]
            f = Frame(i, f.rgb, f.depth, time.monotonic_ns(), 0)
            t_offer = time.perf_counter_ns()
            worker.offer(f)  # what a frame costs capture to hand to the detector
            worker_offer_ns.append(time.perf_counter_ns() - t_offer)
            if lm is not None:
                lm.offer(f, pose)
            late.append((time.monotonic() - due) * 1000.0)
            worker.results()
            i += 1
        cpu = time.process_time() - cpu0
        done = worker.stats().done
        if lm is not None:
            lm.close()
    out = {
        "captured": i,
        "late_median_ms": statistics.median(late),
        "late_p99_ms": pct(late, 99),
        "late_max_ms": max(late),
        "detector_fps": done / seconds,
        "detector_offer_median_us": statistics.median(worker_offer_ns) / 1000.0,
        "detector_offer_p99_us": pct([float(v) for v in worker_offer_ns], 99) / 1000.0,
        "process_cpu_ms_per_frame": cpu * 1000.0 / i,
    }
    if lm is not None:
        s = lm.stats
        out.update(
            map_ms_per_frame=s.cpu_ms / max(s.offered, 1),
            fused=s.fused,
            fuse_median_ms=statistics.median(s.fuse_cpu_ms),
            fuse_p99_ms=pct(s.fuse_cpu_ms, 99),
            publish_median_ms=statistics.median(s.publish_cpu_ms) if s.publish_cpu_ms else 0.0,
            offer_median_us=statistics.median(s.offer_ns) / 1000.0,
            offer_p99_us=pct([float(v) for v in s.offer_ns], 99) / 1000.0,
        )
    return out


def on_air(n_bytes: int) -> int:
    """MAVLink bytes of one picture: handshake + ENCAPSULATED_DATA frames (12 B framing)."""
    return 12 + 13 + math.ceil(n_bytes / CARD_PAYLOAD) * (12 + 2 + CARD_PAYLOAD)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--repeats", type=int, default=2, help="runs with and without, alternated")
    a = ap.parse_args(argv)
    py = sys.version.split()[0]
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; python {py}")
    t0 = time.monotonic()
    frames, cam = render_frames(a.frames)
    print(f"rendered {len(frames)} frames in {time.monotonic() - t0:.0f} s")
    lm = fuse_alone(frames, cam)
    for rep in range(a.repeats):  # alternated: the machine's load drifts
        for with_map in (False, True):
            r = live(frames, cam, a.seconds, with_map)
            what = "with" if with_map else "without"
            print(
                f"live {what} the map, run {rep + 1} ({a.seconds:g} s at 30 fps), load "
                f"{os.getloadavg()[0]:.1f}:"
            )
            print(
                "  "
                + ", ".join(
                    f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()
                )
            )
    s = lm.stats
    cov, ortho = s.tile_bytes["cov"], s.tile_bytes["ortho"]
    cov_air, ortho_air = on_air(int(statistics.median(cov))), on_air(int(statistics.median(ortho)))
    tiles = lm.outbox()
    layers = lm.map.layers() if lm.map is not None else None
    seen_ha = float(layers.seen.sum()) * lm.config.cell_m**2 / 1e4 if layers is not None else 0.0
    tile_ha = (lm.config.tile_m**2) / 1e4
    air = sum(on_air(len(b)) for b in tiles.values())
    print(
        f"tiles ({lm.config.tile_cells} x {lm.config.tile_cells} cells of "
        f"{lm.config.cell_m * 100:.0f} cm = {lm.config.tile_m:.1f} m): coverage median "
        f"{statistics.median(cov):.0f} B ({cov_air} B on air), "
        f"orthophoto {statistics.median(ortho):.0f} B ({ortho_air} B on air)"
    )
    n_tiles = len(tiles) // 2
    print(
        f"this lap: {n_tiles} tile places, {seen_ha * 1e4:.0f} m2 seen, {air} B on air for all "
        f"tiles once = {air / max(seen_ha, 1e-9) / 1000:.0f} kB per seen hectare; a hectare "
        f"fully seen is {1 / tile_ha:.0f} tile places = "
        f"{(cov_air + ortho_air) / tile_ha / 1000:.0f} kB"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
