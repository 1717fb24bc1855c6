"""Measure each choice of the default detector: AP with one choice undone at a time.

    python benchmarks/ablation.py DATASET [DATASET ...] [--workers N]

Each row switches one design choice of the default detector (``detect/_default.py``,
``_regions.py``, ``_geometry.py``, ``_photometry.py``) back to the simpler option
(module constants, set in the worker processes) and evaluates every dataset.
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
from pathlib import Path
from typing import Any

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

VARIANTS: dict[str, dict[str, Any]] = {
    "holescan default": {},
    "no wall growing (box = deep region only)": {"GROW_PX": 0},
    "no no-reading blobs (basins only)": {"NECK_RADII_PX": ()},
    "no neck cutting (blobs as they are)": {"NECK_RADII_PX": (0,)},
    "block valid at >= 25 % readings (not 5 %)": {"MIN_VALID_FRACTION": 0.25},
    "minor axis = ellipse axis (no passable width)": {"PASSABLE_WIDTH": False},
    "no light evidence at the range limit": {"RANGE_LIMIT_LIGHT": False},
    "linear depth score (not sqrt)": {"DEPTH_EXPONENT": 1.0},
    "no photometric evidence for no-reading regions": {"PHOTOMETRIC_EVIDENCE": False},
    "no dark cut of spilled no-reading blobs": {"DARK_SPLIT": False},
    "no hole-in-depression candidates": {"DEPRESSION_RATIO": 1e9},
    "NMS without containment": {"CONTAINED": 9.0},
    "occluding edges kept as rim": {"OCCLUDER_STEP_M": 1e9},
}


def _init(overrides: dict[str, Any]) -> None:
    import holescan.detect._default
    import holescan.detect._geometry
    import holescan.detect._photometry
    import holescan.detect._regions

    # The ablation switches are private module constants on purpose; set each where it lives.
    d = holescan.detect
    modules = (d._default, d._geometry, d._photometry, d._regions)
    for k, v in overrides.items():
        homes = [m for m in modules if hasattr(m, k)]
        if not homes:
            raise AttributeError(f"no detector module has the switch {k}")
        for m in homes:
            setattr(m, k, v)


_DATASETS: dict[Path, Any] = {}


def _one(job: tuple[Path, int]) -> tuple[int, list[tuple[int, tuple[float, ...], float]]]:
    from holescan.detect import DEFAULT, detect_holes
    from holescan.ground import load_dataset, load_image_pair

    root, i = job
    if root not in _DATASETS:
        _DATASETS[root] = load_dataset(root)
    ds = _DATASETS[root]
    img = ds.images[i]
    rgb, depth = load_image_pair(ds, img)
    dets = detect_holes(rgb, depth, ds.camera, DEFAULT)
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
        with ctx.Pool(args.workers, initializer=_init, initargs=(overrides,)) as pool:
            for root, ds in sets:
                jobs = [(root, i) for i in range(len(ds.images))]
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
