"""Absorbing stains against access holes: the default detector with and without its rim-plane
test, over many stains and holes of the sortie simulator's rubble world.

    python benchmarks/absorbing_eval.py --worlds 51,52,53,54 --frames 12 [--workers 2]

Per world (14 x 14 m: 8 access holes, 24 stains of which two in three are soot, char or wet,
and a few other distractors), ``--frames`` views centred near an absorbing stain and as many
near an access hole, 2-3.5 m above, tilt <= 15 deg, through the structured-light model with
the drone's motion. Truth is the world's: access-hole boxes (``iscrowd`` = cut by the
frame) and the boxes of the absorbing stains. Prints, with the plane test off ("before")
and on: holes found at ``p_hole >= 0.3`` and announced (``>= 0.9``), and detections lying
on an absorbing stain (half the box inside it, matching no hole) shown and announced.
Seeds 31, 32, 41-44 were used to set the test's cut-offs; use others to measure.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

P_SHOWN = 0.3
P_ANNOUNCED = 0.9
Box = tuple[float, float, float, float]

_WORLDS: dict[int, Any] = {}


def _frame(job: tuple[int, int, str]) -> dict[str, Any]:
    from holescan.detect import DEFAULT, CameraIntrinsics, detect_holes
    from holescan.sim import CameraPose, hole_boxes, make_world, random_conditions, render
    from holescan.sim.structured_light import random_motion

    wseed, i, mode = job
    if wseed not in _WORLDS:
        _WORLDS.clear()
        _WORLDS[wseed] = make_world(
            wseed,
            (14.0, 14.0),
            n_access_holes=8,
            n_stains=24,
            n_small_holes=4,
            n_cracks=4,
            n_depressions=4,
            n_shadows=4,
        )
    world = _WORLDS[wseed]
    rng = np.random.default_rng([wseed, i, 0 if mode == "stain" else 1])

    def absorbing(h: Any) -> bool:
        r, c = (round(v / world.cell_m) for v in h.centre_xy[::-1])
        return bool(world.ir_unread[r, c] > 0)

    stains = [h for h in world.holes if h.kind == "stain" and absorbing(h)]
    pool = stains if mode == "stain" else list(world.access_holes)
    target = pool[i % len(pool)]
    sx, sy = world.size_m
    cx = float(np.clip(target.centre_xy[0] + rng.normal(0, 0.4), 2.0, sx - 2.0))
    cy = float(np.clip(target.centre_xy[1] + rng.normal(0, 0.3), 2.0, sy - 2.0))
    above = float(rng.uniform(2.0, 3.5))
    pose = CameraPose.looking_down(
        cx,
        cy,
        target.rim_z + above,
        yaw=float(rng.uniform(0, 2 * math.pi)),
        tilt=math.radians(float(rng.uniform(0, 15))),
        tilt_heading=float(rng.uniform(0, 2 * math.pi)),
    )
    cam = CameraIntrinsics.xtion()
    cond = random_conditions(rng)
    rgb, depth, boxes = render(world, pose, cam, rng, cond, random_motion(rng, cam.fx, above))
    ids = {h.id for h in stains}
    off = replace(DEFAULT, options=replace(DEFAULT.options, surface_plane=False))
    return {
        "holes": [(tuple(b.box), bool(b.iscrowd)) for b in boxes],
        "stains": [
            tuple(b.box)
            for b in hole_boxes(world, pose, cam, access_only=False)
            if b.hole_id in ids
        ],
        "before": [(tuple(d.box), d.p_hole or 0.0) for d in detect_holes(rgb, depth, cam, off)],
        "after": [(tuple(d.box), d.p_hole or 0.0) for d in detect_holes(rgb, depth, cam)],
    }


def _iou(a: Box, b: Box) -> float:
    ix = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    return ix * iy / max(a[2] * a[3] + b[2] * b[3] - ix * iy, 1e-9)


def _inside(a: Box, b: Box) -> float:
    ix = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    return ix * iy / max(a[2] * a[3], 1e-9)


def summary(frames: list[dict[str, Any]], key: str) -> dict[str, int]:
    """Counts over ``frames`` for the detections under ``key`` ("before" or "after")."""
    out = dict.fromkeys(("holes", "found", "announced", "on_stain", "stain_announced"), 0)
    for fr in frames:
        dets = fr[key]
        for box, crowd in fr["holes"]:
            if crowd:
                continue
            ps = [p for b, p in dets if _iou(b, box) > 0.5]
            out["holes"] += 1
            out["found"] += bool(ps) and max(ps) >= P_SHOWN
            out["announced"] += bool(ps) and max(ps) >= P_ANNOUNCED
        for b, p in dets:
            if p < P_SHOWN or any(_iou(b, h) > 0.5 for h, _ in fr["holes"]):
                continue
            if any(_inside(b, s) >= 0.5 for s in fr["stains"]):
                out["on_stain"] += 1
                out["stain_announced"] += p >= P_ANNOUNCED
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", default="51,52,53,54", help="comma-separated world seeds")
    ap.add_argument("--frames", type=int, default=12, help="views per world and kind")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    try:
        seeds = [int(s) for s in args.worlds.split(",")]
    except ValueError:
        print(f"--worlds {args.worlds!r}: expected comma-separated integers", file=sys.stderr)
        return 2
    if args.frames < 1 or args.workers < 1:
        print("--frames and --workers must be at least 1", file=sys.stderr)
        return 2
    jobs = [(s, i, m) for s in seeds for m in ("stain", "hole") for i in range(args.frames)]
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        frames = pool.map(_frame, jobs, chunksize=args.frames)
    n_stains = sum(len(f["stains"]) for f in frames)
    print(f"worlds {args.worlds}: {len(frames)} frames, {n_stains} absorbing stains in view")
    print(
        "| plane test | holes found p>=0.3 | announced | on absorbing stains p>=0.3 | announced |"
    )
    print("|---|---|---|---|---|")
    for key in ("before", "after"):
        r = summary(frames, key)
        print(
            f"| {'off' if key == 'before' else 'on'} | {r['found']}/{r['holes']} | "
            f"{r['announced']}/{r['holes']} | {r['on_stain']} | {r['stain_announced']} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
