"""Absorbing stains against access holes: the default detector with and without its rim-plane
test, over many stains and holes of the sortie simulator's rubble world.

    python benchmarks/absorbing_eval.py --worlds 51,52,53,54 --frames 12 [--workers 2] [--rgb]
    python benchmarks/absorbing_eval.py --worlds 51,52,53,54 --frames 12 --holes

Per world (14 x 14 m: 8 access holes, 24 stains of which two in three are soot, char or wet,
and a few other distractors), ``--frames`` views centred near an absorbing stain and as many
near an access hole, 2-3.5 m above, tilt <= 15 deg, through the structured-light model with
the drone's motion. Truth is the world's: access-hole boxes (``iscrowd`` = cut by the
frame) and the boxes of the absorbing stains. Prints, with the plane test off ("before")
and on: holes found at ``p_hole >= 0.3`` and announced (``>= 0.9``), and detections lying
on an absorbing stain (half the box inside it, matching no hole) shown and announced.
Seeds 31, 32, 41-44 were used to set the test's cut-offs; use others to measure.

``--holes`` measures the hole level instead (what reaches the crew): per world, a straight
pass over each absorbing stain and each access hole (``--frames`` views 0.25 m apart, 2.5-
3.5 m above, a small random tilt, the structured-light model under the vehicle's motion),
every frame detected, geotagged and merged by :class:`geotag.HoleTracker`; then each hole's
tier by :class:`geotag.AnnounceGate` three ways on the same holes: without the
absorbing-surface vote ("vote off"), with it but without holding unread holes seen only at
the image's edge ("before") and the default gate ("after"). Per stain the best tier of the
holes lying on it (inside its outline or within 0.5 m of its centre, not at an access
hole); per access hole the best tier of the holes at its opening; every hole of every pass
by where it lies; and each hole announced elsewhere (on neither) traced: the world's
nearest feature of any kind and its distance, its views, plane readings and sightings
(score, verdict, cut by the image border). ``--save`` keeps the passes; ``--tables`` prints
the tables of saved passes again (under the gate of the checkout that runs it).

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


def _world(wseed: int) -> Any:
    from holescan.sim import make_world

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
    return _WORLDS[wseed]


def _absorbing_stains(world: Any) -> list[Any]:
    def absorbing(h: Any) -> bool:
        r, c = (round(v / world.cell_m) for v in h.centre_xy[::-1])
        return bool(world.ir_unread[r, c] > 0)

    return [h for h in world.holes if h.kind == "stain" and absorbing(h)]


def _frame(job: tuple[int, int, str]) -> dict[str, Any]:
    from holescan.detect import DEFAULT, CameraIntrinsics, detect_holes
    from holescan.sim import CameraPose, hole_boxes, random_conditions, render
    from holescan.sim.structured_light import random_motion

    wseed, i, mode = job
    world = _world(wseed)
    rng = np.random.default_rng([wseed, i, 0 if mode == "stain" else 1])
    stains = _absorbing_stains(world)
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


# A pass: views STEP_M apart along a random heading, the vehicle at PASS_SPEED_M_S.
STEP_M = 0.25
PASS_SPEED_M_S = 0.8
_TIER_RANK = {"none": 0, "candidate": 1, "review": 2, "announced": 3}


def _pass(job: tuple[int, int, str, int]) -> dict[str, Any]:
    """One pass over a target (an absorbing stain or an access hole): the holes it made
    and which lie on the target, on an absorbing stain or at an access hole."""
    from shapely.geometry import Point, Polygon

    from holescan.detect import CameraIntrinsics, detect_holes
    from holescan.geotag import CameraMount, HolePipeline, VehiclePose
    from holescan.sim import (
        DEFAULT_ANCHOR,
        camera_pose_in_world,
        image_motion,
        random_conditions,
        render,
    )

    wseed, i, mode, n_frames = job
    world = _world(wseed)
    stains = _absorbing_stains(world)
    pool = stains if mode == "stain" else list(world.access_holes)
    target = pool[i]
    rng = np.random.default_rng([wseed, i, 2 if mode == "stain" else 3])
    cam, mount, anchor = CameraIntrinsics.xtion(), CameraMount(), DEFAULT_ANCHOR
    heading = float(rng.uniform(0, 2 * math.pi))
    d = (math.sin(heading), math.cos(heading))
    side = float(rng.normal(0, 0.3))
    above = float(rng.uniform(2.5, 3.5))
    pipe = HolePipeline(cam, mount)
    sx, sy = world.size_m

    def pose_at(k: float, roll: float, pitch: float) -> VehiclePose:
        along = (k - (n_frames - 1) / 2) * STEP_M
        x = float(np.clip(target.centre_xy[0] + along * d[0] - side * d[1], 1.5, sx - 1.5))
        y = float(np.clip(target.centre_xy[1] + along * d[1] + side * d[0], 1.5, sy - 1.5))
        lat, lon, alt = anchor.to_geodetic(x, y, target.rim_z + above)
        t = round((10.0 + k * STEP_M / PASS_SPEED_M_S) * 1e9)
        return VehiclePose(t, lat, lon, alt, above, roll, pitch, heading)

    for k in range(n_frames):
        roll, pitch = (math.radians(float(v)) for v in rng.normal(0, 4, 2))
        pose = pose_at(k, roll, pitch)
        cam_pose = camera_pose_in_world(pose, mount, anchor)
        dk = 0.01 * PASS_SPEED_M_S / STEP_M
        later = camera_pose_in_world(pose_at(k + dk, roll, pitch), mount, anchor)
        motion = image_motion(cam_pose, later, cam, 0.01)
        rgb, depth, _ = render(world, cam_pose, cam, rng, random_conditions(rng), motion)
        pipe.add(k, detect_holes(rgb, depth, cam), lambda pose=pose: pose)

    def where(h: Any) -> tuple[str, int]:
        x, y, _ = anchor.to_world(h.lat_deg, h.lon_deg, h.alt_m)
        pt = Point(float(x), float(y))
        for kind, group in (("hole", world.access_holes), ("stain", stains)):
            for t in group:
                near = math.hypot(float(x) - t.centre_xy[0], float(y) - t.centre_xy[1]) <= 0.5
                if near or Polygon(t.opening).contains(pt):
                    return kind, t.id
        return "other", -1

    def nearest(h: Any) -> tuple[str, float, bool]:
        """The world's nearest feature of any kind: its kind, distance (m), inside it."""
        x, y, _ = anchor.to_world(h.lat_deg, h.lon_deg, h.alt_m)
        pt = Point(float(x), float(y))
        best = ("terrain", math.inf, False)
        for t in world.holes:
            poly = Polygon(t.opening)
            dist = float(poly.distance(pt))
            if dist < best[1]:
                kind = "absorbing stain" if t in stains else t.kind
                best = (kind, dist, bool(poly.contains(pt)))
        return best

    holes = pipe.holes()
    print(f"  pass {wseed}/{mode} {target.id} done", file=sys.stderr, flush=True)
    return {
        "mode": mode,
        "target": (wseed, target.id),
        "holes": [(h, *where(h)) for h in holes],
        "near": {h.id: nearest(h) for h in holes},
        "sightings": {
            h.id: [
                (s.frame_index, round(s.score, 3), s.plane, s.cut_by_border)
                for s in pipe.tracker.sightings_of(h.id)
            ]
            for h in holes
        },
    }


