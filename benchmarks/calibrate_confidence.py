#!/usr/bin/env python3
"""Fit the hole-level confidence (:mod:`geotag._confidence`) and print how well it is calibrated.

    nice -n 10 python benchmarks/calibrate_confidence.py CACHE --fit-seeds 1-16 \
        --test-seeds 17-36 --scenes ALIEN HARD [--write]

Hole-level truth comes from two kinds of source the confidence never saw:

* simulated flights (``benchmarks/tier_flights.py``: surveys, hovers, passes over holes
  of :func:`sim.make_sortie_world` worlds), replayed through :class:`geotag.HoleTracker`.
  Each hole is an example at several points of its life (after 1, 2, 4, 8, ... sightings
  and at the end): the vehicle decides on a hole while it is still being seen. Its label
  is the final hole's truth (within 0.5 m of an access hole's centre, or inside its
  opening);
* the independent generators' frames (``benchmarks/alien_scenes``,
  ``benchmarks/hard_scenes`` datasets): each default-mode detection is a hole of one
  sighting, true when it matches an access hole at IoU > 0.5 (detections that only match a
  crowd box, a hole partly in view, are neither, as ``benchmarks/calibrate.py``).

Worlds and scenes are split by seed: ``--fit-seeds`` flights and the scene images with an
even id fit the model (logistic regression, log loss with a small L2 penalty, scipy);
``--test-seeds`` flights and the odd scene images are held out. Printed on the held-out
part: Brier score and reliability per bin (predicted mean / observed rate / count) of the
model and of the best frame's ``p_hole`` (what the vehicle used before), per source.
``--write`` stores the coefficients in ``geotag/_confidence_table.py`` with their
provenance.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import sys
import textwrap
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import tier_flights

from holescan.geotag import (
    ConfidenceModel,
    HoleEvidence,
    HoleSighting,
    HoleTracker,
    evidence_of,
)

TABLE = Path(__file__).resolve().parent.parent / "geotag" / "_confidence_table.py"


@dataclass(frozen=True)
class Example:
    source: str  # survey / hover / line / alien / hard
    seed: int
    evidence: HoleEvidence
    label: int
    weight: float = 1.0  # a hole's examples (its life's stages) weigh 1 together


def _prefixes(n: int) -> list[int]:
    out, k = [], 1
    while k < n:
        out.append(k)
        k *= 2
    return [*out, n]


def flight_examples(cache: Path, seeds: Sequence[int]) -> Iterator[Example]:
    for kind in tier_flights.KINDS:
        for seed in seeds:
            for fl in tier_flights.cached(cache, kind, seed, tier_flights.FPS[kind]):
                tracker = HoleTracker()
                for fr in tier_flights.sightings_of(fl):
                    if fr:
                        tracker.update(fr)
                for h in tracker.holes():
                    label = int(tier_flights.truth_of(fl, h.lat_deg, h.lon_deg) is not None)
                    seen = tracker.sightings_of(h.id)
                    stages = _prefixes(len(seen))
                    for n in stages:
                        yield Example(kind, seed, evidence_of(seen[:n]), label, 1 / len(stages))


def scene_examples(root: Path, source: str) -> Iterator[Example]:
    """One example per default-mode detection of a generated dataset (image id = seed)."""
    from holescan.detect import DEFAULT, box_iou, detect_holes
    from holescan.geotag import VehiclePose
    from holescan.ground import load_dataset, load_image_pair

    ds = load_dataset(root)
    pose = VehiclePose(0, 0.0, 0.0, 100.0, 3.0, 0.0, 0.0, 0.0, eph_m=1.2)
    for img in ds.images:
        rgb, depth = load_image_pair(ds, img)
        dets = detect_holes(rgb, depth, ds.camera, DEFAULT)
        for d, s in zip(dets, _placed(dets, ds.camera, pose), strict=True):
            if s is None:
                continue
            best, crowd = 0.0, False
            for box, is_crowd in zip(img.boxes, img.crowd, strict=True):
                iou = box_iou(d.box, tuple(round(v) for v in box))
                if iou > best:
                    best, crowd = iou, is_crowd
            if best > 0.5 and crowd:
                continue
            yield Example(source, img.id, evidence_of([s]), int(best > 0.5))


def _placed(dets: Sequence[object], camera: object, pose: object) -> list[HoleSighting | None]:
    from holescan.errors import InputError
    from holescan.geotag import CameraMount, geotag_detection

    out: list[HoleSighting | None] = []
    for d in dets:
        try:
            out.append(geotag_detection(d, camera, CameraMount(), pose))  # type: ignore[arg-type]
        except InputError:  # no rim depth: cannot be placed, as in flight
            out.append(None)
    return out


def fit(
    x: np.ndarray, y: np.ndarray, wt: np.ndarray, offset: np.ndarray, l2: float = 1e-2
) -> np.ndarray:
    """Weighted logistic regression with a fixed ``offset`` and no intercept:
    ``logit p = offset + x @ w`` (log loss + ``l2`` * |w|^2 / 2)."""
    k = x.shape[1]
    wt = wt / wt.mean()

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        w = theta
        z = offset + x @ w
        p = 1.0 / (1.0 + np.exp(-z))
        eps = 1e-12
        ll = -np.mean(wt * (y * np.log(p + eps) + (1 - y) * np.log(1 - p + eps)))
        ll += 0.5 * l2 * float(w @ w)
        g = wt * (p - y)
        grad = x.T @ g / len(y) + l2 * w
        return float(ll), grad

    res = minimize(loss, np.zeros(k), jac=True, method="L-BFGS-B")
    return np.asarray(res.x)


def predict(ev: Sequence[HoleEvidence], model: ConfidenceModel) -> np.ndarray:
    return np.array([model.p_hole(e) for e in ev])


def reliability(p: np.ndarray, y: np.ndarray, bins: int = 10) -> list[tuple[float, float, int]]:
    out = []
    edges = np.linspace(0, 1, bins + 1)
    for lo, hi in itertools.pairwise(edges):
        m = (p >= lo) & ((p < hi) if hi < 1 else (p <= hi))
        if m.any():
            out.append((float(p[m].mean()), float(y[m].mean()), int(m.sum())))
    return out


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


#: The evidence beyond the best frame (all 0 for a hole seen once).
EXTRA = ("median_gap", "log_views", "strong_log_views", "size_spread", "scatter")


def _model(w: np.ndarray) -> ConfidenceModel:
    return ConfidenceModel(("best_logit", *EXTRA), (1.0, *map(float, w)), 0.0)


def _report(name: str, ex: list[Example], model: ConfidenceModel) -> None:
    if not ex:
        return
    y = np.array([e.label for e in ex], float)
    p = predict([e.evidence for e in ex], model)
    best = np.array([min(max(e.evidence.best_p, 0.01), 0.99) for e in ex])
    bm, bb = float(np.mean((p - y) ** 2)), float(np.mean((best - y) ** 2))
    print(f"  {name:7} n={len(ex):5} true={int(y.sum()):5}  Brier {bm:.4f}  best frame {bb:.4f}")
    for label, q in (("model", p), ("best frame", best)):
        cells = " ".join(f"{m:.2f}/{o:.2f}({c})" for m, o, c in reliability(q, y))
        print(f"    {label:10} {cells}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("cache", type=Path, help="tier_flights.py cache folder")
    ap.add_argument("--fit-seeds", default="1-16")
    ap.add_argument("--test-seeds", default="17-36")
    ap.add_argument("--scenes", type=Path, nargs="*", default=[], help="generated datasets")
    ap.add_argument("--l2", type=float, default=1e-2)
    ap.add_argument("--write", action="store_true", help="store the fit in the table")
    args = ap.parse_args(argv)
    fit_ex = list(flight_examples(args.cache, _seeds(args.fit_seeds)))
    test_ex = list(flight_examples(args.cache, _seeds(args.test_seeds)))
    for root in args.scenes:
        source = "hard" if "hard" in root.name else "alien"
        for e in scene_examples(root, source):
            (fit_ex if e.seed % 2 == 0 else test_ex).append(e)
    x = np.array([e.evidence.features(EXTRA) for e in fit_ex])
    y = np.array([e.label for e in fit_ex], float)
    offset = np.array([e.evidence.features(("best_logit",))[0] for e in fit_ex])
    w = fit(x, y, np.array([e.weight for e in fit_ex]), offset, args.l2)
    model = _model(w)
    print(f"fitted on {len(fit_ex)} examples ({int(y.sum())} true); held out {len(test_ex)}")
    print("  logit p_hole = logit(best frame's p_hole)")
    for name, c in zip(EXTRA, w, strict=True):
        print(f"    {c:+.4f} * {name}")
    print("held out (reliability: predicted / observed (count) per 0.1 bin):")
    _report("all", test_ex, model)
    for src in ("survey", "hover", "line", "alien", "hard"):
        _report(src, [e for e in test_ex if e.source == src], model)
    if args.write:
        srcs = sorted({e.source for e in fit_ex})
        prov = (
            f"benchmarks/calibrate_confidence.py, {datetime.date.today().isoformat()}: "
            f"{len(fit_ex)} examples ({int(y.sum())} true) from {', '.join(srcs)}; "
            f"flight seeds {args.fit_seeds} ({tier_flights.SENSOR}), scene images with even ids of "
            f"{', '.join(r.name for r in args.scenes) or 'no scene set'}; l2 {args.l2}"
        )
        words = textwrap.wrap(prov, 80, drop_whitespace=False)
        feats = ", ".join(json.dumps(f) for f in model.features)
        TABLE.write_text(
            '"""Fitted coefficients of the hole-level confidence (:mod:`geotag._confidence`).'
            "\n\nWritten by ``benchmarks/calibrate_confidence.py --write``; do not edit by"
            ' hand.\n"""\n\n'
            f"FEATURES = ({feats})\n"
            f"COEFFICIENTS = ({', '.join(f'{c:.6g}' for c in model.coefficients)})\n"
            f"INTERCEPT = {model.intercept!r}\n"
            "PROVENANCE = (\n" + "".join(f"    {json.dumps(w)}\n" for w in words) + ")\n"
        )
        print(f"wrote {TABLE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
