"""Exact ray casting of the triangulated height field with a max-height pyramid.

Each grid cell is split into two triangles along the diagonal from node ``(i, j)`` to
``(i + 1, j + 1)`` (the surface :mod:`sim._raster` draws); along a ray the height
of a triangle is linear, so the first intersection in a cell is found in closed form. Empty
space is skipped with a pyramid of maximum heights (level 0 = each cell's
highest corner, level l = blocks of 2^l x 2^l cells): a ray leaves a block at once when it
stays above the block's maximum.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = ["MaxPyramid", "build_pyramid", "cast_rays"]

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

_EPS_T = 1e-6  # metres: how far a ray steps past a block boundary
_MAX_STEPS = 200_000
_START_LEVEL = 6


class MaxPyramid(NamedTuple):
    """Max-height pyramid of a height field, all levels in one flat array.

    data : float32, level l stored row-major at ``data[offsets[l]:]``, shape
        ``(rows[l], cols[l])``; zmin, zmax : height range of the field, metres.
    """

    data: F32
    offsets: I64
    rows: I64
    cols: I64
    zmin: float
    zmax: float


def build_pyramid(height: F32) -> MaxPyramid:
    """The max-height pyramid of a (ny, nx) float32 height field (a few ms per million cells)."""
    lvl = np.maximum(
        np.maximum(height[:-1, :-1], height[1:, :-1]), np.maximum(height[:-1, 1:], height[1:, 1:])
    )
    levels = [lvl]
    while lvl.shape[0] > 1 or lvl.shape[1] > 1:
        r, c = lvl.shape
        pad = np.full((r + r % 2, c + c % 2), -np.inf, dtype=np.float32)
        pad[:r, :c] = lvl
        lvl = pad.reshape(pad.shape[0] // 2, 2, pad.shape[1] // 2, 2).max(axis=(1, 3))
        levels.append(lvl)
    sizes = [a.size for a in levels]
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    data = np.concatenate([a.ravel() for a in levels]).astype(np.float32)
    rows = np.array([a.shape[0] for a in levels], dtype=np.int64)
    cols = np.array([a.shape[1] for a in levels], dtype=np.int64)
    return MaxPyramid(data, offsets, rows, cols, float(height.min()), float(height.max()))


@njit(cache=True, inline="always")
def _plane_z(h00: float, h10: float, h01: float, h11: float, u: float, v: float) -> float:
    """Height of the cell's triangulated surface at local (u, v) in [0, 1]^2."""
    if u >= v:
        return h00 + (h10 - h00) * u + (h11 - h10) * v
    return h00 + (h11 - h01) * u + (h01 - h00) * v


@njit(cache=True, inline="always")
def _cell_hit(
    h: F32,
    i: int,
    j: int,
    gx: float,
    gy: float,
    oz: float,
    gdx: float,
    gdy: float,
    dz: float,
    t_in: float,
    t_out: float,
) -> float:
    """First t in [t_in, t_out] where the ray meets cell (i, j)'s two triangles, else -1.

    The ray is ``(gx, gy) + t (gdx, gdy)`` in grid units and ``oz + t dz`` in metres. The
    cell is split along the diagonal from node (i, j) to (i + 1, j + 1); along the ray the
    surface height is linear on each side of it, so each piece has one closed-form root.
    """
    h00 = h[j, i]
    h10 = h[j, i + 1]
    h01 = h[j + 1, i]
    h11 = h[j + 1, i + 1]
    u0 = gx + t_in * gdx - i
    v0 = gy + t_in * gdy - j
    span = t_out - t_in
    # Where the ray crosses the diagonal u = v (if inside the span): split there.
    s_mid = -1.0
    if gdx != gdy:
        s_mid = (v0 - u0) / (gdx - gdy)
    s_a = 0.0
    f_a = oz + t_in * dz - _plane_z(h00, h10, h01, h11, u0, v0)
    if f_a <= 0.0:
        return t_in
    for piece in range(2):
        if piece == 0:
            s_b = s_mid if 0.0 < s_mid < span else span
        else:
            if not (0.0 < s_mid < span):
                break
            s_b = span
        # Evaluate on the side the piece's midpoint lies on (exact at the diagonal too).
        s_c = 0.5 * (s_a + s_b)
        uc = u0 + s_c * gdx
        vc = v0 + s_c * gdy
        ub = u0 + s_b * gdx
        vb = v0 + s_b * gdy
        if uc >= vc:
            hb = h00 + (h10 - h00) * ub + (h11 - h10) * vb
        else:
            hb = h00 + (h11 - h01) * ub + (h01 - h00) * vb
        f_b = oz + (t_in + s_b) * dz - hb
        if f_b <= 0.0:
            return float(t_in + s_a + (s_b - s_a) * f_a / (f_a - f_b))
        s_a = s_b
        f_a = f_b
    return -1.0