def _gates() -> dict[str, Any]:
    """The gates compared on the same holes: without the absorbing-surface vote, as before
    (the vote, no hold for holes seen only at the image's edge), and the default."""
    from holescan.geotag import AnnounceGate

    return {
        "vote off": AnnounceGate(
            surface_min_views=10**9, surface_tie_views=0, edge_behind_views=0
        ),
        "before": AnnounceGate(surface_tie_views=0, edge_behind_views=0),
        "after": AnnounceGate(),
    }


def _trace(r: dict[str, Any], h: Any) -> str:
    """A hole's evidence in one line, its sightings as score + verdict initial (s surface,
    b behind, u unread, m mixed, - not measured) + c when cut by the image border."""
    near_kind, dist, inside = r["near"][h.id]
    sights = " ".join(
        f"{sc:.2f}{(pl or '-')[0]}{'c' if cut else ''}" for _, sc, pl, cut in r["sightings"][h.id]
    )
    return (
        f"hole {h.id}: p_hole {h.p_hole:.2f}, views {h.views}, plane views "
        f"{h.plane_views} (surface {h.surface_views}, behind {h.behind_views}), seen whole "
        f"{h.seen_whole}; nearest {near_kind} {'(inside)' if inside else f'{dist:.2f} m'}; "
        f"sightings {sights}"
    )


