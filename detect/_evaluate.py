"""Precision-recall and average precision of box detections (pure).

Matching follows COCO (pycocotools ``evaluateImg``): per image, detections in descending
score order each take the unmatched ground-truth box they overlap most, when the overlap
passes the rule; a detection that matches only a crowd box (``iscrowd``: a hole partly in
view) is ignored, neither right nor wrong. Two overlap rules:

- ``"iou"``: intersection / union > 0.5 (PASCAL VOC, COCO AP50);
- ``"authors"``: intersection / area of the larger box > 0.5 (Kong et al.'s ``evaluate.m``).

For a crowd box the overlap is intersection / detection area (COCO).

AP is all-point interpolated (area under the monotone precision envelope, VOC 2010+);
``interpolation="coco101"`` samples that envelope at recall 0, 0.01, ..., 1 as pycocotools
does, which the tests use to check this module against pycocotools' AP50.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

Box = tuple[float, float, float, float]
OverlapRule = Literal["iou", "authors"]


@dataclass(frozen=True)
class GroundTruthBox:
    image_id: int
    box: Box
    crowd: bool = False


@dataclass(frozen=True)
class ScoredBox:
    image_id: int
    box: Box
    score: float


@dataclass(frozen=True)
class PRResult:
    """Evaluation of a detection set against ground truth under one overlap rule.

    ap : average precision; recall : highest recall reached; precision_at_full_recall :
    precision where recall first reaches 1.0 (NaN when it never does);
    precision, recall_curve : the raw curve, one point per scored (non-ignored) detection.
    """

    rule: OverlapRule
    ap: float
    recall: float
    precision_at_full_recall: float
    n_gt: int
    n_tp: int
    n_fp: int
    precision: tuple[float, ...]
    recall_curve: tuple[float, ...]
    scores: tuple[float, ...]


def overlap(det: Box, gt: Box, rule: OverlapRule, crowd: bool = False) -> float:
    """Overlap of two (x, y, w, h) boxes under ``rule`` (crowd: intersection / det area)."""
    ix = max(0.0, min(det[0] + det[2], gt[0] + gt[2]) - max(det[0], gt[0]))
    iy = max(0.0, min(det[1] + det[3], gt[1] + gt[3]) - max(det[1], gt[1]))
    inter = ix * iy
    a_det, a_gt = det[2] * det[3], gt[2] * gt[3]
    if crowd:
        denom = a_det
    elif rule == "iou":
        denom = a_det + a_gt - inter
    elif rule == "authors":
        denom = max(a_det, a_gt)
    else:
        raise ValueError(f"overlap rule must be 'iou' or 'authors', got {rule!r}")
    return inter / denom if denom > 0 else 0.0


def match_image(
    dets: list[ScoredBox], gts: list[GroundTruthBox], rule: OverlapRule, threshold: float
) -> list[tuple[float, int]]:
    """(score, outcome) per detection: 1 true positive, 0 false positive, -1 ignored."""
    order = sorted(gts, key=lambda g: g.crowd)  # real boxes first, as pycocotools
    matched = [False] * len(order)
    out = []
    for d in sorted(dets, key=lambda d: -d.score):
        best, best_ov = -1, threshold
        for gi, g in enumerate(order):
            if matched[gi] and not g.crowd:
                continue
            if best > -1 and not order[best].crowd and g.crowd:
                break
            ov = overlap(d.box, g.box, rule, g.crowd)
            if ov <= best_ov:
                continue
            best, best_ov = gi, ov
        if best == -1:
            out.append((d.score, 0))
        elif order[best].crowd:
            out.append((d.score, -1))
        else:
            matched[best] = True
            out.append((d.score, 1))
    return out


def evaluate_detections(
    detections: Sequence[ScoredBox],
    ground_truth: Sequence[GroundTruthBox],
    rule: OverlapRule = "iou",
    threshold: float = 0.5,
    interpolation: Literal["all-point", "coco101"] = "all-point",
) -> PRResult:
    """Precision-recall curve and AP of ``detections`` (see module docstring)."""
    by_img_d: dict[int, list[ScoredBox]] = {}
    by_img_g: dict[int, list[GroundTruthBox]] = {}
    for d in detections:
        by_img_d.setdefault(d.image_id, []).append(d)
    for g in ground_truth:
        by_img_g.setdefault(g.image_id, []).append(g)
    n_gt = sum(1 for g in ground_truth if not g.crowd)
    outcomes: list[tuple[float, int]] = []
    for img, dets in by_img_d.items():
        outcomes += match_image(dets, by_img_g.get(img, []), rule, threshold)
    kept = [(s, o) for s, o in outcomes if o >= 0]
    kept.sort(key=lambda so: -so[0])  # stable, as pycocotools' mergesort
    scores = np.array([s for s, _ in kept], dtype=np.float64)
    tp = np.cumsum([o == 1 for _, o in kept], dtype=np.float64)
    fp = np.cumsum([o == 0 for _, o in kept], dtype=np.float64)
    recall = tp / n_gt if n_gt else np.zeros_like(tp)
    precision = tp / np.maximum(tp + fp, np.finfo(np.float64).eps)
    envelope = np.maximum.accumulate(precision[::-1])[::-1] if len(precision) else precision
    if interpolation == "coco101":
        thresholds = np.linspace(0.0, 1.0, 101)
        idx = np.searchsorted(recall, thresholds, side="left")
        ap = float(np.mean([envelope[i] if i < len(envelope) else 0.0 for i in idx]))
    else:
        r = np.concatenate([[0.0], recall])
        ap = float(np.sum((r[1:] - r[:-1]) * envelope)) if len(recall) else 0.0
    full = np.nonzero(recall >= 1.0 - 1e-12)[0]
    return PRResult(
        rule=rule,
        ap=ap,
        recall=float(recall[-1]) if len(recall) else 0.0,
        precision_at_full_recall=float(precision[full[0]]) if len(full) else float("nan"),
        n_gt=n_gt,
        n_tp=int(tp[-1]) if len(tp) else 0,
        n_fp=int(fp[-1]) if len(fp) else 0,
        precision=tuple(float(p) for p in precision),
        recall_curve=tuple(float(r) for r in recall),
        scores=tuple(float(s) for s in scores),
    )