@njit(cache=True, inline="always")
def _trace(
    h: F32,
    data: F32,
    offs: I64,
    prow: I64,
    pcol: I64,
    cell: float,
    zmin: float,
    zmax: float,
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
) -> float:
    """Ray parameter (metres along the unit direction) of the first hit, or -1."""
    ny, nx = h.shape
    nlev = prow.shape[0]
    # Work in grid units: node (i, j) at (i, j); t stays in metres along the ray.
    gx = ox / cell
    gy = oy / cell
    gdx = dx / cell
    gdy = dy / cell
    inv_x = 1.0 / gdx if gdx != 0.0 else 1e30
    inv_y = 1.0 / gdy if gdy != 0.0 else 1e30
    t0 = 0.0
    t1 = 1e9
    for axis in range(3):
        if axis == 0:
            o, d, lo, hi = gx, gdx, 0.0, nx - 1.0
        elif axis == 1:
            o, d, lo, hi = gy, gdy, 0.0, ny - 1.0
        else:
            o, d, lo, hi = oz, dz, zmin, zmax
        if abs(d) < 1e-15:
            if o < lo or o > hi:
                return -1.0
        else:
            ta = (lo - o) / d
            tb = (hi - o) / d
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
    if t0 > t1:
        return -1.0
    step_x = 1 if gdx > 0.0 else 0
    step_y = 1 if gdy > 0.0 else 0
    t = t0
    lev = min(nlev - 1, _START_LEVEL)
    for _ in range(_MAX_STEPS):
        if t > t1:
            return -1.0
        ix = int(gx + t * gdx) >> lev
        iy = int(gy + t * gdy) >> lev
        ix = min(max(ix, 0), pcol[lev] - 1)
        iy = min(max(iy, 0), prow[lev] - 1)
        tx = (((ix + step_x) << lev) - gx) * inv_x if gdx != 0.0 else 1e30
        ty = (((iy + step_y) << lev) - gy) * inv_y if gdy != 0.0 else 1e30
        te = max(min(tx, ty, t1), t)
        zlo = oz + (te if dz < 0.0 else t) * dz  # the ray's lowest point in this block
        if zlo > data[offs[lev] + iy * pcol[lev] + ix]:
            t = te + _EPS_T
            if lev < nlev - 1:
                lev += 1
            continue
        if lev > 0:
            lev -= 1
            continue
        hit = _cell_hit(h, ix, iy, gx, gy, oz, gdx, gdy, dz, t, te)
        if hit >= 0.0:
            return hit
        t = te + _EPS_T
        if nlev > 1:
            lev = 1
    return -1.0


@njit(cache=True, inline="always")
def _sample3(img: F32, x: float, y: float, out: F32, k: int) -> None:
    """out[k] = img at grid point (x, y), interpolated on the cell's triangles."""
    ny, nx = img.shape[0], img.shape[1]
    x = min(max(x, 0.0), nx - 1.000001)
    y = min(max(y, 0.0), ny - 1.000001)
    i = int(x)
    j = int(y)
    u = x - i
    v = y - j
    for c in range(3):
        if u >= v:
            val = (1.0 - u) * img[j, i, c] + (u - v) * img[j, i + 1, c] + v * img[j + 1, i + 1, c]
        else:
            val = (1.0 - v) * img[j, i, c] + (v - u) * img[j + 1, i, c] + u * img[j + 1, i + 1, c]
        out[k, c] = val


@njit(cache=True)
def _cast(
    h: F32,
    rad: F32,
    data: F32,
    offs: I64,
    prow: I64,
    pcol: I64,
    cell: float,
    zmin: float,
    zmax: float,
    origins: F64,
    dirs: F64,
    t_out: F64,
    rgb: F32,
) -> None:
    for k in range(origins.shape[0]):
        ox, oy, oz = origins[k, 0], origins[k, 1], origins[k, 2]
        dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
        t = _trace(h, data, offs, prow, pcol, cell, zmin, zmax, ox, oy, oz, dx, dy, dz)
        t_out[k] = t
        if t < 0.0:
            rgb[k, 0] = 0.0
            rgb[k, 1] = 0.0
            rgb[k, 2] = 0.0
        else:
            _sample3(rad, (ox + t * dx) / cell, (oy + t * dy) / cell, rgb, k)


def cast_rays(
    height: F32,
    radiance: F32,
    pyramid: MaxPyramid,
    cell_m: float,
    origins: npt.ArrayLike,
    directions: npt.ArrayLike,
) -> tuple[F64, F32]:
    """Trace rays into the height field.

    origins : (N, 3) world metres; directions : (N, 3), normalised here.
    Returns ``t`` (N,) float64, metres from the origin to the first hit (NaN = no hit,
    e.g. a ray that leaves the field) and ``radiance`` (N, 3) float32 of the surface hit.
    """
    o = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(d / np.linalg.norm(d, axis=1, keepdims=True))
    t = np.empty(len(o), dtype=np.float64)
    rgb = np.empty((len(o), 3), dtype=np.float32)
    p = pyramid
    _cast(height, radiance, p.data, p.offsets, p.rows, p.cols, float(cell_m), p.zmin, p.zmax,
          o, d, t, rgb)  # fmt: skip
    t[t < 0] = np.nan
    return t, rgb
