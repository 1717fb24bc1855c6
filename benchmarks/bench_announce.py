#!/usr/bin/env python3
"""What is worth announcing: p_hole, sightings and time span of true and false holes.

For each simulated world (``SortieParams(world_seed=S)``, the demo's 10 x 10 m survey at
3 m with the full set of distractors: small holes, cracks, depressions, stains, shadows),
one lap of the survey is rendered from the simulated autopilot's true pose at ``--fps``
frames per second (the flight's detector keeps up with ~18 of the camera's 30 fps), each
frame is detected and the detections merged into holes by the flight's own
:class:`geotag.HolePipeline` (GPS accuracy reported as in the demo, 1.2 m). Every change
of every hole is recorded (time, best score, sightings, time span of its sightings). The
final holes are scored against the world's truth (:func:`demo.score_holes`: a hole within
0.5 m of a true access hole's centre, or inside its opening, is true).

A hole's ``p_hole`` is its hole-level confidence (:attr:`geotag.Hole.p_hole`, the
tracker's :class:`geotag.ConfidenceModel` over all its sightings), recorded at every
change. Then each gate ``AnnounceGate(min_p_hole=p, min_sightings=n, min_span_s=t)`` of a
grid is replayed over the recorded histories with :meth:`geotag.AnnounceGate.tier`: a hole
is delivered (announced) at the first change whose tier is ``announced``, and it is a
review item when it reached ``review`` (``--review-min-p-hole``) and was never announced.
Printed: the best score, p_hole, sightings and span distributions of true and false holes
(all, and those seen twice over 0.3 s), and per gate the delivered precision, the recall of
holes in view (whole in >= 3 frames), the time from first sighting to delivery (median,
max), the review items and the recall of announced + review. Histories of a ``--json``
from before hole-level p_hole (4 numbers per change) fall back to the best frame's
p_hole, as the gate does for old logs, and say so.

Also (``--alien DATASET``): per-detection scores and p_hole of true and false detections
on the independent scenes of ``benchmarks/alien_scenes.py`` (IoU > 0.5 with an access
hole): single frames, where the hole-level p_hole is the best frame's. ``--load JSON``
replays the histories of an earlier ``--json`` run.

Usage::

    nice python benchmarks/bench_announce.py --seeds 1-8 --fps 10 --jobs 2 --json out.json \
        --alien DATASET

docs/tiers.md's figures come from ``benchmarks/bench_tiers.py`` (surveys, hovers and passes
on the structured-light sensor); this benchmark's tables there were measured on the ideal
sensor and were removed when the tiers were measured again.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from holescan.demo import count_in_view, score_holes
from holescan.detect import CameraIntrinsics, detect_holes, p_hole_of_score
from holescan.geotag import AnnounceGate, CameraMount, Hole, HolePipeline, Tier, VehiclePose
from holescan.sim import (
    Conditions,
    SimAutopilot,
    SortieParams,
    camera_pose_in_world,
    image_motion,
    loop_length_m,
    make_sortie_world,
    random_conditions,
    render,
    survey_path,
    true_holes,
)

#: Frames are rendered as the sortie's camera renders them: the structured-light sensor
#: (``Conditions()``' default) under the vehicle's image motion, measured over this step.
MOTION_DT_NS = 10_000_000


def fly_world(seed: int, fps: float) -> dict[str, Any]:
    """One lap over world ``seed``: hole histories and their truth."""
    p = SortieParams(world_seed=seed, n_access_holes=4, fps=fps)
    world = make_sortie_world(p)
    _, path = survey_path(world, p)
    ap = SimAutopilot("udpout:127.0.0.1:9", path, uptime_at_start_s=p.clock_offset_s)
    camera = CameraIntrinsics.xtion()
    mount = CameraMount()
    pipeline = HolePipeline(camera, mount)
    n = int(loop_length_m(path) / path.speed_m_s * fps)
    history: dict[int, list[tuple[float, float, int, float, float]]] = {}
    boxes_seen = []
    t0 = time.perf_counter()
    for k in range(n):
        t_boot = round(p.clock_offset_s * 1e9) + round(k * 1e9 / fps)
        truth_pose = ap.truth_pose(t_boot)
        pose = VehiclePose(**{**truth_pose.__dict__, "eph_m": p.eph_m})
        rng = np.random.default_rng((seed, k))
        cond = random_conditions(rng, Conditions())
        cam_pose = camera_pose_in_world(pose, mount, p.anchor)
        later = camera_pose_in_world(ap.truth_pose(t_boot + MOTION_DT_NS), mount, p.anchor)
        motion = image_motion(cam_pose, later, camera, MOTION_DT_NS * 1e-9)
        rgb, depth, boxes = render(world, cam_pose, camera, rng, cond, motion)
        boxes_seen.append(boxes)
        dets = detect_holes(rgb, depth, camera)
        step = pipeline.add(k, dets, lambda pose=pose: pose)
        for h in step.changed:
            span = (h.t_last_boot_ns - h.t_first_boot_ns) * 1e-9
            entry = (k / fps, h.score, h.sightings, span, AnnounceGate().p_hole(h))
            history.setdefault(h.id, []).append(entry)
    holes = pipeline.holes()
    truth = true_holes(world, p.anchor)
    rows, false = score_holes(holes, truth, world, p.anchor, count_in_view(boxes_seen))
    in_view = {r.truth.id for r in rows if r.status != "not in view"}
    seen = count_in_view(boxes_seen)
    # the holes a crew sent to would find each true hole at (duplicates included)
    finds: dict[int, list[int]] = {t.id: [] for t in truth}
    for h in holes:
        for t in truth:
            r, _ = score_holes([h], [t], world, p.anchor, seen)
            if r[0].status == "found":
                finds[t.id].append(h.id)
    true_ids = {i for ids in finds.values() for i in ids}
    match_for = {str(t): ids for t, ids in finds.items() if t in in_view}
    false_kind = {f.hole.id: f.nearest for f in false}
    return {
        "seed": seed,
        "frames": n,
        "seconds": time.perf_counter() - t0,
        "holes": [
            {
                "id": h.id,
                "true": h.id in true_ids,
                "nearest": false_kind.get(h.id, "access hole"),
                "history": history[h.id],
            }
            for h in holes
        ],
        "truth_in_view": match_for,
    }


def p_hole_of(entry: list[float]) -> float:
    """The hole-level p_hole of a history entry (old histories: the best frame's)."""
    return entry[4] if len(entry) > 4 else p_hole_of_score(entry[1])


def tier_of(gate: AnnounceGate, entry: list[float]) -> Tier:
    """:meth:`AnnounceGate.tier` of a hole as one history entry recorded it."""
    _, score, k, span = entry[:4]
    hole = Hole(
        0, 0.0, 0.0, 0.0, 0.0, score, int(k), 0, round(span * 1e9), None, (0, 0, 1, 1), 0.0,
        0.0, p_hole=p_hole_of(entry),
    )  # fmt: skip
    return gate.tier(hole)


def replay(
    worlds: list[dict[str, Any]], p: float, n: int, span: float, review_p: float
) -> dict[str, Any]:
    """The tier gate (``p_hole >= p``, ``n`` sightings over ``span`` s; review at
    ``review_p``) over the histories."""
    gate = AnnounceGate(min_p_hole=p, min_sightings=n, min_span_s=span, review_min_p_hole=review_p)
    delivered = true_delivered = reviews = true_reviews = 0
    latency = []
    in_view = found = found_or_review = 0
    for w in worlds:
        first_pass: dict[int, float] = {}
        reviewed: set[int] = set()
        for h in w["holes"]:
            t_first = h["history"][0][0]
            for entry in h["history"]:
                tier = tier_of(gate, entry)
                if tier == "announced":
                    first_pass[h["id"]] = entry[0] - t_first
                    break
                if tier == "review":
                    reviewed.add(h["id"])
        reviewed -= set(first_pass)
        for h in w["holes"]:
            reviews += h["id"] in reviewed
            true_reviews += h["id"] in reviewed and h["true"]
        for h in w["holes"]:
            if h["id"] in first_pass:
                delivered += 1
                true_delivered += h["true"]
        for cands in w["truth_in_view"].values():
            in_view += 1
            got = [first_pass[c] for c in cands if c in first_pass]
            if got:
                found += 1
                latency.append(min(got))
            found_or_review += bool(got) or any(c in reviewed for c in cands)
    return {
        "p_hole": p,
        "sightings": n,
        "span_s": span,
        "delivered": delivered,
        "precision": true_delivered / delivered if delivered else math.nan,
        "recall": found / in_view if in_view else math.nan,
        "in_view": in_view,
        "latency_median_s": statistics.median(latency) if latency else math.nan,
        "latency_max_s": max(latency) if latency else math.nan,
        "review": reviews,
        "review_true": true_reviews,
        "recall_with_review": found_or_review / in_view if in_view else math.nan,
    }


def alien_scores(dataset: Path) -> dict[str, list[float]]:
    """Per-detection scores on an alien dataset: true (IoU > 0.5 with an access hole), false."""
    import cv2

    from holescan.detect import box_iou

    coco = json.loads((dataset / "annotations.json").read_text())
    cam = json.loads((dataset / "camera.json").read_text())
    camera = CameraIntrinsics(**{k: cam[k] for k in ("width", "height", "fx", "fy", "cx", "cy")})
    by_image: dict[int, list[dict[str, Any]]] = {}
    for a in coco["annotations"]:
        by_image.setdefault(a["image_id"], []).append(a)
    out: dict[str, list[float]] = {"true": [], "false": [], "crowd": []}
    for img in coco["images"]:
        rgb = cv2.cvtColor(cv2.imread(str(dataset / img["file_name"])), cv2.COLOR_BGR2RGB)
        depth = cv2.imread(str(dataset / img["depth_file_name"]), cv2.IMREAD_UNCHANGED)
        anns = by_image.get(img["id"], [])
        for d in detect_holes(rgb, depth, camera):
            best, crowd = 0.0, False
            for a in anns:
                iou = box_iou(d.box, tuple(round(v) for v in a["bbox"]))
                if iou > best:
                    best, crowd = iou, bool(a.get("iscrowd", 0))
            kind = "crowd" if best > 0.5 and crowd else "true" if best > 0.5 else "false"
            out[kind].append(d.score)
    return out


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(v) for v in text.split(",")]


