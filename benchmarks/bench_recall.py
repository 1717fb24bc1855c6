"""Measure the detector's recall by range and view angle: the search map's coverage model.

    python benchmarks/bench_recall.py DATASET [DATASET ...] [--workers N] [--min-p-hole P]
        [--write] [--min-holes N]

For every access hole labelled in every frame of the datasets (our simulator's
``holescan dataset synth``, the independent generators ``benchmarks/alien_scenes`` and
``benchmarks/hard_scenes``), measured from the frame's own depth, the same way for all:

* the terrain around the hole: the read pixels of a ring around its box (the box grown by
  30 % a side, the box itself left out), back-projected, a plane fitted (SVD);
* **range**: distance from the camera to where the box centre's ray meets that plane;
* **view angle**: between that ray and the plane's normal (0 = looking straight at it);
* **image position**: the box centre's distance from the edge of the frame's read area
  (the frame without its unread border bands, found as the detector finds them), pixels at
  640 px wide (negative inside a band).

A hole is **detected** when a default-mode detection with ``p_hole >= --min-p-hole``
(default 0.5) matches it: IoU > 0.5 or, for a hole cut by the image border (a crowd box),
covering at least half of its visible part. Holes whose ring has under 200 read pixels
cannot be measured (counted and printed). Recall per (range, angle) bin is printed with its
count, per border bin; ``--write`` stores it as ``mapping/recall_table.json`` with its
provenance (the command, datasets, counts and date). A bin measured on fewer than
``--min-holes`` views (default 15) takes the lower of its own recall and that of itself
and its 8 range/angle neighbours at the same image position pooled; a bin with no view the lowest
measured neighbour; both only when the neighbourhood holds ``--min-holes`` views, else 0:
the map claims no coverage it has not measured. ``--rows FILE`` keeps the
per-view measurements (a second run with the same file re-bins without detecting).
"""

from __future__ import annotations

import argparse
import datetime
import json
import multiprocessing
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

RANGE_EDGES = [1.5, 2.5, 3.0, 3.5, 4.0, 4.5]
ANGLE_EDGES = [0.0, 15.0, 30.0, 45.0, 60.0]
BORDER_EDGES = [0.0, 80.0, float("inf")]
RING = 0.3
MIN_RING_PX = 200

_CACHE: dict[str, object] = {}


def _dataset(root: str):  # type: ignore[no-untyped-def]
    from holescan.ground import load_dataset

    if root not in _CACHE:
        _CACHE[root] = load_dataset(root)
    return _CACHE[root]


def _iou(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float]:
    ax0, ay0, aw, ah = a
    bx0, by0, bw, bh = b
    iw = max(0.0, min(ax0 + aw, bx0 + bw) - max(ax0, bx0))
    ih = max(0.0, min(ay0 + ah, by0 + bh) - max(ay0, by0))
    inter = iw * ih
    union = aw * ah + bw * bh - inter
    return (inter / union if union > 0 else 0.0, inter / (bw * bh) if bw * bh > 0 else 0.0)


def _geometry(depth: np.ndarray, cam, box: tuple[float, ...]) -> tuple[float, float] | None:  # type: ignore[no-untyped-def]
    h, w = depth.shape
    x, y, bw, bh = box
    gx, gy = RING * bw, RING * bh
    x0, y0 = max(0, int(x - gx)), max(0, int(y - gy))
    x1, y1 = min(w, int(np.ceil(x + bw + gx))), min(h, int(np.ceil(y + bh + gy)))
    win = depth[y0:y1, x0:x1].astype(np.float64) * cam.depth_unit_m
    vv, uu = np.mgrid[y0:y1, x0:x1]
    inside = (uu >= x) & (uu < x + bw) & (vv >= y) & (vv < y + bh)
    ok = (win > 0) & ~inside
    if ok.sum() < MIN_RING_PX:
        return None
    z = win[ok]
    p = np.column_stack([(uu[ok] - cam.cx) / cam.fx * z, (vv[ok] - cam.cy) / cam.fy * z, z])
    centroid = np.median(p, axis=0)
    _, _, vt = np.linalg.svd(p - p.mean(axis=0), full_matrices=False)
    normal = vt[2]
    u, v = x + bw / 2, y + bh / 2
    ray = np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
    denom = float(normal @ ray)
    if abs(denom) < 1e-6:
        return None
    t = float(normal @ centroid) / denom
    if t <= 0:
        return None
    range_m = t * float(np.linalg.norm(ray))
    cosang = abs(denom) / float(np.linalg.norm(ray))
    return range_m, float(np.degrees(np.arccos(min(1.0, cosang))))


