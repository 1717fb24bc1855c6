"""The default detector on scene sets, per failure mode of a structured-light sensor.

    python benchmarks/sensor_eval.py DATASET [DATASET ...] [--workers N] [--off CHOICE ...]
                                     [--pooled]

For each dataset (a COCO-style folder from ``benchmarks/hard_scenes``, ``benchmarks/
alien_scenes`` or ``holescan dataset synth``): AP under IoU > 0.5, recall, false positives
at ``p_hole >= 0.3``, and by failure mode:

* **border**: holes within 2 px of the read area's edge (the frame's border or the unread
  band along it, from the scene record's ``bands_ltrb_px``) against the others; and the
  recall of every hole at least half inside the read area (crowd boxes included: a hole the
  frame cuts is still one to find); and of those, the ones the sensor can read: not crowd
  for being mostly hidden by rubble (under half of the opening visible) or for a rim beyond
  the sensor's range (hard_scenes' ``crowd_reason``; alien_scenes' ``visible_fraction``
  and ``rim_depth_m`` against the scene's ``max_range_m``);
* **absorbing**: detections with ``p_hole >= 0.3`` lying on a stain (hard_scenes distractor
  ``stain``; those in ``absorbing_stains`` return no infrared) and those announced
  (``p_hole >= 0.9``, the announce tier);
* **shadow**: detections with ``p_hole >= 0.3`` on a cast shadow (distractor
  ``cast_shadow``).

A detection lies on a distractor when half of its box is inside the distractor's box and it
matches no hole. The false positives at ``p_hole >= 0.3`` (those the AP's matching counts
as such: crowd boxes take theirs) are split by the same labels into **absorbing** (on an
absorbing stain), **shadow** (on a cast shadow), **border** (within 2 px of the read area's
edge) and **other**, in that order.

With ``--pooled`` a last row takes every set's frames as one set: the AP and false
positives of all their detections matched together (a set of 40 frames gives AP to a few
hundredths; the pooled AP is the figure of the sets together), the counts summed.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
from pathlib import Path
from typing import Any

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

P_SHOWN = 0.3
P_ANNOUNCED = 0.9
EDGE_PX = 2.0

Det = tuple[tuple[float, float, float, float], float, float]


def _detect(job: tuple[Path, int, tuple[str, ...]]) -> tuple[int, list[Det]]:
    from dataclasses import replace

    from holescan.detect import DEFAULT, detect_holes
    from holescan.ground import load_dataset, load_image_pair

    root, i, off = job
    ds = _cache.get(root) or _cache.setdefault(root, load_dataset(root))
    img = ds.images[i]
    rgb, depth = load_image_pair(ds, img)
    params = replace(DEFAULT, options=replace(DEFAULT.options, **dict.fromkeys(off, False)))
    dets = detect_holes(rgb, depth, ds.camera, params)
    return img.id, [
        (tuple(float(v) for v in d.box), d.score, float(d.p_hole or 0.0))  # type: ignore[misc]
        for d in dets
    ]


_cache: dict[Path, Any] = {}


def _inside(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    ix = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    return ix * iy / max(a[2] * a[3], 1e-9)


def _iou(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    ix = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    inter = ix * iy
    return inter / max(a[2] * a[3] + b[2] * b[3] - inter, 1e-9)


def _near_edge(box: tuple[float, ...], read: tuple[float, ...]) -> bool:
    """Whether ``box`` comes within ``EDGE_PX`` of the read area's edge (x, y, w, h)."""
    return (
        box[0] <= read[0] + EDGE_PX
        or box[1] <= read[1] + EDGE_PX
        or box[0] + box[2] >= read[0] + read[2] - EDGE_PX
        or box[1] + box[3] >= read[1] + read[3] - EDGE_PX
    )


def _hidden_or_beyond(a: dict[str, Any], im: dict[str, Any]) -> bool:
    """Whether a hole's label says the sensor cannot read it: under half of the opening
    visible (rubble in front) or its rim beyond the sensor's range."""
    reasons = a.get("crowd_reason")
    if reasons is not None:  # hard_scenes
        return bool({"occluded", "beyond_range"} & set(reasons))
    max_range = (im.get("scene") or {}).get("max_range_m")
    far = max_range is not None and float(a.get("rim_depth_m", 0.0)) > float(max_range)
    return bool(a.get("visible_fraction", 1.0) < 0.5 or far)