def _pct(v: list[float]) -> str:
    if not v:
        return "-"
    q = np.percentile(v, [0, 10, 50, 90, 100])
    return " / ".join(f"{x:.2f}" for x in q)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--seeds", default="1-10", help="world seeds, e.g. 1-10 or 3,5,8")
    ap.add_argument("--fps", type=float, default=15.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", type=Path, help="write the histories here")
    ap.add_argument("--load", type=Path, help="replay histories from an earlier --json")
    ap.add_argument("--alien", type=Path, help="alien_scenes.py dataset for per-detection scores")
    ap.add_argument("--review-min-p-hole", type=float, default=AnnounceGate.review_min_p_hole)
    args = ap.parse_args(argv)
    if args.load:
        worlds = json.loads(args.load.read_text())["worlds"]
    else:
        seeds = _seeds(args.seeds)
        with concurrent.futures.ProcessPoolExecutor(max_workers=args.jobs) as pool:
            worlds = list(pool.map(fly_world, seeds, [args.fps] * len(seeds)))
        if args.json:
            args.json.write_text(json.dumps({"fps": args.fps, "worlds": worlds}))
    tru = [h for w in worlds for h in w["holes"] if h["true"]]
    fal = [h for w in worlds for h in w["holes"] if not h["true"]]
    print(f"{len(worlds)} worlds, {sum(w['frames'] for w in worlds)} frames")
    if any(len(e) < 5 for w in worlds for h in w["holes"] for e in h["history"]):
        print("  histories from before hole-level p_hole: the best frame's p_hole stands in")

    def dist(name: str, hs: list[dict[str, Any]]) -> None:
        best = [h["history"][-1][1] for h in hs]
        print(
            f"  {name:22} n={len(hs):3}  score {_pct(best)}  p_hole "
            f"{_pct([p_hole_of(h['history'][-1]) for h in hs])}"
            f"  sightings {_pct([h['history'][-1][2] for h in hs])}"
            f"  span s {_pct([h['history'][-1][3] for h in hs])}"
        )

    def twice(hs: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [h for h in hs if h["history"][-1][2] >= 2 and h["history"][-1][3] >= 0.3]

    print("final holes (percentiles 0/10/50/90/100):")
    dist("true", tru)
    dist("false", fal)
    dist("true, 2 over 0.3 s", twice(tru))
    dist("false, 2 over 0.3 s", twice(fal))
    dist("false, >= 3 sightings", [h for h in fal if h["history"][-1][2] >= 3])
    kinds: dict[str, int] = {}
    for h in fal:
        kinds[h["nearest"]] = kinds.get(h["nearest"], 0) + 1
    print("  false holes by nearest feature:", kinds)
    for name, hs in (("true", twice(tru)), ("false", twice(fal))):
        ps = sorted(round(p_hole_of(h["history"][-1]), 3) for h in hs)
        print(f"  p_hole of every {name} hole seen twice over 0.3 s: {ps}")
    rp = args.review_min_p_hole
    print(
        f"gate (review p_hole >= {rp:g})     delivered precision recall  latency median/max s"
        "  review (true)  recall announced+review"
    )
    for p in (0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99):
        for n in (2, 3, 5):
            for span in (0.0, 0.3, 0.6):
                r = replay(worlds, p, n, span, min(rp, p))
                print(
                    f"  p_hole>={p:.2f} n>={n} span>={span:.1f}  {r['delivered']:4d}  "
                    f"{r['precision']:.3f}  {r['recall']:.3f} ({r['in_view']})  "
                    f"{r['latency_median_s']:.2f} / {r['latency_max_s']:.2f}  "
                    f"{r['review']:4d} ({r['review_true']})  {r['recall_with_review']:.3f}"
                )
    if args.alien:
        a = alien_scores(args.alien)
        print(f"alien scenes {args.alien}: per-detection (percentiles 0/10/50/90/100)")
        for k, v in a.items():
            print(
                f"  {k:5} n={len(v):4}  score {_pct(v)}  p_hole "
                f"{_pct([p_hole_of_score(s) for s in v])}"
            )
        for p in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.9, 0.95):
            tp = sum(p_hole_of_score(v) >= p for v in a["true"])
            fp = sum(p_hole_of_score(v) >= p for v in a["false"])
            print(
                f"  p_hole>={p:.2f}: true kept {tp}/{len(a['true'])}, "
                f"false kept {fp}/{len(a['false'])}, precision {tp / max(tp + fp, 1):.3f}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
