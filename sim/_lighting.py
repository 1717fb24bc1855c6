"""Dawn/dusk lighting of the height field: soft sun shadows, sky visibility, shading.

Everything here runs once per world (or per change of sun); the renderer only samples the
resulting radiance map. Grids are indexed ``[row, col]`` = ``[y / cell, x / cell]``.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = ["SKY_RGB", "SUN_RGB", "radiance_map", "sky_visibility", "sun_visibility"]

F32 = npt.NDArray[np.float32]

#: Colour of the low sun (warm) and of the sky's diffuse light (cool), linear RGB irradiance.
SUN_RGB = (1.55, 1.05, 0.62)
SKY_RGB = (0.42, 0.48, 0.60)


@njit(cache=True, inline="always")
def _bilinear(h: F32, x: float, y: float) -> float:
    ny, nx = h.shape
    x = min(max(x, 0.0), nx - 1.000001)
    y = min(max(y, 0.0), ny - 1.000001)
    i = int(x)
    j = int(y)
    fx = x - i
    fy = y - j
    a = h[j, i] * (1.0 - fx) + h[j, i + 1] * fx
    b = h[j + 1, i] * (1.0 - fx) + h[j + 1, i + 1] * fx
    return float(a * (1.0 - fy) + b * fy)


@njit(cache=True)
def _sun_visibility(
    h: F32, cell: float, sx: float, sy: float, tan_el: float, softness: float, max_dist: float
) -> F32:
    ny, nx = h.shape
    zmax = h.max()
    out = np.empty((ny, nx), dtype=np.float32)
    for j in range(ny):
        for i in range(nx):
            h0 = h[j, i] + 0.01
            res = 1.0
            dist = cell
            while dist < max_dist:
                x = i + sx * dist / cell
                y = j + sy * dist / cell
                if x < 0 or y < 0 or x > nx - 1 or y > ny - 1:
                    break
                ray_z = h0 + dist * tan_el
                if ray_z > zmax:
                    break
                r = softness * (ray_z - _bilinear(h, x, y)) / dist
                if r < res:
                    res = r
                    if res <= 0.0:
                        res = 0.0
                        break
                dist += cell * max(1.0, dist / 0.6)
            out[j, i] = res
    return out


@njit(cache=True)
def _sky_visibility(h: F32, cell: float, n_dirs: int, max_dist: float) -> F32:
    ny, nx = h.shape
    out = np.empty((ny, nx), dtype=np.float32)
    for j in range(ny):
        for i in range(nx):
            h0 = h[j, i]
            acc = 0.0
            for k in range(n_dirs):
                ang = 2.0 * math.pi * (k + 0.5) / n_dirs
                dx = math.cos(ang)
                dy = math.sin(ang)
                t_max = 0.0
                dist = cell
                while dist <= max_dist:
                    x = i + dx * dist / cell
                    y = j + dy * dist / cell
                    if x < 0 or y < 0 or x > nx - 1 or y > ny - 1:
                        break
                    t = (_bilinear(h, x, y) - h0) / dist
                    t_max = max(t_max, t)
                    dist += cell * max(1.0, dist / 0.5)
                # Cosine-weighted sky seen above a horizon of elevation a: cos(a)^2.
                acc += 1.0 / (1.0 + t_max * t_max)
            out[j, i] = acc / n_dirs
    return out


def _coarse(h: F32, cell_m: float, factor: int) -> tuple[F32, float]:
    if factor <= 1:
        return h, cell_m
    ny, nx = h.shape
    small = cv2.resize(
        h, ((nx - 1) // factor + 1, (ny - 1) // factor + 1), interpolation=cv2.INTER_AREA
    )
    return np.ascontiguousarray(small, dtype=np.float32), cell_m * factor


def _upsample(a: F32, shape: tuple[int, int]) -> F32:
    return np.asarray(
        cv2.resize(a, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR), dtype=np.float32
    )


def sun_visibility(
    height: F32,
    cell_m: float,
    sun_azimuth: float,
    sun_elevation: float,
    softness: float = 8.0,
    coarse: int = 2,
) -> F32:
    """Fraction of the sun seen from each cell, in [0, 1], with soft (penumbra) edges.

    height : (ny, nx) float32 ndarray, metres. sun_azimuth : rad clockwise from north;
    sun_elevation : rad above the horizon. ``softness`` ~ 1 / penumbra angle (rad).
    Computed on a grid ``coarse`` times coarser, then upsampled.
    """
    hc, cell = _coarse(height, cell_m, coarse)
    sx, sy = math.sin(sun_azimuth), math.cos(sun_azimuth)
    tan_el = math.tan(max(sun_elevation, 1e-3))
    zrange = float(hc.max() - hc.min())
    max_dist = min(zrange / tan_el, 30.0)
    vis = _sun_visibility(hc, cell, sx, sy, tan_el, softness, max_dist)
    return _upsample(vis, height.shape)


def sky_visibility(
    height: F32, cell_m: float, n_dirs: int = 8, max_dist_m: float = 2.0, coarse: int = 2
) -> F32:
    """Cosine-weighted fraction of the sky seen from each cell (ambient occlusion), in [0, 1].

    Deep narrow holes see little sky (their floors are dark); open ground sees ~1.
    """
    hc, cell = _coarse(height, cell_m, coarse)
    vis = _sky_visibility(hc, cell, n_dirs, max_dist_m)
    return _upsample(vis, height.shape)


def radiance_map(
    height: F32,
    albedo: F32,
    cell_m: float,
    sun_azimuth: float,
    sun_elevation: float,
    sun_strength: float = 1.0,
    sky_strength: float = 1.0,
) -> F32:
    """Linear RGB radiance of each cell under a low sun and the sky.

    height : (ny, nx) float32, metres; albedo : (ny, nx, 3) float32 in [0, 1].
    Returns (ny, nx, 3) float32: albedo x (sun x max(0, n.s) x sun visibility + sky x sky
    visibility).
    """
    gy, gx = np.gradient(height, cell_m)
    norm = np.sqrt(gx * gx + gy * gy + 1.0)
    s = (
        math.sin(sun_azimuth) * math.cos(sun_elevation),
        math.cos(sun_azimuth) * math.cos(sun_elevation),
        math.sin(sun_elevation),
    )
    lambert = np.maximum(0.0, (-gx * s[0] - gy * s[1] + s[2]) / norm).astype(np.float32)
    direct = lambert * sun_visibility(height, cell_m, sun_azimuth, sun_elevation)
    ambient = sky_visibility(height, cell_m)
    irr = sun_strength * direct[..., None] * np.asarray(
        SUN_RGB, dtype=np.float32
    ) + sky_strength * ambient[..., None] * np.asarray(SKY_RGB, dtype=np.float32)
    return np.ascontiguousarray(albedo * irr, dtype=np.float32)