def evaluate(root: Path, workers: int, off: tuple[str, ...] = ()) -> dict[str, Any]:
    from holescan.detect import GroundTruthBox, ScoredBox, evaluate_detections, match_image
    from holescan.ground import ground_truth, load_dataset

    ds = load_dataset(root)
    raw = json.loads((root / "annotations.json").read_text())
    jobs = [(root, i, off) for i in range(len(ds.images))]
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(workers) as pool:
        found = dict(pool.map(_detect, jobs, chunksize=2))
    gt = ground_truth(ds)
    scored = [ScoredBox(i, b, s) for i, ds_ in found.items() for b, s, _ in ds_]
    iou = evaluate_detections(scored, gt, "iou")
    shown = [ScoredBox(i, b, p) for i, ds_ in found.items() for b, _, p in ds_ if p >= P_SHOWN]
    fp_shown = evaluate_detections(shown, gt, "iou").n_fp if shown else 0

    images = {im["id"]: im for im in raw["images"]}
    anns: dict[int, list[dict[str, Any]]] = {}
    for a in raw["annotations"]:
        anns.setdefault(a["image_id"], []).append(a)
    counts = {
        "border": [0, 0, 0],  # holes, found (any score), found at p >= 0.3
        "interior": [0, 0, 0],
        "half_read": [0, 0, 0],
        "readable": [0, 0, 0],
    }
    on = {"stain": 0, "absorbing": 0, "absorbing_announced": 0, "cast_shadow": 0}
    fp_modes = {"border": 0, "absorbing": 0, "shadow": 0, "other": 0}
    gt_by_image: dict[int, list[GroundTruthBox]] = {}
    for g in gt:
        gt_by_image.setdefault(g.image_id, []).append(g)
    for image_id, im in images.items():
        w, h = float(im["width"]), float(im["height"])
        sensor = (im.get("scene") or {}).get("sensor") or {}
        left, top, right, bottom = sensor.get("bands_ltrb_px") or (0, 0, 0, 0)
        read = (float(left), float(top), w - left - right, h - top - bottom)
        dets = found.get(image_id, [])
        holes = [a for a in anns.get(image_id, []) if a.get("category_id", 1) == 1]
        for a in holes:
            box = tuple(float(v) for v in a["bbox"])
            near_edge = _near_edge(box, read)
            hit_any = any(_iou(d[0], box) > 0.5 for d in dets)
            hit_shown = any(_iou(d[0], box) > 0.5 and d[2] >= P_SHOWN for d in dets)
            rows = []
            if not a.get("iscrowd"):
                rows.append("border" if near_edge else "interior")
            if _inside(box, read) >= 0.5:
                rows.append("half_read")
                if not _hidden_or_beyond(a, im):
                    rows.append("readable")
            for r in rows:
                counts[r][0] += 1
                counts[r][1] += hit_any
                counts[r][2] += hit_shown
        absorbing_ids = set(map(str, (sensor.get("absorbing_stains") or {}).keys()))
        dists = [
            (
                "absorbing"
                if x["kind"] == "stain" and str(x.get("feature_id")) in absorbing_ids
                else "shadow"
                if x["kind"] == "cast_shadow"
                else "",
                tuple(float(v) for v in x["bbox"]),
            )
            for x in im.get("distractors") or []
        ]
        shown_here = sorted((d for d in dets if d[2] >= P_SHOWN), key=lambda d: -d[2])
        outcomes = match_image(
            [ScoredBox(image_id, d[0], d[2]) for d in shown_here],
            gt_by_image.get(image_id, []),
            "iou",
            0.5,
        )
        for d, (_, outcome) in zip(shown_here, outcomes, strict=True):
            if outcome != 0:
                continue
            on_kind = {k for k, b in dists if k and _inside(d[0], b) >= 0.5}
            if "absorbing" in on_kind:
                fp_modes["absorbing"] += 1
            elif "shadow" in on_kind:
                fp_modes["shadow"] += 1
            elif _near_edge(d[0], read):
                fp_modes["border"] += 1
            else:
                fp_modes["other"] += 1
        for d in dets:
            if d[2] < P_SHOWN or any(_iou(d[0], tuple(a["bbox"])) > 0.5 for a in holes):
                continue
            for dist in im.get("distractors") or []:
                if dist["kind"] not in ("stain", "cast_shadow"):
                    continue
                if _inside(d[0], tuple(float(v) for v in dist["bbox"])) < 0.5:
                    continue
                on[dist["kind"]] += 1
                if dist["kind"] == "stain" and str(dist.get("feature_id")) in absorbing_ids:
                    on["absorbing"] += 1
                    on["absorbing_announced"] += d[2] >= P_ANNOUNCED
                break
    return {
        "dataset": root.name,
        "images": len(ds.images),
        "holes": iou.n_gt,
        "ap_iou": round(iou.ap, 3),
        "recall": round(iou.recall, 3),
        "fp_p03": fp_shown,
        "modes": {k: tuple(v) for k, v in counts.items()},
        "on_distractors_p03": on,
        "fp_p03_modes": fp_modes,
        "scored": scored,
        "shown": shown,
        "gt": gt,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--pooled",
        action="store_true",
        help="also a last row over all the sets as one: AP of their frames together, counts summed",
    )
    ap.add_argument(
        "--off",
        nargs="*",
        default=[],
        help="boolean detector choices to switch off (DefaultOptions fields, e.g. bands "
        "closed_border)",
    )
    args = ap.parse_args(argv)
    from holescan.detect import DefaultOptions

    for name in args.off:
        if not isinstance(getattr(DefaultOptions(), name, None), bool):
            print(f"--off {name}: not a boolean option of DefaultOptions", file=sys.stderr)
            return 2
    print(
        "| set | frames | holes | AP IoU | recall | FP p>=0.3 | border recall (p>=0.3) | "
        "interior recall (p>=0.3) | >= half in read area: recall (p>=0.3) | ... of them "
        "readable: recall (p>=0.3) | on stain / "
        "absorbing / announced | on shadow | FP p>=0.3: border / absorbing / shadow / other |"
    )
    print("|---|" + "---|" * 12)
    results: list[dict[str, Any]] = []
    for root in args.datasets:
        if not (root / "annotations.json").is_file():
            print(f"{root}: not a dataset folder (no annotations.json)", file=sys.stderr)
            return 2
        results.append(evaluate(root, args.workers, tuple(args.off)))
        _row(results[-1])
    if args.pooled and len(results) > 1:
        _row(_pooled(results))
    return 0


