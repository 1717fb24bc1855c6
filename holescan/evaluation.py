"""Run a detector over a dataset and score it (the I/O side of :mod:`detect._evaluate`)."""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from detect import CameraIntrinsics, Detection, DetectParams, detect_baseline, detect_holes
from detect._evaluate import GroundTruthBox, PRResult, ScoredBox, evaluate_detections
from holescan.datasets import Dataset, load_dataset, load_image_pair
from holescan.errors import InputError

log = logging.getLogger(__name__)

Detector = Callable[
    [npt.NDArray[np.uint8], npt.NDArray[np.uint16], CameraIntrinsics], list[Detection]
]


def make_detector(params: DetectParams | None) -> Detector:
    """The detector for ``params``; ``None`` means the naive depth-threshold baseline."""
    if params is None:
        return detect_baseline
    return lambda rgb, depth, camera: detect_holes(rgb, depth, camera, params)


@dataclass(frozen=True)
class EvalReport:
    """AP under both overlap rules for one detector on one dataset."""

    name: str
    n_images: int
    iou: PRResult
    authors: PRResult
    ms_per_frame: float
    detections: tuple[ScoredBox, ...]


def ground_truth(dataset: Dataset) -> list[GroundTruthBox]:
    return [
        GroundTruthBox(img.id, tuple(float(v) for v in box), bool(crowd))  # type: ignore[arg-type]
        for img in dataset.images
        for box, crowd in zip(img.boxes, img.crowd, strict=True)
    ]


def run_detector(
    dataset: Dataset,
    detector: Detector,
    name: str,
    progress: Callable[[int, int], None] | None = None,
) -> EvalReport:
    """Detect on every image of ``dataset`` and evaluate under both overlap rules."""
    scored: list[ScoredBox] = []
    elapsed = 0.0
    for i, img in enumerate(dataset.images):
        rgb, depth = load_image_pair(dataset, img)
        t0 = time.perf_counter()
        dets = detector(rgb, depth, dataset.camera)
        elapsed += time.perf_counter() - t0
        scored += [ScoredBox(img.id, tuple(float(v) for v in d.box), d.score) for d in dets]  # type: ignore[misc]
        if progress:
            progress(i + 1, len(dataset.images))
    gt = ground_truth(dataset)
    n = max(1, len(dataset.images))
    return EvalReport(
        name=name,
        n_images=len(dataset.images),
        iou=evaluate_detections(scored, gt, "iou"),
        authors=evaluate_detections(scored, gt, "authors"),
        ms_per_frame=1000.0 * elapsed / n,
        detections=tuple(scored),
    )


def evaluate_dataset(path: Path, params: DetectParams | None, name: str) -> EvalReport:
    dataset = load_dataset(path)
    if not any(img.boxes for img in dataset.images):
        raise InputError(f"{path}: the dataset has no annotated hole; nothing to evaluate")
    return run_detector(dataset, make_detector(params), name)


def write_coco_results(path: Path, detections: Sequence[ScoredBox]) -> None:
    """COCO results list: ``[{image_id, category_id: 1, bbox: [x, y, w, h], score}]``."""
    rows = [
        {
            "image_id": d.image_id,
            "category_id": 1,
            "bbox": [float(v) for v in d.box],
            "score": round(float(d.score), 6),
        }
        for d in detections
    ]
    path.write_text(json.dumps(rows))


def format_table(reports: Sequence[EvalReport]) -> str:
    """A Markdown table: AP under both rules, recall, precision at full recall, speed."""
    lines = [
        "| detector | AP (IoU>0.5) | AP (authors) | recall | precision at full recall | "
        "TP/FP | ms/frame |",
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


def plot_pr(path: Path, reports: Sequence[EvalReport], title: str) -> None:
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
