"""Fast rendering of the height field by rasterising its triangles into a depth buffer.

The surface is the triangulated height field (each grid cell split along the diagonal from
node ``(i, j)`` to ``(i + 1, j + 1)``), the same surface :mod:`sim._raycast` traces.
Every pixel centre gets the exact axial depth of the nearest triangle it lies in (1/z
interpolated linearly in the image, which is exact for planar triangles) and the
perspective-correct interpolation of the vertices' radiance. Only the cells inside the
view frustum's footprint on the terrain's height range are drawn.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = ["footprint_rows", "rasterise_view"]

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

_NEAR_M = 0.05  # triangles with a vertex closer than this to the camera plane are skipped


def footprint_rows(
    shape: tuple[int, int],
    cell_m: float,
    zmin: float,
    zmax: float,
    rotation: F64,
    position: F64,
    corner_dirs_c: F64,
) -> tuple[int, I64, I64]:
    """Cells the camera can see: first cell row and, per row, the [lo, hi) cell columns.

    corner_dirs_c : (K, 3) float64, directions of the image's corner (and edge) rays in the
    camera frame. The frustum is cut by the slab ``zmin <= z <= zmax``; the cells under the
    convex hull of that cut (plus one cell of margin) are returned.
    """
    ny, nx = shape
    d = corner_dirs_c @ rotation.T  # world directions
    far = 2.0 * math.hypot(nx * cell_m, ny * cell_m) + abs(position[2]) + (zmax - zmin)
    pts = [position[:2]]
    for dw in d:
        for z in (zmin, zmax):
            t = (z - position[2]) / dw[2] if abs(dw[2]) > 1e-12 else -1.0
            pts.append((position + dw * (t if 0.0 < t < far else far))[:2])
    hull = _convex_hull(np.asarray(pts))
    j_lo = max(math.floor(hull[:, 1].min() / cell_m) - 1, 0)
    j_hi = min(math.ceil(hull[:, 1].max() / cell_m) + 1, ny - 1)
    if j_hi <= j_lo:
        return 0, np.zeros(0, np.int64), np.zeros(0, np.int64)
    ys = (np.arange(j_lo, j_hi + 1) * cell_m)[:, None]  # cell-row boundaries
    p, q = hull, np.roll(hull, -1, axis=0)
    y0, y1 = np.minimum(p[:, 1], q[:, 1]), np.maximum(p[:, 1], q[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (ys - p[:, 1]) / (q[:, 1] - p[:, 1])
    x = p[:, 0] + f * (q[:, 0] - p[:, 0])
    inside = (ys >= y0) & (ys <= y1) & np.isfinite(x)
    xmin = np.where(inside, x, np.inf).min(axis=1)
    xmax = np.where(inside, x, -np.inf).max(axis=1)
    # A cell row spans two boundaries; also hull vertices strictly inside a row count.
    lo_b = np.minimum(xmin[:-1], xmin[1:])
    hi_b = np.maximum(xmax[:-1], xmax[1:])
    row_of_vertex = np.floor(hull[:, 1] / cell_m).astype(np.int64) - j_lo
    for k, r in enumerate(row_of_vertex):
        if 0 <= r < len(lo_b):
            lo_b[r] = min(lo_b[r], hull[k, 0])
            hi_b[r] = max(hi_b[r], hull[k, 0])
    lo = np.clip(np.floor(np.nan_to_num(lo_b / cell_m, posinf=nx, neginf=0)) - 1, 0, nx - 1)
    hi = np.clip(np.ceil(np.nan_to_num(hi_b / cell_m, posinf=nx, neginf=0)) + 1, 0, nx - 1)
    hi = np.maximum(hi, lo)
    return j_lo, lo.astype(np.int64), hi.astype(np.int64)


def _convex_hull(pts: F64) -> F64:
    """Andrew's monotone chain; (M, 2) counter-clockwise hull of (N, 2) points."""
    p = sorted({(float(x), float(y)) for x, y in pts})
    if len(p) < 3:
        return np.asarray(p * (3 // max(len(p), 1) + 1))[:3]

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for pt in p:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], pt) <= 0:
            lower.pop()
        lower.append(pt)
    upper: list[tuple[float, float]] = []
    for pt in reversed(p):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], pt) <= 0:
            upper.pop()
        upper.append(pt)
    return np.asarray(lower[:-1] + upper[:-1], dtype=np.float64)


