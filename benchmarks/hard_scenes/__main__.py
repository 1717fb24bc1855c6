"""Hard synthetic RGB-D rubble scenes with access-hole truth, as a COCO-style dataset.

    python benchmarks/hard_scenes OUT --n 100 --seed 101 --jobs 2

See README.md beside this file for the technique, the distributions and labelling rules.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import cv2
from camera import dataset_intrinsics
from frame import render_frame


def _init() -> None:
    cv2.setNumThreads(1)


def _work(task: tuple) -> dict:
    seed, index, intr, scale, out, sensor = task
    fr = render_frame(seed, index, intr, scale, sensor)
    name = f"hs{seed}_{index:04d}"
    cv2.imwrite(str(Path(out) / "rgb" / f"{name}.png"), cv2.cvtColor(fr["rgb"], cv2.COLOR_RGB2BGR))
    cv2.imwrite(str(Path(out) / "depth" / f"{name}.png"), fr["depth"])
    return {
        "name": name,
        "scene": fr["scene"],
        "annotations": fr["annotations"],
        "distractors": fr["distractors"],
    }


def generate(
    out: Path,
    n: int,
    seed: int,
    jobs: int = 1,
    scale: float = 1.0,
    sensor: str = "structured-light",
) -> dict:
    out = Path(out)
    (out / "rgb").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(parents=True, exist_ok=True)
    intr = dataset_intrinsics(seed)
    cam = intr.scaled(scale)
    tasks = [(seed, i, intr, scale, str(out), sensor) for i in range(n)]
    if jobs > 1:
        with multiprocessing.Pool(jobs, initializer=_init) as pool:
            results = list(pool.imap(_work, tasks, chunksize=1))
    else:
        _init()
        results = [_work(t) for t in tasks]
    images, anns = [], []
    for image_id, r in enumerate(results, start=1):
        images.append(
            {
                "id": image_id,
                "file_name": f"rgb/{r['name']}.png",
                "depth_file_name": f"depth/{r['name']}.png",
                "width": cam.width,
                "height": cam.height,
                "scene": r["scene"],
                "distractors": r["distractors"],
            }
        )
        for a in r["annotations"]:
            x, y, w, h = a.pop("bbox")
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": image_id,
                    "category_id": 1,
                    "bbox": [x, y, w, h],
                    "area": w * h,
                    "iscrowd": a.pop("iscrowd"),
                    **a,
                }
            )
    coco = {
        "info": {
            "generator": "benchmarks/hard_scenes",
            "seed": seed,
            "n": n,
            "scale": scale,
            "sensor": sensor,
        },
        "images": images,
        "annotations": anns,
        "categories": [{"id": 1, "name": "access_hole"}],
    }
    (out / "annotations.json").write_text(json.dumps(coco, indent=1))
    (out / "camera.json").write_text(json.dumps(cam.to_dict(), indent=1))
    return coco


def summary(coco: dict) -> str:
    holes = Counter(a["kind"] for a in coco["annotations"] if not a["iscrowd"])
    crowd = Counter("+".join(a["crowd_reason"]) for a in coco["annotations"] if a["iscrowd"])
    dis = Counter(d["kind"] for im in coco["images"] for d in im["distractors"])
    with_d = sum(
        1 for im in coco["images"] if any(d["kind"] != "cast_shadow" for d in im["distractors"])
    )
    lines = [
        f"{len(coco['images'])} frames, {sum(holes.values())} access holes "
        f"({', '.join(f'{k} {v}' for k, v in sorted(holes.items()))}), "
        f"{sum(crowd.values())} crowd ({', '.join(f'{k} {v}' for k, v in sorted(crowd.items()))})",
        f"frames with a placed distractor: {with_d}",
        "distractors: " + ", ".join(f"{k} {v}" for k, v in sorted(dis.items())),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python benchmarks/hard_scenes",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("out", type=Path, help="dataset folder to write")
    ap.add_argument("--n", type=int, default=100, help="number of frames")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="render at this fraction of 640x480 (for quick tests)",
    )
    ap.add_argument(
        "--sensor",
        choices=("structured-light", "basic"),
        default="structured-light",
        help="depth model: the measured structured-light model (default) or this generator's "
        "own earlier one, for comparison",
    )
    args = ap.parse_args(argv)
    if args.n < 1 or args.jobs < 1 or not 0.1 <= args.scale <= 1.0:
        ap.error("--n and --jobs must be >= 1, --scale in [0.1, 1]")
    t0 = time.perf_counter()
    coco = generate(args.out, args.n, args.seed, args.jobs, args.scale, args.sensor)
    print(summary(coco))
    print(f"wrote {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