def _border_px(depth: np.ndarray, box: tuple[float, ...]) -> float:
    from holescan.detect import BAND_MAX_PX, unread_bands

    h, w = depth.shape
    k = 640.0 / w
    left, top, right, bottom = unread_bands(depth == 0, max(1, round(BAND_MAX_PX / k)))
    u, v = box[0] + box[2] / 2, box[1] + box[3] / 2
    return k * min(u - left, w - right - u, v - top, h - bottom - v)


def _one(job: tuple[str, int, float]) -> list[tuple[float, float, int, int, float]]:
    from holescan.detect import DEFAULT, detect_holes
    from holescan.ground import load_image_pair

    root, i, min_p = job
    ds = _dataset(root)
    img = ds.images[i]  # type: ignore[attr-defined]
    rgb, depth = load_image_pair(ds, img)  # type: ignore[arg-type]
    dets = [d for d in detect_holes(rgb, depth, ds.camera, DEFAULT) if (d.p_hole or 0) >= min_p]  # type: ignore[attr-defined]
    out = []
    for box, crowd in zip(img.boxes, img.crowd, strict=True):
        geo = _geometry(depth, ds.camera, tuple(float(v) for v in box))  # type: ignore[attr-defined]
        hit = 0
        for d in dets:
            iou, covered = _iou(tuple(float(v) for v in d.box), tuple(float(v) for v in box))
            if iou > 0.5 or (crowd and covered >= 0.5):
                hit = 1
                break
        border = _border_px(depth, tuple(float(v) for v in box))
        if geo is None:
            out.append((float("nan"), float("nan"), hit, int(crowd), border))
        else:
            out.append((geo[0], geo[1], hit, int(crowd), border))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--min-p-hole", type=float, default=0.5)
    ap.add_argument("--min-holes", type=int, default=15)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--rows", type=Path, help="save the per-view rows here (or read them back)")
    a = ap.parse_args()
    from holescan.mapping import RecallTable

    rows: list[tuple[str, float, float, int, int, float]] = []
    if a.rows is not None and a.rows.exists():
        rows = [tuple(r) for r in json.loads(a.rows.read_text())]  # type: ignore[misc]
    for root in a.datasets if not rows else []:
        ds = _dataset(str(root))
        jobs = [(str(root), i, a.min_p_hole) for i in range(len(ds.images))]  # type: ignore[attr-defined]
        if a.workers > 1:
            with multiprocessing.get_context("spawn").Pool(a.workers) as pool:
                per = pool.map(_one, jobs, chunksize=4)
        else:
            per = [_one(j) for j in jobs]
        got = [(root.name, *r) for p in per for r in p]
        rows += got
        arr = np.array([r[1:] for r in got], dtype=np.float64).reshape(-1, 5)
        meas = np.isfinite(arr[:, 0])
        print(
            f"{root.name}: {len(ds.images)} frames, {len(arr)} hole views "  # type: ignore[attr-defined]
            f"({int(arr[:, 3].sum())} cut by the border), {int((~meas).sum())} unmeasurable, "
            f"recall {arr[:, 2].mean():.3f} (measured {arr[meas, 2].mean():.3f})"
        )
    if a.rows is not None and not a.rows.exists():
        a.rows.write_text(json.dumps(rows))
    arr = np.array([r[1:] for r in rows], dtype=np.float64)
    meas = np.isfinite(arr[:, 0])
    arr = arr[meas]
    re, ae, be = np.array(RANGE_EDGES), np.array(ANGLE_EDGES), np.array(BORDER_EDGES)
    ri = np.searchsorted(re, arr[:, 0], side="right") - 1
    ai = np.searchsorted(ae, arr[:, 1], side="right") - 1
    bi = np.searchsorted(be, arr[:, 4], side="right") - 1
    nr, na, nb = len(re) - 1, len(ae) - 1, len(be) - 1
    ok = (ri >= 0) & (ri < nr) & (ai >= 0) & (ai < na) & (bi >= 0) & (bi < nb)
    n = np.zeros((nr, na, nb), np.int64)
    k = np.zeros((nr, na, nb), np.int64)
    np.add.at(n, (ri[ok], ai[ok], bi[ok]), 1)
    np.add.at(k, (ri[ok], ai[ok], bi[ok]), arr[ok, 2].astype(np.int64))
    print(f"outside the table's bins: {int((~ok).sum())} of {len(arr)}")
    rec = np.where(n > 0, k / np.maximum(n, 1), 0.0)
    for b in range(nb):
        print(f"border {be[b]:.0f}-{be[b + 1]:.0f} px: recall {k[..., b].sum()}/{n[..., b].sum()}")
        print("range \\ angle | " + " | ".join(f"{ae[j]:.0f}-{ae[j + 1]:.0f}" for j in range(na)))
        for i in range(nr):
            cells = " | ".join(
                f"{rec[i, j, b]:.2f} ({n[i, j, b]})" if n[i, j, b] else "-" for j in range(na)
            )
            print(f"{re[i]:.1f}-{re[i + 1]:.1f} m | {cells}")
    # A bin with few views takes the recall of it and its neighbours pooled, when those
    # hold enough; a bin outside everything measured stays 0.
    table = np.zeros((nr, na, nb))
    for idx in np.ndindex(nr, na, nb):
        # Neighbours in range and angle, at the same image position (pooling across it
        # would lend the interior's recall to the border).
        sl = (slice(max(0, idx[0] - 1), idx[0] + 2), slice(max(0, idx[1] - 1), idx[1] + 2), idx[2])
        pn, pk = int(n[sl].sum()), int(k[sl].sum())
        pooled = pk / pn if pn >= a.min_holes else 0.0
        if n[idx] >= a.min_holes:
            table[idx] = rec[idx]
        elif n[idx] > 0:  # few views: never above what they showed
            table[idx] = min(pooled, rec[idx])
        elif pooled > 0:  # none: the worst measured neighbour
            table[idx] = min(pooled, float(rec[sl][n[sl] > 0].min()))
    print("written table (sparse bins: see --help):")
    for b in range(nb):
        print(f"border {be[b]:.0f}-{be[b + 1]:.0f} px")
        for i in range(nr):
            print(
                f"{re[i]:.1f}-{re[i + 1]:.1f} m | "
                + " | ".join(f"{table[i, j, b]:.2f}" for j in range(na))
            )
    if a.write:
        t = RecallTable(
            re,
            ae,
            table,
            n,
            {
                "what": "default-mode detector recall of access holes per frame, by range, "
                "view angle (line of sight vs the terrain plane around the hole) and image "
                "position (the hole centre's distance from the edge of the read area, px at "
                "640 wide), on the structured-light sensor model",
                "command": "python benchmarks/bench_recall.py "
                + " ".join(str(p) for p in a.datasets)
                + f" --min-p-hole {a.min_p_hole} --min-holes {a.min_holes} --write",
                "datasets": sorted({r[0] for r in rows}),
                "hole_views": len(rows),
                "measured": int(meas.sum()),
                "detected_when": f"p_hole >= {a.min_p_hole} and IoU > 0.5 (border-cut: covers "
                "half the visible part)",
                "bins_below_min_holes": f"fewer than {a.min_holes} views: the lower of its own "
                "recall and that of it and its neighbours pooled; no view: the lowest measured "
                "neighbour; 0 when the neighbourhood holds fewer views",
                "date": datetime.date.today().isoformat(),
            },
            be,
        )
        out = Path(__file__).resolve().parent.parent / "mapping" / "recall_table.json"
        out.write_text(json.dumps(t.to_json(), indent=1) + "\n")
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
