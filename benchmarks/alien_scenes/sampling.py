"""Alien scenes: camera placement, opening outlines and rubble pieces (random draws)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from alien_scenes.common import (
    F64,
    CameraModel,
    perp_basis,
    pick,
    powerlaw,
    resting_rotation,
    rot,
    rz,
)

# --------------------------------------------------------------------------- scene sampling

LIB_BOX, _LIB_PRISM, _LIB_CUT0, LIB_HULL0 = 0, 1, 2, 34


def camera_rotation(up: F64, tilt: float, yaw: float, roll: float) -> F64:
    """World-from-camera rotation: tilt from nadir, yaw about gravity, roll about the axis."""
    x, _ = perp_basis(up)
    x = rot(up, yaw) @ x
    z = -up
    y = np.cross(z, x)
    rt = rot(x, tilt)
    z2, y2 = rt @ z, rt @ y
    rr = rot(z2, roll)
    return np.column_stack([rr @ x, rr @ y2, z2])


def ground_point(cam: CameraModel, C: F64, R: F64, u: float, v: float) -> F64 | None:
    d = R @ np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
    if d[2] > -0.05:
        return None
    p: F64 = C + (-C[2] / d[2]) * d
    return p


def footprint(cam: CameraModel, C: F64, R: F64) -> F64:
    """Ground-plane polygon (M, 2) seen through the image border."""
    w, h = cam.width - 1, cam.height - 1
    border = (
        [(u, 0) for u in range(0, w, 16)]
        + [(w, v) for v in range(0, h, 16)]
        + [(u, h) for u in range(w, 0, -16)]
        + [(0, v) for v in range(h, 0, -16)]
    )
    pts = []
    for u, v in border:
        p = ground_point(cam, C, R, u, v)
        if p is None:  # ray towards the horizon: stop it 12 m away
            d = R @ np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
            d[2] = 0
            p = C + 12 * d / np.linalg.norm(d)
        pts.append(p[:2])
    return np.array(pts)


def poly_dims(poly: F64, axis: F64) -> tuple[float, float, float]:
    """Long and short side of the min-area rectangle and inscribed-circle diameter (m) of
    an opening ``poly`` in z = 0, measured across the shaft ``axis``."""
    u, v = perp_basis(axis)
    p3 = np.column_stack([poly, np.zeros(len(poly))])
    q = np.column_stack([p3 @ u, p3 @ v])
    (_, _), (w, h), _ = cv2.minAreaRect(q.astype(np.float32))
    res = 0.01
    q0 = q.min(0) - 0.05
    size = np.ceil((q.max(0) - q0 + 0.05) / res).astype(int) + 1
    m = np.zeros((size[1], size[0]), np.uint8)
    cv2.fillPoly(m, [np.round((q - q0) / res * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    dist = cv2.distanceTransform(m, cv2.DIST_L2, 5)
    return float(max(w, h)), float(min(w, h)), float(2 * dist.max() * res)


def polygon_area(p: F64) -> float:
    x, y = p[:, 0], p[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


# --------------------------------------------------------------------------- openings, rubble


def opening_polygon(r: np.random.Generator, kind: str) -> F64:
    """An opening outline centred at the origin (K, 2), counter-clockwise."""
    if kind in ("irregular", "small"):
        n = int(r.integers(7, 15))
        ang = (np.arange(n) + r.uniform(-0.35, 0.35, n)) * 2 * math.pi / n
        rad = (
            1
            + 0.18 * np.sin(2 * ang + r.uniform(0, 6.3))
            + 0.12 * np.sin(3 * ang + r.uniform(0, 6.3))
            + r.normal(0, 0.07, n)
        )
        p = np.column_stack([rad * np.cos(ang) * r.uniform(1.0, 1.9), rad * np.sin(ang)])
        lo, hi = (0.75, 1.55) if kind == "irregular" else (0.08, 0.28)
    elif kind == "rect":
        L, w = r.uniform(0.8, 1.5), r.uniform(0.5, 1.1)
        p = np.array([[-L, -w], [L, -w], [L, w], [-L, w]]) / 2
        p = p + r.normal(0, 0.025 * L, p.shape)
        mids = (p + np.roll(p, -1, 0)) / 2
        out = []
        for i in range(4):
            out.append(p[i])
            if r.uniform() < 0.5:
                out.append(mids[i] * r.uniform(1.0, 1.12))
        p = np.array(out)
        lo = hi = 0.0
    elif kind == "gap":
        L, w = r.uniform(0.85, 1.55), r.uniform(0.48, 0.8)
        w0, w1 = w * r.uniform(0.85, 1.15), w * r.uniform(0.85, 1.15)
        p = np.array([[-L / 2, -w0 / 2], [L / 2, -w1 / 2], [L / 2, w1 / 2], [-L / 2, w0 / 2]])
        p[:, 0] += r.normal(0, 0.04, 4)
        lo = hi = 0.0
    else:  # crack: a jagged thin band
        L = r.uniform(0.6, 2.5)
        n = int(L / 0.2) + 2
        head = r.uniform(0, 2 * math.pi) + np.cumsum(r.normal(0, 0.3, n - 1))
        step = L / (n - 1)
        c = np.vstack([[0, 0], np.cumsum(step * np.column_stack([np.cos(head), np.sin(head)]), 0)])
        c -= c.mean(0)
        tang = np.gradient(c, axis=0)
        nrm = np.column_stack([-tang[:, 1], tang[:, 0]])
        nrm /= np.linalg.norm(nrm, axis=1)[:, None]
        s = np.linspace(0, 1, n)
        wid = r.uniform(0.03, 0.11) * (np.sin(math.pi * (0.05 + 0.9 * s)) ** 0.6)
        wid *= r.uniform(0.7, 1.3, n)
        p = np.vstack([c + nrm * wid[:, None] / 2, (c - nrm * wid[:, None] / 2)[::-1]])
        lo = hi = 0.0
    p = p @ rz(r.uniform(0, 2 * math.pi))[:2, :2].T
    if hi > 0:
        (_, _), (a, b), _ = cv2.minAreaRect(p.astype(np.float32))
        p *= r.uniform(lo, hi) / max(a, b)
    signed = np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1))
    if signed < 0:
        p = p[::-1]
    return np.asarray(p, float)


def rubble_piece(r: np.random.Generator, n_shapes: int) -> tuple[int, F64, F64, str, float]:
    """A random piece of rubble: (library shape, dims, rotation, material, embedding)."""
    k = pick(
        r,
        ["chunk", "cut", "brick", "block", "plank", "beam", "rebar", "sheet", "pole"],
        [0.52, 0.2, 0.12, 0.04, 0.04, 0.015, 0.03, 0.02, 0.015],
    )
    if k == "chunk":
        s = powerlaw(r, 0.08, 0.9, 1.9)
        dims = s * np.array([1, r.uniform(0.55, 1), r.uniform(0.4, 0.85)])
        mat = pick(r, ["concrete", "brick", "stone", "dark"], [0.68, 0.12, 0.15, 0.05])
        return (
            int(r.integers(LIB_HULL0, n_shapes)),
            dims,
            resting_rotation(r, 35),
            mat,
            r.uniform(0, 0.4),
        )
    if k == "cut":
        s = powerlaw(r, 0.1, 0.9, 2.0)
        dims = s * np.array([1, r.uniform(0.5, 0.95), r.uniform(0.3, 0.7)])
        return (
            int(r.integers(_LIB_CUT0, LIB_HULL0)),
            dims,
            resting_rotation(r, 20),
            "concrete",
            r.uniform(0, 0.3),
        )
    if k == "brick":
        dims = np.array([0.215, 0.1025, 0.065]) * r.uniform(0.95, 1.05)
        if r.uniform() < 0.3:
            dims[0] *= r.uniform(0.4, 0.8)
        return LIB_BOX, dims, resting_rotation(r, 40), "brick", r.uniform(0, 0.3)
    if k == "block":
        dims = np.array([0.39, 0.19, 0.19]) * r.uniform(0.9, 1.1)
        return LIB_BOX, dims, resting_rotation(r, 25), "concrete", r.uniform(0, 0.3)
    if k == "plank":
        dims = np.array([r.uniform(0.4, 2.5), r.uniform(0.06, 0.25), r.uniform(0.02, 0.06)])
        return LIB_BOX, dims, resting_rotation(r, 20), "wood", r.uniform(0, 0.2)
    if k == "beam":
        dims = np.array([r.uniform(1, 3), r.uniform(0.1, 0.25), r.uniform(0.1, 0.25)])
        return (
            LIB_BOX,
            dims,
            resting_rotation(r, 12),
            pick(r, ["wood", "concrete"]),
            r.uniform(0, 0.3),
        )
    if k == "rebar":
        d = r.uniform(0.01, 0.03)
        dims = np.array([r.uniform(0.4, 2.0), d, d])
        return _LIB_PRISM, dims, resting_rotation(r, 25), "rust", 0.0
    if k == "sheet":
        dims = np.array([r.uniform(0.3, 1.2), r.uniform(0.3, 1.0), r.uniform(0.005, 0.02)])
        return (
            LIB_BOX,
            dims,
            resting_rotation(r, 25),
            pick(r, ["metal", "drywall", "tarp"]),
            0.0,
        )
    d = r.uniform(0.06, 0.2)
    dims = np.array([r.uniform(0.5, 2.5), d, d])
    return (
        _LIB_PRISM,
        dims,
        resting_rotation(r, 12),
        pick(r, ["wood", "concrete"]),
        r.uniform(0, 0.3),
    )