@njit(cache=True, inline="always")
def _triangle(
    u0: float,
    v0: float,
    w0: float,
    u1: float,
    v1: float,
    w1: float,
    u2: float,
    v2: float,
    w2: float,
    rad: F32,
    j0: int,
    i0: int,
    j1: int,
    i1: int,
    j2: int,
    i2: int,
    zbuf: F32,
    rgb: F32,
) -> None:
    """Draw one triangle; (u, v) pixels, w = 1 / axial depth; vertex radiance at rad[j, i]."""
    area = (u1 - u0) * (v2 - v0) - (u2 - u0) * (v1 - v0)
    if abs(area) < 1e-12:
        return
    height, width = zbuf.shape
    xa = max(math.ceil(min(u0, u1, u2)), 0)
    xb = min(math.floor(max(u0, u1, u2)), width - 1)
    ya = max(math.ceil(min(v0, v1, v2)), 0)
    yb = min(math.floor(max(v0, v1, v2)), height - 1)
    if xa > xb or ya > yb:
        return
    inv = 1.0 / area
    # Barycentric b0, b1 are affine in (x, y): b = base + bx * x + by * y.
    b0x = (v1 - v2) * inv
    b0y = (u2 - u1) * inv
    b0c = (u1 * v2 - u2 * v1) * inv
    b1x = (v2 - v0) * inv
    b1y = (u0 - u2) * inv
    b1c = (u2 * v0 - u0 * v2) * inv
    tol = -1e-9
    for y in range(ya, yb + 1):
        c0 = b0c + b0y * y
        c1 = b1c + b1y * y
        for x in range(xa, xb + 1):
            b0 = c0 + b0x * x
            b1 = c1 + b1x * x
            b2 = 1.0 - b0 - b1
            if b0 < tol or b1 < tol or b2 < tol:
                continue
            iz = b0 * w0 + b1 * w1 + b2 * w2
            if iz <= 0.0:
                continue
            z = 1.0 / iz
            if z < zbuf[y, x]:
                zbuf[y, x] = z
                # Perspective-correct interpolation of the vertices' radiance.
                k0 = b0 * w0 * z
                k1 = b1 * w1 * z
                k2 = b2 * w2 * z
                for c in range(rad.shape[2]):
                    rgb[y, x, c] = k0 * rad[j0, i0, c] + k1 * rad[j1, i1, c] + k2 * rad[j2, i2, c]


@njit(cache=True)
def _draw(
    h: F32,
    rad: F32,
    cell: float,
    j_lo: int,
    col_lo: I64,
    col_hi: I64,
    rot: F64,
    pos: F64,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    zbuf: F32,
    rgb: F32,
) -> None:
    nrow = col_lo.shape[0]
    # Rows of projected nodes, reused between neighbouring cell rows: u, v, 1/z (0 = behind).
    nx = h.shape[1]
    pu = np.empty((2, nx), dtype=np.float64)
    pv = np.empty((2, nx), dtype=np.float64)
    pw = np.empty((2, nx), dtype=np.float64)
    for r in range(nrow + 1):
        j = j_lo + r
        buf = r % 2
        a = col_lo[max(r - 1, 0)] if r > 0 else col_lo[0]
        b = col_hi[max(r - 1, 0)] if r > 0 else col_hi[0]
        if r < nrow:
            a = min(a, col_lo[r])
            b = max(b, col_hi[r])
        y = j * cell - pos[1]
        for i in range(a, b + 1):
            x = i * cell - pos[0]
            z = h[j, i] - pos[2]
            xc = rot[0, 0] * x + rot[1, 0] * y + rot[2, 0] * z
            yc = rot[0, 1] * x + rot[1, 1] * y + rot[2, 1] * z
            zc = rot[0, 2] * x + rot[1, 2] * y + rot[2, 2] * z
            if zc < _NEAR_M:
                pw[buf, i] = 0.0
            else:
                iz = 1.0 / zc
                pu[buf, i] = fx * xc * iz + cx
                pv[buf, i] = fy * yc * iz + cy
                pw[buf, i] = iz
        if r == 0:
            continue
        lo_buf = 1 - buf  # node row j - 1
        jj = j - 1
        for i in range(col_lo[r - 1], col_hi[r - 1]):
            w00 = pw[lo_buf, i]
            w10 = pw[lo_buf, i + 1]
            w01 = pw[buf, i]
            w11 = pw[buf, i + 1]
            if w00 == 0.0 or w10 == 0.0 or w01 == 0.0 or w11 == 0.0:
                continue
            u00, v00 = pu[lo_buf, i], pv[lo_buf, i]
            u10, v10 = pu[lo_buf, i + 1], pv[lo_buf, i + 1]
            u01, v01 = pu[buf, i], pv[buf, i]
            u11, v11 = pu[buf, i + 1], pv[buf, i + 1]
            _triangle(
                u00, v00, w00, u10, v10, w10, u11, v11, w11,
                rad, jj, i, jj, i + 1, j, i + 1, zbuf, rgb,
            )  # fmt: skip
            _triangle(
                u00, v00, w00, u11, v11, w11, u01, v01, w01,
                rad, jj, i, j, i + 1, j, i, zbuf, rgb,
            )  # fmt: skip


def rasterise_view(
    height: F32,
    radiance: F32,
    cell_m: float,
    zmin: float,
    zmax: float,
    rotation: F64,
    position: F64,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    width: int,
    height_px: int,
) -> tuple[F32, F32]:
    """Render depth and radiance of the height field seen from a pinhole camera.

    Returns
    -------
    depth : (height_px, width) float32, metres along the optical axis, 0 = no surface.
    radiance : (height_px, width, C) float32, the input's C channels (linear radiance, and
        any further surface property) of the surface seen (0 if none).
    """
    us = np.array([-0.5, (width - 1) / 2.0, width - 0.5])
    vs = np.array([-0.5, (height_px - 1) / 2.0, height_px - 0.5])
    dirs = np.array([[(u - cx) / fx, (v - cy) / fy, 1.0] for u in us for v in vs])
    rot = np.ascontiguousarray(rotation, dtype=np.float64)
    pos = np.ascontiguousarray(position, dtype=np.float64)
    j_lo, lo, hi = footprint_rows(height.shape, cell_m, zmin, zmax, rot, pos, dirs)
    zbuf = np.full((height_px, width), np.inf, dtype=np.float32)
    rgb = np.zeros((height_px, width, radiance.shape[2]), dtype=np.float32)
    if len(lo):
        _draw(height, radiance, float(cell_m), j_lo, lo, hi, rot, pos, fx, fy, cx, cy, zbuf, rgb)
    zbuf[~np.isfinite(zbuf)] = 0.0
    return zbuf, rgb
