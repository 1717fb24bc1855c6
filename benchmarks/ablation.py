"""Measure each choice of the default detector: AP with one choice undone at a time.

    python benchmarks/ablation.py DATASET [DATASET ...] [--workers N]

Each row switches one design choice of the default detector back to the simpler option (a
field of ``DetectParams.options``, :class:`holescan.detect.DefaultOptions`, passed with the
call) and evaluates every dataset.
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

VARIANTS: dict[str, dict[str, Any]] = {
    "holescan default": {},
    "no wall growing (box = deep region only)": {"grow_px": 0},
    "no no-reading blobs (basins only)": {"neck_radii_px": ()},
    "no neck cutting (blobs as they are)": {"neck_radii_px": (0,)},
    "block valid at >= 25 % readings (not 5 %)": {"min_valid_fraction": 0.25},
    "minor axis = ellipse axis (no passable width)": {"passable_width": False},
    "no light evidence at the range limit": {"range_limit_light": False},
    "linear depth score (not sqrt)": {"depth_exponent": 1.0},
    "no photometric evidence for no-reading regions": {"photometric_evidence": False},
    "no dark cut of spilled no-reading blobs": {"dark_split": False},
    "no hole-in-depression candidates": {"depression_ratio": 1e9},
    "NMS without containment": {"contained": 9.0},
    "occluding edges kept as rim": {"occluder_step_m": 1e9},
    "unread border bands not cut off (frame = read area)": {"bands": False},
    "basins cut by the border spill (not closed)": {"closed_border": False},
    "no rim-plane test of unread regions (absorbing surfaces)": {"surface_plane": False},
    "thin spurs kept on candidate regions": {"trim_spurs": False},
    "NMS by score alone between bridged and seen-rim basins": {"seen_rim_first": False},
    "boxes of the work grid (not refined at the frame's resolution)": {"pixel_boxes": False},
    "an unread region's box takes in its lit unread part": {"dark_box": False},
}

_DATASETS: dict[Path, Any] = {}


def _one(
    job: tuple[Path, int, dict[str, Any]],
) -> tuple[int, list[tuple[int, tuple[float, ...], float]]]:
    from holescan.detect import DEFAULT, detect_holes
    from holescan.ground import load_dataset, load_image_pair

    root, i, overrides = job
    if root not in _DATASETS:
        _DATASETS[root] = load_dataset(root)
    ds = _DATASETS[root]
    img = ds.images[i]
    rgb, depth = load_image_pair(ds, img)
    params = replace(DEFAULT, options=replace(DEFAULT.options, **overrides))
    dets = detect_holes(rgb, depth, ds.camera, params)
    return img.id, [(img.id, tuple(float(v) for v in d.box), d.score) for d in dets]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from holescan.detect import ScoredBox, evaluate_detections
    from holescan.ground import ground_truth, load_dataset

    sets = [(p, load_dataset(p)) for p in args.datasets]
    head = " | ".join(f"{p.name} AP IoU / authors / recall" for p, _ in sets)
    print(f"| variant | {head} |")
    print("|---|" + "---|" * len(sets))
    ctx = multiprocessing.get_context("spawn")
    for name, overrides in VARIANTS.items():
        cells = []
        with ctx.Pool(args.workers) as pool:
            for root, ds in sets:
                jobs = [(root, i, overrides) for i in range(len(ds.images))]
                rows_all = pool.map(_one, jobs, chunksize=4)
                dets = [ScoredBox(i, b, s) for _, rows in rows_all for i, b, s in rows]
                gt = ground_truth(ds)
                iou = evaluate_detections(dets, gt, "iou")
                auth = evaluate_detections(dets, gt, "authors")
                cells.append(f"{iou.ap:.3f} / {auth.ap:.3f} / {iou.recall:.3f}")
        print(f"| {name} | {' | '.join(cells)} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
