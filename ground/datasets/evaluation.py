"""Run a detector over a dataset and score it (the I/O side of :mod:`detect._evaluate`)."""

from __future__ import annotations

import json
import logging
import multiprocessing
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from holescan.detect import (
    CameraIntrinsics,
    Detection,
    DetectParams,
    GroundTruthBox,
    PRResult,
    ScoredBox,
    detect_baseline,
    detect_holes,
    evaluate_detections,
    p_hole_of_score,
)
from holescan.errors import InputError
from holescan.ground.datasets.coco import Dataset, DatasetImage, load_dataset, load_image_pair
from holescan.outputs import atomic_output, output_via_part

__all__ = [
    "JSON_SUFFIXES",
    "PLOT_SUFFIXES",
    "EvalReport",
    "brier_score",
    "calibration_outcomes",
    "detect_image",
    "evaluate_dataset",
    "format_table",
    "ground_truth",
    "plot_pr",
    "plot_reliability",
    "run_detector",
    "write_coco_results",
]

log = logging.getLogger(__name__)


def detect_image(
    params: DetectParams | None,
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
) -> list[Detection]:
    """Run the detector for ``params``; ``None`` means the naive depth-threshold baseline."""
    if params is None:
        return detect_baseline(rgb, depth, camera)
    return detect_holes(rgb, depth, camera, params)


def _detect_file(
    job: tuple[DetectParams | None, Dataset, DatasetImage],
) -> tuple[int, list[ScoredBox], float]:
    params, dataset, img = job
    rgb, depth = load_image_pair(dataset, img)
    t0 = time.perf_counter()
    dets = detect_image(params, rgb, depth, dataset.camera)
    ms = (time.perf_counter() - t0) * 1000.0
    return img.id, [ScoredBox(img.id, _box(d.box), d.score) for d in dets], ms


def _box(b: tuple[int, int, int, int]) -> tuple[float, float, float, float]:
    return (float(b[0]), float(b[1]), float(b[2]), float(b[3]))


@dataclass(frozen=True)
class EvalReport:
    """AP under both overlap rules for one detector on one dataset."""

    name: str
    n_images: int
    iou: PRResult
    authors: PRResult
    ms_per_frame: float  # median
    detections: tuple[ScoredBox, ...]


def ground_truth(dataset: Dataset) -> list[GroundTruthBox]:
    return [
        GroundTruthBox(img.id, tuple(float(v) for v in box), bool(crowd))  # type: ignore[arg-type]
        for img in dataset.images
        for box, crowd in zip(img.boxes, img.crowd, strict=True)
    ]


def run_detector(
    dataset: Dataset,
    params: DetectParams | None,
    name: str,
    progress: Callable[[int, int], None] | None = None,
    workers: int = 1,
) -> EvalReport:
    """Detect on every image of ``dataset`` and evaluate under both overlap rules.

    ``workers > 1`` detects in that many processes; results do not depend on it.
    """
    jobs = [(params, dataset, img) for img in dataset.images]
    results: list[tuple[int, list[ScoredBox], float]] = []
    if workers > 1:
        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(workers) as pool:
            for r in pool.imap(_detect_file, jobs):
                results.append(r)
                if progress:
                    progress(len(results), len(jobs))
    else:
        for job in jobs:
            results.append(_detect_file(job))
            if progress:
                progress(len(results), len(jobs))
    scored = [b for _, boxes, _ in results for b in boxes]
    gt = ground_truth(dataset)
    return EvalReport(
        name=name,
        n_images=len(dataset.images),
        iou=evaluate_detections(scored, gt, "iou"),
        authors=evaluate_detections(scored, gt, "authors"),
        ms_per_frame=float(np.median([ms for _, _, ms in results])) if results else 0.0,
        detections=tuple(scored),
    )


def evaluate_dataset(path: Path, params: DetectParams | None, name: str) -> EvalReport:
    dataset = load_dataset(path)
    if not any(img.boxes for img in dataset.images):
        raise InputError(f"{path}: the dataset has no annotated hole; nothing to evaluate")
    return run_detector(dataset, params, name)


JSON_SUFFIXES = frozenset({".json"})
PLOT_SUFFIXES = frozenset({".png", ".pdf", ".svg"})
"""The extensions of the files :func:`write_coco_results` and the plots write."""


def write_coco_results(path: Path, detections: Sequence[ScoredBox], *, force: bool = False) -> None:
    """COCO results list: ``[{image_id, category_id: 1, bbox: [x, y, w, h], score}]``,
    written through the output-path rule (an existing ``path`` refused unless ``force``)."""
    rows = [
        {
            "image_id": d.image_id,
            "category_id": 1,
            "bbox": [float(v) for v in d.box],
            "score": round(float(d.score), 6),
        }
        for d in detections
    ]
    with atomic_output(path, suffixes=JSON_SUFFIXES, force=force) as f:
        f.write(json.dumps(rows).encode())


