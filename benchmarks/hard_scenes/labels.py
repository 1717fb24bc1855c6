"""Truth: the visible part of every opening, crowd rules, and the distractors' boxes.

An opening is its outline on its rim plane (a plane fitted to the rubble within 15 cm of
it). A pixel belongs to the opening when its ray crosses the rim plane inside the outline;
it sees the opening when nothing is hit before that crossing (4 cm of slack): a slab or a
mound nearer to the camera hides the pixels it covers. Boxes are pixel-edge boxes of these
visible pixels.
"""

from __future__ import annotations

import cv2
import numpy as np
from camera import Intrinsics, project
from features import rim_z
from raycast import SURF_BOX, SURF_FLOOR, SURF_TOP, SURF_UNDER, Hits
from shapes import polygon_area
from world import Grid


def _box(rows: np.ndarray, cols: np.ndarray) -> list[float]:
    return [
        float(cols.min()),
        float(rows.min()),
        float(cols.max() - cols.min() + 1),
        float(rows.max() - rows.min() + 1),
    ]


def opening_view(intr: Intrinsics, R, C, D, hits: Hits, grid: Grid, op: dict) -> dict:
    poly = op["poly"]
    pz = rim_z(op, poly[:, 0], poly[:, 1])
    P = np.column_stack([poly, pz])
    u, v, Z = project(intr, R, C, P)
    W, H = intr.width, intr.height
    cut = bool(u.min() < -1.5 or v.min() < -1.5 or u.max() > W + 0.5 or v.max() > H + 0.5)
    area = polygon_area(u, v)
    inside = (u >= -0.5) & (u <= W - 0.5) & (v >= -0.5) & (v <= H - 0.5)
    u0, u1 = max(0, int(np.floor(u.min())) - 2), min(W, int(np.ceil(u.max())) + 3)
    v0, v1 = max(0, int(np.floor(v.min())) - 2), min(H, int(np.ceil(v.max())) + 3)
    res = {"cut": cut, "area_px": area, "rim_Z": Z, "rim_inside": inside}
    res.update(_centre_truth(R, C, op))
    if u0 >= u1 or v0 >= v1:
        res.update(full=np.zeros(0, np.intp), vis=np.zeros(0, np.intp))
        return res
    vv, uu = np.mgrid[v0:v1, u0:u1]
    idx = (vv * W + uu).ravel()
    d = D[idx]
    z0, gx, gy, xc, yc = op["plane"]
    denom = d[:, 2] - gx * d[:, 0] - gy * d[:, 1]
    tpl = (z0 + gx * (C[0] - xc) + gy * (C[1] - yc) - C[2]) / denom
    x, y = C[0] + tpl * d[:, 0], C[1] + tpl * d[:, 1]
    full = (tpl > 0) & (grid.nearest(grid.open_id, x, y) == op["id"])
    vis = full & (hits.t[idx] >= tpl - 0.04 / np.abs(d[:, 2]))
    res.update(full=idx[full], vis=idx[vis])
    return res


def _centre_truth(R, C, op: dict) -> dict:
    """The opening's area centroid on its rim plane, and the plane's normal, in the camera
    frame (x right, y down, z forward; metres), and the view's angle off the vertical."""
    x, y = op["poly"][:, 0], op["poly"][:, 1]
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y
    a2 = float(cross.sum())
    cx = float(((x + np.roll(x, -1)) * cross).sum()) / (3.0 * a2)
    cy = float(((y + np.roll(y, -1)) * cross).sum()) / (3.0 * a2)
    P = np.array([cx, cy, float(rim_z(op, cx, cy))])
    _, gx, gy, _, _ = op["plane"]
    n = np.array([-gx, -gy, 1.0]) / np.sqrt(gx * gx + gy * gy + 1.0)
    los = P - C
    off = np.degrees(np.arccos(-los[2] / np.linalg.norm(los)))
    return {
        "centre_cam": [round(float(c), 4) for c in (P - C) @ R],
        "normal_cam": [round(float(c), 4) for c in n @ R],
        "view_off_vertical_deg": round(float(off), 2),
    }


