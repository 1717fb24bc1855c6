"""Shapes of rubble features (opening outlines, slabs) and stamping them into grids.

Polygons are (N, 2) float64 arrays of world x, y metres, counter-clockwise. A grid node
``[j, i]`` sits at ``(x, y) = (i * cell, j * cell)``.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt
import shapely

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]
Mask = npt.NDArray[np.bool_]

_SHIFT = 4  # cv2.fillPoly sub-pixel bits


def irregular_ellipse(
    rng: np.random.Generator, centre: tuple[float, float], a: float, b: float, n: int = 48
) -> F64:
    """An ellipse with semi-axes ``a`` >= ``b`` m, random yaw, and a wobbly outline."""
    theta = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    r = a * b / np.sqrt((b * np.cos(theta)) ** 2 + (a * np.sin(theta)) ** 2)
    wobble = np.zeros(n)
    for k in range(2, 6):
        wobble += rng.uniform(0.0, 0.06 / (k - 1)) * np.cos(k * theta + rng.uniform(0, 2 * math.pi))
    r = r * (1.0 + wobble)
    return _place(np.column_stack([r * np.cos(theta), r * np.sin(theta)]), centre, rng)


def irregular_polygon(
    rng: np.random.Generator, centre: tuple[float, float], a: float, b: float
) -> F64:
    """A 5-9 sided polygon roughly inscribed in an ellipse with semi-axes ``a``, ``b`` m."""
    n = int(rng.integers(5, 10))
    # Vertices spread around the centre, each jittered by up to 0.3 of its share.
    theta = np.sort((np.arange(n) + rng.uniform(-0.3, 0.3, n)) * 2.0 * math.pi / n)
    r = a * b / np.sqrt((b * np.cos(theta)) ** 2 + (a * np.sin(theta)) ** 2)
    r = r * rng.uniform(0.9, 1.12, n)
    return _place(np.column_stack([r * np.cos(theta), r * np.sin(theta)]), centre, rng)


def _place(local: F64, centre: tuple[float, float], rng: np.random.Generator) -> F64:
    yaw = rng.uniform(0.0, math.pi)
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    return np.asarray(local @ rot.T + np.asarray(centre), dtype=np.float64)


def crack_polygon(
    rng: np.random.Generator, start: tuple[float, float], length: float, width: float
) -> F64:
    """A long thin crack: a random-walk polyline ``length`` m long, ``width`` m wide."""
    n_seg = int(rng.integers(4, 9))
    heading = rng.uniform(0.0, 2.0 * math.pi)
    pts = [np.asarray(start, dtype=np.float64)]
    for _ in range(n_seg):
        heading += rng.normal(0.0, 0.35)
        step = length / n_seg
        pts.append(pts[-1] + step * np.array([math.cos(heading), math.sin(heading)]))
    line = shapely.LineString(pts)
    poly = line.buffer(width / 2.0, cap_style="flat", join_style="mitre", mitre_limit=3.0)
    if not isinstance(poly, shapely.Polygon):  # a self-crossing walk: keep its largest part
        poly = max(poly.geoms, key=lambda g: g.area)
    return ccw(np.asarray(poly.exterior.coords, dtype=np.float64)[:-1])


def ccw(poly: F64) -> F64:
    """The polygon with counter-clockwise vertex order."""
    x, y = poly[:, 0], poly[:, 1]
    area2 = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    return poly if area2 >= 0 else poly[::-1].copy()


def axes(poly: F64) -> tuple[float, float]:
    """Major and minor side of the polygon's minimum-area bounding rectangle, metres."""
    (_, _), (w, h), _ = cv2.minAreaRect(poly.astype(np.float32))
    return float(max(w, h)), float(min(w, h))


def rasterise(
    poly: F64, cell_m: float, shape: tuple[int, int], pad: int = 1
) -> tuple[slice, slice, Mask] | None:
    """Grid nodes inside ``poly``: (row slice, col slice, mask of that window) or None."""
    ij = poly / cell_m
    c0 = max(math.floor(ij[:, 0].min()) - pad, 0)
    c1 = min(math.ceil(ij[:, 0].max()) + pad + 1, shape[1])
    r0 = max(math.floor(ij[:, 1].min()) - pad, 0)
    r1 = min(math.ceil(ij[:, 1].max()) + pad + 1, shape[0])
    if c1 <= c0 or r1 <= r0:
        return None
    mask = np.zeros((r1 - r0, c1 - c0), dtype=np.uint8)
    pts = np.round((ij - [c0, r0]) * (1 << _SHIFT)).astype(np.int32)
    cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return slice(r0, r1), slice(c0, c1), mask.astype(bool)


def window_xy(rows: slice, cols: slice, cell_m: float) -> tuple[F64, F64]:
    """World x, y (metres) of the grid nodes of a window, each (rows, cols)."""
    xs = np.arange(cols.start, cols.stop) * cell_m
    ys = np.arange(rows.start, rows.stop) * cell_m
    x, y = np.meshgrid(xs, ys)
    return x, y


def rectangle(centre: tuple[float, float], length: float, width: float, yaw: float) -> F64:
    """An oriented rectangle, (4, 2) float64, counter-clockwise."""
    c, s = math.cos(yaw), math.sin(yaw)
    u = np.array([c, s]) * length / 2.0
    v = np.array([-s, c]) * width / 2.0
    ctr = np.asarray(centre)
    return np.array([ctr - u - v, ctr + u - v, ctr + u + v, ctr - u + v], dtype=np.float64)


def sample_bilinear(grid: F32, xy: F64, cell_m: float) -> F64:
    """Values of ``grid`` at world points ``xy`` (N, 2) by bilinear interpolation."""
    ny, nx = grid.shape
    x = np.clip(xy[:, 0] / cell_m, 0, nx - 1.000001)
    y = np.clip(xy[:, 1] / cell_m, 0, ny - 1.000001)
    i = x.astype(np.int64)
    j = y.astype(np.int64)
    fx, fy = x - i, y - j
    a = grid[j, i] * (1 - fx) + grid[j, i + 1] * fx
    b = grid[j + 1, i] * (1 - fx) + grid[j + 1, i + 1] * fx
    return np.asarray(a * (1 - fy) + b * fy, dtype=np.float64)


def densify(poly: F64, step_m: float) -> F64:
    """The outline resampled so that no two consecutive points are more than ``step_m`` apart."""
    out = []
    for p, q in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        n = max(1, math.ceil(float(np.hypot(*(q - p))) / step_m))
        t = np.arange(n)[:, None] / n
        out.append(p + t * (q - p))
    return np.concatenate(out)
