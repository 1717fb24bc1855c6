"""Record the default detector's detections on datasets, or compare two such records.

    python benchmarks/same_detections.py record OUT.json DATASET [DATASET ...] [--frames N]
    python benchmarks/same_detections.py compare BEFORE.json AFTER.json [--tol 1e-6]

A speed change to the detector must not change what it finds: record the detections of the
checkout before the change and after it (this script measures the checkout it lives in),
then compare. Every field of every detection is compared, frame by frame and in order:
boxes, flags and counts exactly, numbers within ``--tol`` (absolute; float noise).
``compare`` prints each difference and exits 1 when there is one.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Any

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def record(out: Path, roots: list[Path], frames: int | None) -> int:
    from holescan.detect import DEFAULT, detect_holes
    from holescan.ground import load_dataset, load_image_pair

    if out.exists():
        print(f"error: {out} exists (no overwrite)", file=sys.stderr)
        return 2
    rec: dict[str, list[dict[str, Any]]] = {}
    for root in roots:
        ds = load_dataset(root)
        for img in ds.images[:frames]:
            rgb, depth = load_image_pair(ds, img)
            dets = detect_holes(rgb, depth, ds.camera, DEFAULT)
            rec[f"{root.name}/{img.name}"] = [dataclasses.asdict(d) for d in dets]
    out.write_text(json.dumps(rec))
    n = sum(len(v) for v in rec.values())
    print(f"{len(rec)} frames, {n} detections -> {out}")
    return 0


def _diff(a: Any, b: Any, tol: float, where: str) -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        if a.keys() != b.keys():
            return [f"{where}: fields {sorted(a)} != {sorted(b)}"]
        return [x for k in a for x in _diff(a[k], b[k], tol, f"{where}.{k}")]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{where}: {len(a)} != {len(b)} items"]
        return [
            x
            for i, (u, v) in enumerate(zip(a, b, strict=True))
            for x in _diff(u, v, tol, f"{where}[{i}]")
        ]
    if isinstance(a, float) and isinstance(b, float) and not isinstance(a, bool):
        if math.isclose(a, b, rel_tol=0.0, abs_tol=tol) or (math.isnan(a) and math.isnan(b)):
            return []
        return [f"{where}: {a!r} != {b!r}"]
    return [] if a == b else [f"{where}: {a!r} != {b!r}"]


def compare(before: Path, after: Path, tol: float) -> int:
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    if a.keys() != b.keys():
        print(f"different frames: {sorted(set(a) ^ set(b))[:5]} ...")
        return 1
    diffs = [x for k in a for x in _diff(a[k], b[k], tol, k)]
    for line in diffs[:50]:
        print(line)
    n = sum(len(v) for v in a.values())
    print(f"{len(a)} frames, {n} detections: {len(diffs)} differences (tol {tol:g})")
    return 1 if diffs else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out", type=Path)
    r.add_argument("datasets", nargs="+", type=Path)
    r.add_argument("--frames", type=int, default=None)
    c = sub.add_parser("compare")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    c.add_argument("--tol", type=float, default=1e-6)
    args = ap.parse_args(argv)
    if args.cmd == "record":
        return record(args.out, args.datasets, args.frames)
    return compare(args.before, args.after, args.tol)


if __name__ == "__main__":
    sys.exit(main())
