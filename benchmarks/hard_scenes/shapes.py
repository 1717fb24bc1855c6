"""Random smooth noise and outlines (all randomness from the generator passed in)."""

from __future__ import annotations

import cv2
import numpy as np


def smooth_noise(rng: np.random.Generator, shape: tuple[int, int], scale_cells: float):
    """Zero-mean, unit-std noise with features about ``scale_cells`` cells across."""
    h, w = shape
    s = max(float(scale_cells), 1.0)
    gh, gw = int(np.ceil(h / s)) + 3, int(np.ceil(w / s)) + 3
    coarse = rng.standard_normal((gh, gw)).astype(np.float32)
    if s > 1.0:
        size = (int(np.ceil(gw * s)), int(np.ceil(gh * s)))
        coarse = cv2.resize(coarse, size, interpolation=cv2.INTER_CUBIC)
    oy, ox = int(rng.integers(0, int(s) + 1)), int(rng.integers(0, int(s) + 1))
    out = coarse[oy : oy + h, ox : ox + w]
    sd = float(out.std())
    return (out - float(out.mean())) / (sd if sd > 1e-6 else 1.0)


def fractal(rng, shape, cell: float, octaves) -> np.ndarray:
    """Sum of ``amplitude * smooth_noise`` over (feature size m, amplitude) octaves."""
    out = np.zeros(shape, np.float32)
    for scale_m, amp in octaves:
        out += np.float32(amp) * smooth_noise(rng, shape, scale_m / cell)
    return out


def rotate(pts: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return pts @ np.array([[c, s], [-s, c]])


def blob(rng, centre, a: float, b: float, angle: float, rough: float = 0.1, n: int = 96):
    """Irregular closed outline, roughly an a x b ellipse (full axes, m), as (n, 2) x, y."""
    th = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    r = np.ones(n)
    for k in range(2, 8):
        r += rough / k**0.7 * rng.standard_normal() * np.cos(k * th + rng.uniform(0, 2 * np.pi))
    r = np.clip(r, 0.72, 1.28)
    pts = np.stack([0.5 * a * r * np.cos(th), 0.5 * b * r * np.sin(th)], axis=1)
    return rotate(pts, angle) + np.asarray(centre, float)


def rect(centre, length: float, width: float, angle: float, jitter: float = 0.0, rng=None):
    """Rectangle outline (4 corners, or 4*8 points with ``jitter`` m of edge wobble)."""
    if jitter <= 0 or rng is None:
        pts = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * [length / 2, width / 2]
    else:
        t = np.linspace(-1, 1, 8, endpoint=False)
        sides = [
            np.stack([t, -np.ones(8)], 1),
            np.stack([np.ones(8), t], 1),
            np.stack([-t, np.ones(8)], 1),
            np.stack([-np.ones(8), -t], 1),
        ]
        pts = np.concatenate(sides) * [length / 2, width / 2]
        pts += rng.normal(0.0, jitter, pts.shape)
    return rotate(pts, angle) + np.asarray(centre, float)


def strip(rng, centre, length: float, width: float, angle: float, n: int = 40):
    """A narrow, slightly bent slit outline of the given length and (maximum) width."""
    s = np.linspace(-length / 2, length / 2, n)
    bend = rng.uniform(-0.12, 0.12) * length
    c = np.stack([s, bend * (1 - (2 * s / length) ** 2)], 1)
    tang = np.gradient(c, axis=0)
    nrm = np.stack([-tang[:, 1], tang[:, 0]], 1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    taper = np.sqrt(np.clip(1 - (2 * s / length) ** 6, 0.05, 1))
    w = width * (0.8 + 0.2 * np.cos(s * rng.uniform(3, 9) + rng.uniform(0, 6))) * taper
    pts = np.concatenate([c + nrm * (w / 2)[:, None], (c - nrm * (w / 2)[:, None])[::-1]])
    return rotate(pts, angle) + np.asarray(centre, float)


def inscribed_diameter(poly: np.ndarray, res: float = 0.01) -> float:
    """Diameter (m) of the largest disk inside the outline (raster distance transform)."""
    lo = poly.min(0) - 3 * res
    size = np.ceil((poly.max(0) + 3 * res - lo) / res).astype(int) + 1
    m = np.zeros((size[1], size[0]), np.uint8)
    pts = np.round((poly - lo) / res * 16).astype(np.int32)
    cv2.fillPoly(m, [pts], 1, lineType=cv2.LINE_8, shift=4)
    d = cv2.distanceTransform(m, cv2.DIST_L2, 5)
    return 2.0 * float(d.max()) * res


def polygon_area(x: np.ndarray, y: np.ndarray) -> float:
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