def _pooled(results: list[dict[str, Any]]) -> dict[str, Any]:
    """One result over every set: each set's frames renumbered apart, the AP and the false
    positives of their detections matched together, every count summed."""
    from dataclasses import replace

    from holescan.detect import GroundTruthBox, ScoredBox, evaluate_detections

    scored: list[ScoredBox] = []
    shown: list[ScoredBox] = []
    gt: list[GroundTruthBox] = []
    for k, r in enumerate(results):
        base = (k + 1) * 1_000_000
        scored += [replace(s, image_id=base + s.image_id) for s in r["scored"]]
        shown += [replace(s, image_id=base + s.image_id) for s in r["shown"]]
        gt += [replace(g, image_id=base + g.image_id) for g in r["gt"]]
    iou = evaluate_detections(scored, gt, "iou")

    def summed(key: str) -> dict[str, Any]:
        first = results[0][key]
        if isinstance(next(iter(first.values())), tuple):
            rows = {k: [r[key][k] for r in results] for k in first}
            return {k: tuple(map(sum, zip(*v, strict=True))) for k, v in rows.items()}
        return {k: sum(r[key][k] for r in results) for k in first}

    return {
        "dataset": f"all {len(results)} sets",
        "images": sum(r["images"] for r in results),
        "holes": iou.n_gt,
        "ap_iou": round(iou.ap, 3),
        "recall": round(iou.recall, 3),
        "fp_p03": evaluate_detections(shown, gt, "iou").n_fp if shown else 0,
        "modes": summed("modes"),
        "on_distractors_p03": summed("on_distractors_p03"),
        "fp_p03_modes": summed("fp_p03_modes"),
    }


def _row(r: dict[str, Any]) -> None:
    m, on, fm = r["modes"], r["on_distractors_p03"], r["fp_p03_modes"]

    def rec(k: str) -> str:
        n, a, s = m[k]
        return f"{a}/{n} ({s}/{n})" if n else "-"

    print(
        f"| {r['dataset']} | {r['images']} | {r['holes']} | {r['ap_iou']:.3f} | "
        f"{r['recall']:.3f} | {r['fp_p03']} | {rec('border')} | {rec('interior')} | "
        f"{rec('half_read')} | {rec('readable')} | {on['stain']} / {on['absorbing']} / "
        f"{on['absorbing_announced']} | {on['cast_shadow']} | "
        f"{fm['border']} / {fm['absorbing']} / {fm['shadow']} / {fm['other']} |",
        flush=True,
    )


if __name__ == "__main__":
    sys.exit(main())
