"""AP computation: hand-checked cases and a cross-check against pycocotools' AP50."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from holescan.detect._evaluate import GroundTruthBox, ScoredBox, evaluate_detections, overlap


def test_overlap_rules_differ_as_documented() -> None:
    gt = (0.0, 0.0, 10.0, 10.0)
    det = (0.0, 0.0, 10.0, 6.0)  # inside the gt box, 60 % of it
    assert overlap(det, gt, "iou") == pytest.approx(0.6)
    assert overlap(det, gt, "authors") == pytest.approx(0.6)
    det2 = (5.0, 0.0, 10.0, 10.0)  # half shifted
    assert overlap(det2, gt, "iou") == pytest.approx(50 / 150)
    assert overlap(det2, gt, "authors") == pytest.approx(0.5)
    assert overlap(det2, gt, "iou", crowd=True) == pytest.approx(0.5)  # inter / det area


def test_perfect_and_empty() -> None:
    gts = [GroundTruthBox(1, (0, 0, 10, 10)), GroundTruthBox(2, (5, 5, 10, 10))]
    dets = [ScoredBox(1, (0, 0, 10, 10), 0.9), ScoredBox(2, (5, 5, 10, 10), 0.8)]
    r = evaluate_detections(dets, gts)
    assert (r.ap, r.recall, r.precision_at_full_recall, r.n_tp, r.n_fp) == (1.0, 1.0, 1.0, 2, 0)
    empty = evaluate_detections([], gts)
    assert empty.ap == 0.0 and empty.recall == 0.0 and np.isnan(empty.precision_at_full_recall)


def test_all_point_ap_by_hand() -> None:
    # Ranked outcomes: TP, FP, TP, FP; 3 gt -> precision 1, .5, .667, .5 at recall 1/3,1/3,2/3,2/3
    gts = [
        GroundTruthBox(1, (0, 0, 10, 10)),
        GroundTruthBox(1, (50, 50, 10, 10)),
        GroundTruthBox(1, (100, 100, 10, 10)),
    ]
    dets = [
        ScoredBox(1, (0, 0, 10, 10), 0.9),
        ScoredBox(1, (200, 0, 10, 10), 0.8),
        ScoredBox(1, (50, 50, 10, 10), 0.7),
        ScoredBox(1, (300, 0, 10, 10), 0.6),
    ]
    r = evaluate_detections(dets, gts)
    assert r.ap == pytest.approx(1 / 3 * 1.0 + 1 / 3 * (2 / 3))
    assert r.recall == pytest.approx(2 / 3)
    assert (r.n_tp, r.n_fp) == (2, 2)


def test_crowd_detections_are_ignored_and_duplicates_are_false() -> None:
    gts = [GroundTruthBox(1, (0, 0, 10, 10)), GroundTruthBox(1, (100, 0, 20, 20), crowd=True)]
    dets = [
        ScoredBox(1, (0, 0, 10, 10), 0.9),
        ScoredBox(1, (1, 0, 10, 10), 0.85),
        ScoredBox(1, (100, 0, 15, 15), 0.95),
    ]
    r = evaluate_detections(dets, gts)
    assert r.n_gt == 1 and r.n_tp == 1 and r.n_fp == 1  # crowd hit ignored, duplicate false
    assert r.ap == pytest.approx(1.0)


def _random_case(seed: int) -> tuple[list[GroundTruthBox], list[ScoredBox]]:
    rng = np.random.default_rng(seed)
    gts: list[GroundTruthBox] = []
    dets: list[ScoredBox] = []
    for img in range(1, 31):
        for _ in range(rng.integers(0, 4)):
            x, y = rng.uniform(0, 500), rng.uniform(0, 380)
            w, h = rng.uniform(40, 160), rng.uniform(30, 120)
            crowd = bool(rng.random() < 0.15)
            gts.append(GroundTruthBox(img, (x, y, w, h), crowd))
            if rng.random() < 0.8:  # a jittered detection of it
                j = rng.normal(0, 0.25, 4) * np.array([w, h, w, h])
                dets.append(
                    ScoredBox(
                        img,
                        (x + j[0], y + j[1], abs(w + j[2]) + 1, abs(h + j[3]) + 1),
                        float(rng.random()),
                    )
                )
        for _ in range(rng.integers(0, 3)):  # clutter
            dets.append(
                ScoredBox(
                    img,
                    (
                        rng.uniform(0, 500),
                        rng.uniform(0, 380),
                        rng.uniform(20, 150),
                        rng.uniform(20, 150),
                    ),
                    float(rng.random()),
                )
            )
    return gts, dets


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_pycocotools_ap50(seed: int, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    gts, dets = _random_case(seed)
    coco_gt = {
        "images": [{"id": i, "width": 640, "height": 480} for i in range(1, 31)],
        "categories": [{"id": 1, "name": "access_hole"}],
        "annotations": [
            {
                "id": k + 1,
                "image_id": g.image_id,
                "category_id": 1,
                "bbox": list(g.box),
                "area": g.box[2] * g.box[3],
                "iscrowd": int(g.crowd),
            }
            for k, g in enumerate(gts)
        ],
    }
    (tmp_path / "gt.json").write_text(json.dumps(coco_gt))
    with contextlib.redirect_stdout(io.StringIO()):
        cg = COCO(str(tmp_path / "gt.json"))
        cd = cg.loadRes(
            [
                {"image_id": d.image_id, "category_id": 1, "bbox": list(d.box), "score": d.score}
                for d in dets
            ]
        )
        ev = COCOeval(cg, cd, "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    ap50 = float(ev.stats[1])
    ours = evaluate_detections(dets, gts, "iou", interpolation="coco101")
    assert ours.ap == pytest.approx(ap50, abs=1e-9)
    # The all-point AP we report differs from the 101-point sampling only slightly.
    assert evaluate_detections(dets, gts, "iou").ap == pytest.approx(ap50, abs=0.02)
