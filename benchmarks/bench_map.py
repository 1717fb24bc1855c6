"""The search map, measured against the simulator's world: cost, placement, seams, sizes.

    python benchmarks/bench_map.py [--field 30 | --field 0] [--out DIR] [--log FLIGHT.mcap]

1. **Per-frame cost** of :meth:`mapping.SearchMap.add_frame` on simulated 640x480 frames,
   OpenCV on one thread (median and p99 of the thread's CPU time and of wall time), for the
   ground's 2 cm
   cells (auto stride and stride 4) and coarse on-board-like 10 cm cells.
2. **A field** ``--field`` metres square (default 30) flown as the planner's lawnmower at
   2.5 m with 30 % side overlap, a frame every 0.5 m, fused at 2 cm: the orthophoto's and
   surface's **placement** against the world (phase correlation of the map's heights with
   the world's height field on the same cells: the offset in metres) and the height error;
   **seams**: heights of consecutive frames, and of neighbouring lanes, in the cells both
   saw (median |dh|); the same with a 1 deg attitude error per frame (random roll/pitch,
   what the error model assumes for a real autopilot) to show what pose errors do; the
   **file sizes** of the GeoTIFFs, KMZ and gaps; the searched fraction.
3. With ``--log``: ``holescan reprocess`` of that flight with the map (2 cm, every 3rd and
   every 5th frame) and without (``--map-cell 0``), 2 workers, no cache: frames/s of each.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from holescan.detect import CameraIntrinsics
from holescan.geotag import LocalCameraPose
from holescan.mapping import MapGrid, SearchMap
from holescan.missions import SurveyParams, plan_survey
from holescan.sim import (
    DEFAULT_ANCHOR,
    CameraPose,
    make_world,
    render,
    world_area,
)

CAM = CameraIntrinsics.xtion()


def _pct(v: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(v), q))


def per_frame_cost(world, frames) -> None:  # type: ignore[no-untyped-def]
    cv2.setNumThreads(1)  # one core, as on the reprocessing workers (thread_time is one thread's)
    print(
        "1. per-frame cost of add_frame (640x480), ms: thread CPU median / p99; wall median / p99"
    )
    for cell, stride in ((0.02, None), (0.02, 4), (0.10, None)):
        m = SearchMap(MapGrid.covering(0, 0, *world.size_m, cell), DEFAULT_ANCHOR.frame)
        cpu, wall = [], []
        for depth, rgb, pose in frames:
            c0, w0 = time.thread_time(), time.perf_counter()
            m.add_frame(depth, rgb, CAM, pose, pixel_stride=stride)
            cpu.append((time.thread_time() - c0) * 1e3)
            wall.append((time.perf_counter() - w0) * 1e3)
        print(
            f"   {cell * 100:.0f} cm cells, stride {stride or 'auto'}: {np.median(cpu):.1f} / "
            f"{_pct(cpu, 99):.1f}; {np.median(wall):.1f} / {_pct(wall, 99):.1f} ({len(cpu)} frames)"
        )


def _tilt(pose: CameraPose, rng: np.random.Generator, sigma_deg: float) -> CameraPose:
    """The pose with a random roll/pitch error (the map is placed wrongly by it)."""
    if sigma_deg <= 0:
        return pose
    a = np.radians(rng.normal(0.0, sigma_deg, 2))
    rx = cv2.Rodrigues(np.array([a[0], 0.0, 0.0]))[0]
    ry = cv2.Rodrigues(np.array([0.0, a[1], 0.0]))[0]
    return CameraPose(pose.position, rx @ ry @ pose.rotation)


def field(size: float, out: Path | None) -> None:
    world = make_world(11, (size + 4.0, size + 4.0), n_access_holes=max(3, round(size * size / 60)))
    frame = DEFAULT_ANCHOR.frame
    plan = plan_survey(world_area(world, DEFAULT_ANCHOR, 2.0), SurveyParams(altitude_m=2.5))
    lanes = []
    for a, b in plan.lines:
        (ea, na), (eb, nb) = (frame.to_en(w.lat_deg, w.lon_deg) for w in (a, b))
        lanes.append((float(ea), float(na), float(eb), float(nb)))
    views = []  # (lane, pose)
    for k, (ea, na, eb, nb) in enumerate(lanes):
        length = math.hypot(eb - ea, nb - na)
        yaw = math.atan2(eb - ea, nb - na)
        for t in np.arange(0.0, length + 1e-9, 0.5):
            x, y = ea + (eb - ea) * t / length, na + (nb - na) * t / length
            views.append((k, CameraPose.looking_down(x, y, 2.5, yaw=yaw)))
    print(f"2. a {size:g} x {size:g} m field: {len(lanes)} lanes, {len(views)} frames at 2.5 m")

    def rendered():  # type: ignore[no-untyped-def]
        # Rendered again for each pass (the same seed: the same frames); 1 GB+ if kept.
        r = np.random.default_rng(0)
        for k, pose in views:
            rgb, depth, _ = render(world, pose, CAM, r)
            yield k, pose, depth, rgb

    first = [
        (d, c, LocalCameraPose(p.rotation, p.position))
        for (_, p, d, c), _ in zip(rendered(), range(60), strict=False)
    ]
    per_frame_cost(world, first)
    del first
    grid = MapGrid.covering(0.0, 0.0, *world.size_m, 0.02)
    e, n = grid.centres()
    ee, nn = np.meshgrid(e, n)
    truth = world.height_at(np.column_stack([ee.ravel(), nn.ravel()])).reshape(grid.shape)
    for sigma in (0.0, 1.0):
        prng = np.random.default_rng(1)
        m = SearchMap(grid, frame)
        lane_dh: list[float] = []
        lane_prev: np.ndarray | None = None  # heights of the lane before
        lane_map: SearchMap | None = None
        lane_k = -1
        seams = []
        prev = None
        t0 = time.thread_time()
        for i, (k, pose, depth, rgb) in enumerate(rendered()):
            p = _tilt(pose, prng, sigma)
            lp = LocalCameraPose(p.rotation, p.position)
            m.add_frame(depth, rgb, CAM, lp)
            if i % 10 == 0 and i + 1 < len(views) and views[i + 1][0] == k:
                one = SearchMap(
                    MapGrid.covering(
                        p.position[0] - 3,
                        p.position[1] - 3,
                        p.position[0] + 3,
                        p.position[1] + 3,
                        0.02,
                    ),
                    frame,
                )
                one.add_frame(depth, rgb, CAM, lp)
                prev = one.layers()
            elif prev is not None:
                two = SearchMap(prev.grid, frame)
                two.add_frame(depth, rgb, CAM, lp)
                b = two.layers()
                both = np.isfinite(prev.height_m) & np.isfinite(b.height_m)
                if both.sum() > 100:
                    seams.append(float(np.mean(np.abs(prev.height_m[both] - b.height_m[both]))))
                prev = None
            if k != lane_k:  # a new lane: compare the last one with the one before it
                if lane_map is not None:
                    h = lane_map.layers().height_m
                    if lane_prev is not None:
                        both = np.isfinite(lane_prev) & np.isfinite(h)
                        if both.sum() > 100:
                            lane_dh.append(float(np.mean(np.abs(lane_prev[both] - h[both]))))
                    lane_prev = h
                lane_map, lane_k = SearchMap(grid, frame), k
            assert lane_map is not None
            lane_map.add_frame(depth, rgb, CAM, lp)
        fuse_s = time.thread_time() - t0
        lay = m.layers()
        seen = np.isfinite(lay.height_m)
        err = lay.height_m[seen] - truth[seen]
        a = np.where(seen, lay.height_m, np.nanmean(lay.height_m)).astype(np.float32)
        b = truth.astype(np.float32)
        win = cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F)
        (dx, dy), _ = cv2.phaseCorrelate(b - b.mean(), a - a.mean(), win)
        print(
            f"   attitude error {sigma:g} deg: map vs world offset ({dx * 0.02:+.3f}, "
            f"{-dy * 0.02:+.3f}) m east/north; height - world median {np.median(err):+.4f} m, "
            f"p90 |err| {_pct(list(np.abs(err)), 90):.3f} m; seams, mean |dh| in the common "
            f"cells (median over pairs): consecutive "
            f"frames {np.median(seams):.4f} m ({len(seams)} pairs), neighbouring lanes "
            f"{np.median(lane_dh):.4f} m ({len(lane_dh)} pairs); fused in {fuse_s:.0f} s CPU"
        )
        if sigma == 0.0 and out is not None:
            from shapely.geometry import box

            from holescan.ground.searchmap import write_map_outputs

            res = write_map_outputs(
                out,
                f"field{size:g}",
                lay,
                frame,
                [],
                area=box(2, 2, size + 2, size + 2),
                survey=SurveyParams(altitude_m=2.5),
            )
            g = res.gaps
            print(f"   searched {g.searched_fraction:.1%} of the {g.area_m2:.0f} m2 area; files:")
            for kind, path in res.files:
                print(f"     {kind:<16} {path.stat().st_size / 1e6:8.2f} MB  {path.name}")


def reprocess_on_off(log: Path) -> None:
    print(f"3. holescan reprocess {log.name}, 2 workers, no cache:")
    runs = (
        ("map on (2 cm, every 3rd frame: the default)", ["--map-every", "3"]),
        ("map on (2 cm, every 5th frame)", ["--map-every", "5"]),
        ("map off", ["--map-cell", "0"]),
    )
    for label, extra in runs:
        out = Path(tempfile.mkdtemp(prefix="bench_map_"))
        t0 = time.perf_counter()
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "holescan.cli",
                "reprocess",
                str(log),
                "--out",
                str(out),
                "--workers",
                "2",
                "--no-cache",
                *extra,
            ],
            capture_output=True,
            text=True,
            check=False,
        )
        wall = time.perf_counter() - t0
        line = next(
            (x for x in done.stdout.splitlines() if "frames/s over" in x), done.stderr[-300:]
        )
        fused = ""
        summary = out / "summary.json"
        if summary.exists():
            maps = [f.get("map", {}) for f in json.loads(summary.read_text())["flights"]]
            if maps and "fuse_s" in maps[0]:
                fused = (
                    f"; the workers fused {sum(m['frames_fused'] for m in maps)} frames in "
                    f"{sum(m['fuse_s'] for m in maps):.1f} s"
                )
        print(f"   {label}: {line.strip()} (command {wall:.0f} s){fused}")
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--field", type=float, default=30.0)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--log", type=Path)
    a = ap.parse_args()
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
    if a.field > 0:  # --field 0: only the reprocess comparison
        field(a.field, a.out)
    if a.log:
        reprocess_on_off(a.log)


if __name__ == "__main__":
    main()
