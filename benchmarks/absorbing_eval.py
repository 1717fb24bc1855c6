"""Absorbing stains against access holes: the default detector with and without its rim-plane
test, over many stains and holes of the sortie simulator's rubble world.

    python benchmarks/absorbing_eval.py --worlds 51,52,53,54 --frames 12 [--workers 2] [--rgb]

Per world (14 x 14 m: 8 access holes, 24 stains of which two in three are soot, char or wet,
and a few other distractors), ``--frames`` views centred near an absorbing stain and as many
near an access hole, 2-3.5 m above, tilt <= 15 deg, through the structured-light model with
the drone's motion. Truth is the world's: access-hole boxes (``iscrowd`` = cut by the
frame) and the boxes of the absorbing stains. Prints, with the plane test off ("before")
and on: holes found at ``p_hole >= 0.3`` and announced (``>= 0.9``), and detections lying
on an absorbing stain (half the box inside it, matching no hole) shown and announced.
Seeds 31, 32, 41-44 were used to set the test's cut-offs; use others to measure.

``--rgb`` also prints what the colour image says inside the unread part of each detection
shown (``p_hole >= 0.3``) on a hole and on an absorbing stain: its brightness over the read
rim around the box, its core's brightness over its edge's (a void darkens towards its
inside), and its texture (spread of the high-passed log luminance, which an albedo change
leaves unchanged) over the rim's.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
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
    after = [(tuple(d.box), d.p_hole or 0.0) for d in detect_holes(rgb, depth, cam)]
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    return {
        "holes": [(tuple(b.box), bool(b.iscrowd)) for b in boxes],
        "stains": [
            tuple(b.box)
            for b in hole_boxes(world, pose, cam, access_only=False)
            if b.hole_id in ids
        ],
        "before": [(tuple(d.box), d.p_hole or 0.0) for d in detect_holes(rgb, depth, cam, off)],
        "after": after,
        "rgb": [rgb_features(grey, depth, b) if p >= P_SHOWN else None for b, p in after],
    }


# The rim: read pixels within RIM_PX of the box. High-pass: log luminance minus its
# Gaussian blur (sigma HP_SIGMA_PX), after a light blur against shot noise.
RIM_PX = 12
HP_SIGMA_PX = 3.0
FEATURES = ("brightness", "core_over_edge", "texture")


def rgb_features(grey: np.ndarray, depth: np.ndarray, box: Box) -> dict[str, float] | None:
    """Brightness, radial shading and texture of the unread part of ``box`` (None: too small)."""
    x, y, w, h = (int(v) for v in box)
    hh, ww = depth.shape
    x0, y0 = max(0, x - RIM_PX), max(0, y - RIM_PX)
    x1, y1 = min(ww, x + w + RIM_PX), min(hh, y + h + RIM_PX)
    g = cv2.GaussianBlur(grey[y0:y1, x0:x1].astype(np.float32) / 255.0, (0, 0), 1.0)
    unread = depth[y0:y1, x0:x1] == 0
    in_box = np.zeros_like(unread)
    in_box[y - y0 : y - y0 + h, x - x0 : x - x0 + w] = True
    region = cv2.morphologyEx(
        (unread & in_box).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((9, 9), np.uint8)
    )
    dist = cv2.distanceTransform(np.pad(region, 1), cv2.DIST_L2, 3)[1:-1, 1:-1]
    cut = max(2.0, 0.35 * float(dist.max()))
    core, edge = dist >= cut, (dist > 0) & (dist < cut)
    rim = ~in_box & ~unread
    if core.sum() < 20 or edge.sum() < 20 or rim.sum() < 20:
        return None
    lg = np.log(g + 0.02)
    hp = lg - cv2.GaussianBlur(lg, (0, 0), HP_SIGMA_PX)
    y_core, y_rim = float(g[core].mean()), float(g[rim].mean())
    return {
        "brightness": y_core / max(y_rim, 1e-3),
        "core_over_edge": y_core / max(float(g[edge].mean()), 1e-3),
        "texture": float(hp[core].std()) / max(float(hp[rim].std()), 1e-4),
    }


def rgb_table(frames: list[dict[str, Any]]) -> list[str]:
    """Per feature: percentiles over announced holes, and each absorbing stain shown."""
    holes: list[dict[str, float]] = []
    stains: list[tuple[float, dict[str, float]]] = []
    for fr in frames:
        for (b, p), feat in zip(fr["after"], fr["rgb"], strict=True):
            if feat is None:
                continue
            if any(_iou(b, hb) > 0.5 and not crowd for hb, crowd in fr["holes"]):
                if p >= P_ANNOUNCED:
                    holes.append(feat)
            elif not any(_iou(b, hb) > 0.5 for hb, _ in fr["holes"]) and any(
                _inside(b, s) >= 0.5 for s in fr["stains"]
            ):
                stains.append((p, feat))
    lines = [
        f"| feature | announced holes ({len(holes)}): 5 / 25 / 50 / 75 / 95 % | "
        "absorbing stains shown (p_hole: value) |",
        "|---|---|---|",
    ]
    for k in FEATURES:
        q = np.percentile([f[k] for f in holes], [5, 25, 50, 75, 95]) if holes else []
        st = ", ".join(f"{p:.2f}: {f[k]:.2f}" for p, f in sorted(stains, key=lambda t: -t[0]))
        lines.append(f"| {k} | {' / '.join(f'{v:.2f}' for v in q)} | {st} |")
    return lines


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
    ap.add_argument("--rgb", action="store_true", help="also the colour image's evidence")
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
    if args.rgb:
        print("\n".join(["", *rgb_table(frames)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