def hole_annotation(
    f: dict, view: dict, depth: np.ndarray, beyond: np.ndarray, max_range: float, scale: float
) -> dict | None:
    W = depth.shape[1]
    full, vis = view["full"], view["vis"]
    if vis.size < max(30 * scale * scale, 4):
        return None
    rows, cols = vis // W, vis % W
    vis_frac = vis.size / max(full.size, 1)
    Z, inside = view["rim_Z"], view["rim_inside"]
    rim_in = float(np.mean(Z[inside] <= max_range)) if inside.any() else 0.0
    reasons = []
    if view["cut"]:
        reasons.append("border")
    if vis_frac < 0.5:
        reasons.append("occluded")
    if rim_in < 0.5:
        reasons.append("beyond_range")
    m = np.zeros(depth.shape, np.uint8)
    m.flat[vis] = 1
    noread = m.astype(bool) & (depth == 0)
    fm = np.zeros(depth.shape, np.uint8)
    fm.flat[full] = 1
    near_hole = cv2.dilate(fm, np.ones((7, 7), np.uint8)).astype(bool)
    grown = cv2.dilate(noread.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    touches = bool(np.count_nonzero(grown & beyond & ~near_hole) >= 5)
    a, b = f["size_m"]
    return {
        "bbox": _box(rows, cols),
        "iscrowd": int(bool(reasons)),
        "kind": "hole_void" if f["floor"] == "void" else "hole_floor",
        "crowd_reason": reasons,
        "feature_id": f["id"],
        "size_m": [round(float(a), 3), round(float(b), 3)],
        "inscribed_m": round(float(f["inscribed_m"]), 3),
        "depth_m": None if f["depth"] is None else round(float(f["depth"]), 3),
        "cavity_m": round(float(f["cavity"]), 3),
        "placement": f["placement"],
        "occluder": f["occluder"] is not None,
        "visible_frac": round(float(vis_frac), 3),
        "in_image_frac": round(float(min(1.0, full.size / max(view["area_px"], 1))), 3),
        "rim_in_range_frac": round(rim_in, 3),
        "no_reading_frac": round(float(noread.sum() / vis.size), 3),
        "touches_range_limit": touches,
        # The opening's area centroid on its rim plane and the plane's normal (up, out of
        # the ground), camera frame, metres: truth for geotagging, for analysis only.
        "centre_cam_m": view["centre_cam"],
        "rim_normal_cam": view["normal_cam"],
        "view_off_vertical_deg": view["view_off_vertical_deg"],
    }


def pixel_objects(grid: Grid, boxes, hits: Hits) -> tuple[np.ndarray, np.ndarray]:
    """Feature id under each pixel (0: plain rubble), and stain id under each pixel."""
    n = len(hits.t)
    obj = np.zeros(n, np.int32)
    stain = np.zeros(n, np.int32)
    x, y = hits.pos[:, 0], hits.pos[:, 1]
    top = hits.surf == SURF_TOP
    obj[top] = grid.nearest(grid.obj_top, x[top], y[top])
    stain[top] = grid.nearest(grid.stain, x[top], y[top])
    low = (hits.surf == SURF_FLOOR) | (hits.surf == SURF_UNDER)
    obj[low] = grid.nearest(grid.obj_floor, x[low], y[low])
    bx = hits.surf == SURF_BOX
    if bx.any():
        obj[bx] = np.array([b.obj for b in boxes])[hits.box[bx]]
    return obj, stain


def region_entry(kind: str, fid: int, pix: np.ndarray, W: int, depth: np.ndarray, min_px: int):
    if pix.size < min_px:
        return None
    rows, cols = pix // W, pix % W
    return {
        "kind": kind,
        "feature_id": fid,
        "bbox": _box(rows, cols),
        "area_px": int(pix.size),
        "no_reading_frac": round(float(np.mean(depth.flat[pix] == 0)), 3),
    }


def shadow_entries(shadowed: np.ndarray, depth: np.ndarray, min_px: int) -> list[dict]:
    m = cv2.morphologyEx(shadowed.astype(np.uint8), cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
    n, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    out = []
    for k in range(1, n):
        x, y, w, h, a = (int(v) for v in stats[k])
        if min_px <= a <= 0.15 * shadowed.size:  # a dark patch, not a frame-wide shadow
            out.append(
                {
                    "kind": "cast_shadow",
                    "feature_id": None,
                    "bbox": [x, y, w, h],
                    "area_px": a,
                    "no_reading_frac": round(float(np.mean(depth[lab == k] == 0)), 3),
                }
            )
    return out