def holes_table(passes: list[dict[str, Any]]) -> list[str]:
    """Per target kind, the tier its own pass gave it (the best of the holes lying on it)
    per gate; every hole of every pass by where it lies; the holes elsewhere announced,
    traced to the world's nearest feature; the holes the default gate holds back."""
    gates = _gates()
    tiers: dict[str, list[tuple[str, str]]] = {g: [] for g in gates}
    held: list[str] = []
    others: dict[str, list[str]] = {g: [] for g in gates}
    for p in passes:
        wseed, tid = p["target"]
        where = f"{wseed} pass over {p['mode']} {tid}"
        for g, gate in gates.items():
            best = "none"
            for h, kind, at in p["holes"]:
                t = gate.tier(h)
                if kind == "other" and t == "announced":
                    others[g].append(f"{where}: {_trace(p, h)}")
                elif (kind, at) == (p["mode"], tid) and _TIER_RANK[t] > _TIER_RANK[best]:
                    best = t
            tiers[g].append((p["mode"], best))
        after, before = gates["after"], gates["before"]
        for h, kind, at in p["holes"]:
            if after.tier(h) != before.tier(h) or after.surface_held(h):
                why = "edge" if after.edge_held(h) else "vote"
                held.append(
                    f"{kind} {at} ({where}), {before.tier(h)} -> {after.tier(h)} ({why}): "
                    f"{_trace(p, h)}"
                )
    lines = [
        "| pass over | gate | announced | review | candidate | not found |",
        "|---|---|---|---|---|---|",
    ]
    for kind, name in (("stain", "absorbing stains"), ("hole", "access holes")):
        n = sum(m == kind for m, _ in tiers["after"])
        for g in gates:
            c = {t: sum(m == kind and v == t for m, v in tiers[g]) for t in _TIER_RANK}
            lines.append(
                f"| {name} ({n}) | {g} | {c['announced']} | {c['review']} | "
                f"{c['candidate']} | {c['none']} |"
            )
    # Every hole of every pass (a stain is often seen in a pass over a hole nearby)
    lines += [
        "",
        "| holes of all passes, lying | gate | announced | review | candidate |",
        "|---|---|---|---|---|",
    ]
    for kind, name in (
        ("stain", "on an absorbing stain"),
        ("hole", "at an access hole"),
        ("other", "elsewhere"),
    ):
        found = [h for p in passes for h, k, _ in p["holes"] if k == kind]
        for g, gate in gates.items():
            c = {t: sum(gate.tier(h) == t for h in found) for t in _TIER_RANK}
            lines.append(
                f"| {name} ({len(found)}) | {g} | {c['announced']} | {c['review']} | "
                f"{c['candidate']} |"
            )
    for g in gates:
        lines.append(f"\nholes announced elsewhere (on neither), {g}: {len(others[g])}")
        lines += [f"  {s}" for s in others[g]]
    lines.append(f"\nholes the default gate holds back ({len(held)}):")
    lines += [f"  {s}" for s in held]
    return lines


def plane_views_table(passes: list[dict[str, Any]]) -> list[str]:
    """Per hole on a target: its evidence (:func:`_trace`) and tier (for tuning)."""
    gate = _gates()["after"]
    lines = []
    for p in passes:
        for h, kind, tid in p["holes"]:
            if kind != "other":
                lines.append(f"  {kind} {p['target'][0]}/{tid} {gate.tier(h)}: {_trace(p, h)}")
    return sorted(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", default="51,52,53,54", help="comma-separated world seeds")
    ap.add_argument("--frames", type=int, default=12, help="views per world and kind")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rgb", action="store_true", help="also the colour image's evidence")
    ap.add_argument("--holes", action="store_true", help="hole level: passes, tracker, tiers")
    ap.add_argument("--verbose", action="store_true", help="with --holes: every hole's views")
    ap.add_argument("--save", type=Path, help="with --holes: pickle the passes' holes here")
    ap.add_argument("--tables", type=Path, help="the --holes tables of passes saved before")
    args = ap.parse_args(argv)
    try:
        seeds = [int(s) for s in args.worlds.split(",")]
    except ValueError:
        print(f"--worlds {args.worlds!r}: expected comma-separated integers", file=sys.stderr)
        return 2
    if args.frames < 1 or args.workers < 1:
        print("--frames and --workers must be at least 1", file=sys.stderr)
        return 2
    if args.tables is not None:
        return _tables_of(args.tables)
    if args.holes:
        return _main_holes(seeds, args.frames, args.workers, args.verbose, args.save)
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


def _tables_of(saved: Path) -> int:
    """The tables of passes saved before (``--save``), e.g. under another gate."""
    import pickle

    passes = pickle.loads(saved.read_bytes())
    print("\n".join(holes_table(passes)))
    return 0


def _main_holes(
    seeds: list[int], frames: int, workers: int, verbose: bool, save: Path | None
) -> int:
    jobs = []
    for s in seeds:
        world = _world(s)
        inside = [
            (m, h)
            for m, group in (("stain", _absorbing_stains(world)), ("hole", world.access_holes))
            for h in group
        ]
        counts = {"stain": 0, "hole": 0}
        for m, _ in inside:
            jobs.append((s, counts[m], m, frames))
            counts[m] += 1
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        passes = pool.map(_pass, jobs, chunksize=4)
    if save is not None:
        import pickle

        save.write_bytes(pickle.dumps(passes))
    print(f"worlds {','.join(map(str, seeds))}: {len(passes)} passes of {frames} frames")
    print("\n".join(holes_table(passes)))
    if verbose:
        print("\n".join(plane_views_table(passes)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