def format_table(reports: Sequence[EvalReport]) -> str:
    """A Markdown table: AP under both rules, recall, precision at full recall, speed."""
    lines = [
        "| detector | AP (IoU>0.5) | AP (authors) | recall | precision at full recall | "
        "TP/FP | median ms/frame |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in reports:
        pfr = r.iou.precision_at_full_recall
        lines.append(
            f"| {r.name} | {r.iou.ap:.3f} | {r.authors.ap:.3f} | {r.iou.recall:.3f} | "
            f"{'n/a (never 1.0)' if np.isnan(pfr) else f'{pfr:.3f}'} | "
            f"{r.iou.n_tp}/{r.iou.n_fp} | {r.ms_per_frame:.1f} |"
        )
    return "\n".join(lines)


def plot_pr(path: Path, reports: Sequence[EvalReport], title: str, *, force: bool = False) -> None:
    """Precision-recall curves (both overlap rules) of each report as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), sharey=True)
    for ax, rule in zip(axes, ("iou", "authors"), strict=True):
        for r in reports:
            res: PRResult = getattr(r, rule)
            if res.recall_curve:
                env = np.maximum.accumulate(np.array(res.precision)[::-1])[::-1]
                ax.step(
                    [0.0, *res.recall_curve],
                    [env[0], *env],
                    where="post",
                    label=f"{r.name} (AP {res.ap:.2f})",
                )
        ax.set_title("IoU > 0.5" if rule == "iou" else "authors' rule: overlap / larger box > 0.5")
        ax.set_xlabel("recall")
        ax.set_xlim(0, 1.02)
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower left", fontsize=8)
    axes[0].set_ylabel("precision")
    fig.suptitle(title)
    fig.tight_layout()
    try:
        with output_via_part(path, suffixes=PLOT_SUFFIXES, force=force) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)


def calibration_outcomes(
    result: PRResult,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """``(p_hole, is_true)`` of every scored detection of a default-mode run.

    p_hole comes from the raw score (:func:`detect.p_hole_of_score`); is_true is 1 for a
    detection matched to an access hole, 0 otherwise (crowd matches are already left out).
    """
    tp = np.rint(np.array(result.recall_curve) * result.n_gt)
    is_true = np.diff(np.concatenate([[0.0], tp])).clip(0, 1)
    p = np.array([p_hole_of_score(s) for s in result.scores], dtype=np.float64)
    return p, is_true.astype(np.float64)


def brier_score(p: npt.NDArray[np.float64], is_true: npt.NDArray[np.float64]) -> float:
    """Mean squared difference between predicted probability and outcome (0 = perfect)."""
    return float(np.mean((p - is_true) ** 2)) if len(p) else float("nan")


def plot_reliability(
    path: Path,
    p: npt.NDArray[np.float64],
    label: npt.NDArray[np.float64],
    title: str,
    bins: int = 10,
    *,
    force: bool = False,
) -> None:
    """Reliability diagram: observed frequency of true holes per bin of predicted ``p``.

    Bars show how many detections fall in each bin; bins with >= 20 detections are drawn
    solid, fewer hollow (too few to judge).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    edges = np.linspace(0.0, 1.0, bins + 1)
    idx = np.clip(np.digitize(p, edges[1:-1]), 0, bins - 1)
    fig, (ax, axn) = plt.subplots(
        2, 1, figsize=(5.5, 6.4), sharex=True, gridspec_kw={"height_ratios": [3, 1]}
    )
    ax.plot([0, 1], [0, 1], color="grey", lw=1, label="perfect calibration")
    ax.fill_between([0, 1], [-0.1, 0.9], [0.1, 1.1], color="grey", alpha=0.12, label="+-0.1")
    counts = []
    for b in range(bins):
        m = idx == b
        counts.append(int(m.sum()))
        if not m.any():
            continue
        solid = m.sum() >= 20
        ax.plot(
            p[m].mean(),
            label[m].mean(),
            "o",
            color="C0",
            mfc="C0" if solid else "white",
            ms=7,
        )
    ax.plot([], [], "o", color="C0", label=">= 20 detections (hollow: fewer)")
    ax.set_ylabel("observed fraction of true holes")
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.03, 1.03)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title, fontsize=9)
    axn.bar(edges[:-1] + 0.05, counts, width=0.09, color="C1")
    axn.set_xlabel("p_hole (predicted)")
    axn.set_ylabel("detections")
    fig.tight_layout()
    try:
        with output_via_part(path, suffixes=PLOT_SUFFIXES, force=force) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
