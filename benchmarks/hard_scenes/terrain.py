"""The rubble field: undulating debris, hundreds of broken blocks and beams, and colours."""

from __future__ import annotations

import numpy as np
from shapes import fractal, rect, rotate, smooth_noise
from world import Grid

# linear-light albedos
GROUNDS = {
    "concrete": (0.40, 0.39, 0.37),
    "plaster": (0.52, 0.49, 0.44),
    "brick": (0.40, 0.25, 0.18),
    "soil": (0.30, 0.25, 0.19),
    "ash": (0.22, 0.22, 0.23),
}
CHUNKS = (
    (0.48, 0.47, 0.45),
    (0.60, 0.58, 0.53),
    (0.44, 0.26, 0.18),
    (0.38, 0.28, 0.18),
    (0.36, 0.21, 0.12),
    (0.18, 0.18, 0.19),
    (0.53, 0.48, 0.39),
    (0.30, 0.31, 0.33),
)
SLAB = (0.46, 0.45, 0.43)


def build_terrain(grid: Grid, rng: np.random.Generator) -> dict:
    """Fill ``grid`` with a rubble surface near z = 0 and its albedo. Returns a summary."""
    shape, cell = (grid.ny, grid.nx), grid.cell
    rough = rng.uniform(0.6, 1.4)
    grid.T[:] = fractal(
        rng,
        shape,
        cell,
        [(2.5, 0.10 * rough), (0.7, 0.05 * rough), (0.2, 0.02 * rough), (0.05, 0.005 * rough)],
    )
    names = list(GROUNDS)
    g1, g2 = rng.choice(len(names), 2, replace=False)
    c1, c2 = np.array(GROUNDS[names[g1]]), np.array(GROUNDS[names[g2]])
    mix = np.clip(0.5 + 0.6 * smooth_noise(rng, shape, 1.2 / cell), 0, 1)[..., None]
    base = c1 * (1 - mix) + c2 * mix
    tex = (
        1.0
        + 0.16 * smooth_noise(rng, shape, 0.3 / cell)
        + 0.10 * smooth_noise(rng, shape, 0.04 / cell)
        + 0.06 * smooth_noise(rng, shape, 1.0)
    )
    grid.albedo[:] = np.clip(base * tex[..., None], 0.02, 0.9)

    lo, hi = grid.focus
    area = float(np.prod(np.asarray(hi) - np.asarray(lo)))
    density = rng.uniform(5.0, 14.0)
    n_chunks = int(area * density)
    for _ in range(n_chunks):
        length = float(np.exp(rng.uniform(np.log(0.06), np.log(0.55))))
        width = length * rng.uniform(0.3, 1.0)
        height = min(rng.uniform(0.02, 0.28), 0.7 * length)
        colour = np.array(CHUNKS[rng.integers(len(CHUNKS))]) * rng.uniform(0.8, 1.15)
        _stamp(grid, rng, lo, hi, length, width, height, colour, bool(rng.random() < 0.45))
    n_beams = int(rng.integers(0, 7))
    for _ in range(n_beams):
        colour = np.array(((0.40, 0.29, 0.18), (0.33, 0.17, 0.09))[rng.integers(2)])
        _stamp(
            grid,
            rng,
            lo,
            hi,
            rng.uniform(0.8, 2.4),
            rng.uniform(0.04, 0.12),
            rng.uniform(0.04, 0.12),
            colour,
        )
    return {
        "roughness": round(float(rough), 3),
        "blocks_per_m2": round(float(density), 2),
        "beams": n_beams,
    }


def _stamp(grid: Grid, rng, lo, hi, length, width, height, colour, shard: bool = False) -> None:
    """One block (or an irregular shard) dropped on the rubble, its top a tilted plane."""
    cx, cy = rng.uniform(lo[0], hi[0]), rng.uniform(lo[1], hi[1])
    if shard:
        th = np.sort(rng.uniform(0, 2 * np.pi, int(rng.integers(3, 8))))
        r = rng.uniform(0.6, 1.0, th.size)
        pts = np.stack([r * np.cos(th) * length / 2, r * np.sin(th) * width / 2], 1)
        poly = rotate(pts, rng.uniform(0, np.pi)) + np.array([cx, cy])
    else:
        poly = rect((cx, cy), length, width, rng.uniform(0, np.pi))
    sl, X, Y, m = grid.poly_window(poly)
    if not m.any():
        return
    tw = grid.T[sl]
    gx, gy = rng.normal(0, 0.25, 2)
    top = float(np.mean(tw[m])) + height + gx * (X - cx) + gy * (Y - cy)
    won = m & (top > tw)
    tw[won] = top[won]
    shade = 1.0 + 0.08 * rng.standard_normal(int(won.sum()))
    grid.albedo[sl][won] = np.clip(colour[None, :] * shade[:, None], 0.02, 0.9)
