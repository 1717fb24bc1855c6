"""The world: a layered height field on a fine grid, plus analytic boxes (slabs, sheets).

Solid matter at (x, y, z) is ``(B <= z <= T) or (z <= F)`` with, per grid cell,

- ``T`` the top of the rubble sheet (``NONE`` inside an opening),
- ``B`` the underside of that sheet (``NONE``: solid all the way down; higher under the lip
  of a hole that opens into a cavity),
- ``F`` a floor under an opening or a lip (``NONE``: no floor, a void).

Boxes are oriented cuboids intersected analytically by the ray caster.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

NONE = -50.0  # "no surface" height (far below anything the camera can see)

MAT_RUBBLE, MAT_DEBRIS, MAT_WATER, MAT_METAL, MAT_PLASTIC, MAT_SLAB = range(6)
NO_RETURN = (MAT_WATER, MAT_METAL, MAT_PLASTIC)


@dataclass
class Box:
    centre: np.ndarray  # (3,)
    axes: np.ndarray  # (3, 3), columns are the unit box axes in world
    half: np.ndarray  # (3,) half extents along the axes
    material: int
    albedo: tuple[float, float, float]
    obj: int  # feature id
    kind: str = "slab"
    extra: dict = field(default_factory=dict)

    def corners(self) -> np.ndarray:
        s = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        return self.centre + (s * self.half) @ self.axes.T

    def lattice(self, step: float) -> np.ndarray:
        n = np.maximum(2, np.ceil(2 * self.half / step).astype(int) + 1)
        g = np.stack(np.meshgrid(*[np.linspace(-1, 1, k) for k in n], indexing="ij"), -1)
        return self.centre + (g.reshape(-1, 3) * self.half) @ self.axes.T


def clamp(a, lo, hi):
    """np.clip without its per-call overhead (these run thousands of times per frame)."""
    return np.minimum(np.maximum(a, lo), hi)


def _bilin_setup(gx, gy, nx: int, ny: int):
    gx = clamp(gx, 0.0, nx - 1.0)
    gy = clamp(gy, 0.0, ny - 1.0)
    ix = np.minimum(gx.astype(np.intp), nx - 2)
    iy = np.minimum(gy.astype(np.intp), ny - 2)
    return iy * nx + ix, gx - ix, gy - iy


def _bilin(flat, i, fx, fy, nx: int):
    a, b, c, d = flat[i], flat[i + 1], flat[i + nx], flat[i + nx + 1]
    if flat.ndim == 2:
        fx, fy = fx[:, None], fy[:, None]
    top = a + (b - a) * fx
    return top + (c + (d - c) * fx - top) * fy


class Grid:
    """Cell (i, j) has its centre at (x0 + j * cell, y0 + i * cell)."""

    def __init__(self, x0: float, y0: float, nx: int, ny: int, cell: float):
        self.x0, self.y0, self.nx, self.ny, self.cell = x0, y0, nx, ny, cell
        shape = (ny, nx)
        self.T = np.zeros(shape, np.float32)
        self.B = np.full(shape, NONE, np.float32)
        self.F = np.full(shape, NONE, np.float32)
        self.albedo = np.zeros((ny, nx, 3), np.float32)
        self.mat_top = np.full(shape, MAT_RUBBLE, np.uint8)
        self.mat_floor = np.full(shape, MAT_DEBRIS, np.uint8)
        self.obj_top = np.zeros(shape, np.int16)
        self.obj_floor = np.zeros(shape, np.int16)
        self.open_id = np.zeros(shape, np.int16)
        self.stain = np.zeros(shape, np.int16)
        # the part of the grid the camera sees the rubble in (set by the frame)
        self.focus = ((x0, y0), (x0 + nx * cell, y0 + ny * cell))

    # --- coordinates -------------------------------------------------------------------
    def g(self, x, y):
        return (np.asarray(x) - self.x0) / self.cell, (np.asarray(y) - self.y0) / self.cell

    def window(self, lo, hi, margin: float = 0.0):
        """Slices of the cells within [lo - margin, hi + margin] and their centres X, Y."""
        (gx0, gy0), (gx1, gy1) = (
            self.g(lo[0] - margin, lo[1] - margin),
            self.g(hi[0] + margin, hi[1] + margin),
        )
        j0, j1 = max(0, int(np.floor(gx0))), min(self.nx, int(np.ceil(gx1)) + 1)
        i0, i1 = max(0, int(np.floor(gy0))), min(self.ny, int(np.ceil(gy1)) + 1)
        sl = (slice(i0, max(i0, i1)), slice(j0, max(j0, j1)))
        Y, X = np.mgrid[sl[0], sl[1]].astype(np.float32)
        return sl, self.x0 + X * self.cell, self.y0 + Y * self.cell

    def poly_window(self, poly: np.ndarray, margin: float = 0.0):
        """(slices, X, Y, mask) of an outline within a window around it."""
        sl, X, Y = self.window(poly.min(0), poly.max(0), margin)
        m = np.zeros(X.shape, np.uint8)
        if m.size:
            off = np.array([self.x0 + sl[1].start * self.cell, self.y0 + sl[0].start * self.cell])
            pts = np.round((poly - off) / self.cell * 16).astype(np.int32)
            cv2.fillPoly(m, [pts], 1, lineType=cv2.LINE_8, shift=4)
        return sl, X, Y, m.astype(bool)

    # --- lookups ----------------------------------------------------------------------
    def bilinear(self, fld: np.ndarray, x, y):
        gx, gy = self.g(x, y)
        i, fx, fy = _bilin_setup(gx, gy, fld.shape[1], fld.shape[0])
        return _bilin(
            fld.reshape(fld.shape[0] * fld.shape[1], -1).squeeze(), i, fx, fy, fld.shape[1]
        )

    def nearest(self, fld: np.ndarray, x, y):
        gx, gy = self.g(x, y)
        ix = clamp(np.rint(gx).astype(np.intp), 0, self.nx - 1)
        iy = clamp(np.rint(gy).astype(np.intp), 0, self.ny - 1)
        return fld[iy, ix]

    def finish(self) -> None:
        """Derived fields, once the world is built: where the simple test suffices, and
        shading slopes (of a slightly smoothed surface, so staircase edges shade evenly)."""
        lay = (self.B > NONE) | (self.F > NONE)
        q = lay.copy()
        q[:-1, :] |= lay[1:, :]
        q[:, :-1] |= lay[:, 1:]
        q[:-1, :-1] |= lay[1:, 1:]
        self.layered = q.ravel()
        self.slopes = {}
        for name, fld in (("T", self.T), ("F", self.F)):
            ok = fld > NONE + 1
            lo = float(fld[ok].min()) - 1.0 if ok.any() else 0.0
            sm = cv2.GaussianBlur(np.maximum(fld, lo), (0, 0), 1.2)
            gy, gx = np.gradient(sm, self.cell)
            self.slopes[name] = (gx.astype(np.float32), gy.astype(np.float32))

    def surfaces(self, x, y):
        """T and F (bilinear) and B (nearest) at points, and whether they are on the grid."""
        gx, gy = self.g(x, y)
        inb = (gx >= 0) & (gx <= self.nx - 1) & (gy >= 0) & (gy <= self.ny - 1)
        i, fx, fy = _bilin_setup(gx, gy, self.nx, self.ny)
        t = _bilin(self.T.ravel(), i, fx, fy, self.nx)
        f = _bilin(self.F.ravel(), i, fx, fy, self.nx)
        bi = clamp(np.rint(gy).astype(np.intp), 0, self.ny - 1) * self.nx + clamp(
            np.rint(gx).astype(np.intp), 0, self.nx - 1
        )
        return t, f, self.B.ravel()[bi], inb

    def solid(self, x, y, z):
        """Whether points are inside matter (``finish`` must have run)."""
        gx, gy = self.g(x, y)
        inb = (gx >= 0) & (gx <= self.nx - 1) & (gy >= 0) & (gy <= self.ny - 1)
        i, fx, fy = _bilin_setup(gx, gy, self.nx, self.ny)
        out = z <= _bilin(self.T.ravel(), i, fx, fy, self.nx)
        lay = np.flatnonzero(self.layered[i])
        if lay.size:
            t, f, b, _ = self.surfaces(x[lay], y[lay])
            zl = z[lay]
            out[lay] = ((zl <= t) & (zl >= b)) | (zl <= f)
        return out & inb

    def normals(self, which: str, x, y) -> np.ndarray:
        gx, gy = self.slopes[which]
        n = np.stack([-self.bilinear(gx, x, y), -self.bilinear(gy, x, y), np.ones(len(x))], 1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)


# --- light fields on a coarser grid ------------------------------------------------------
@dataclass
class Coarse:
    """A field on cells ``factor`` times the grid's (same origin convention)."""

    data: np.ndarray
    x0: float
    y0: float
    cell: float

    def nearest(self, x, y):
        ix = clamp(np.rint((x - self.x0) / self.cell).astype(np.intp), 0, self.data.shape[1] - 1)
        iy = clamp(np.rint((y - self.y0) / self.cell).astype(np.intp), 0, self.data.shape[0] - 1)
        return self.data[iy, ix]

    def bilinear(self, x, y):
        gx, gy = (x - self.x0) / self.cell, (y - self.y0) / self.cell
        i, fx, fy = _bilin_setup(gx, gy, self.data.shape[1], self.data.shape[0])
        return _bilin(self.data.ravel(), i, fx, fy, self.data.shape[1])


def caster_field(grid: Grid, boxes: list[Box], factor: int = 2) -> Coarse:
    """Highest matter per coarse cell (height field tops, floors and boxes)."""
    u = np.maximum(grid.T, grid.F)
    ny, nx = (grid.ny // factor) * factor, (grid.nx // factor) * factor
    hc = u[:ny, :nx].reshape(ny // factor, factor, nx // factor, factor).max(axis=(1, 3))
    cell = grid.cell * factor
    x0 = grid.x0 + (factor - 1) * grid.cell / 2
    y0 = grid.y0 + (factor - 1) * grid.cell / 2
    for b in boxes:
        p = b.lattice(cell / 1.5)
        ix = np.rint((p[:, 0] - x0) / cell).astype(np.intp)
        iy = np.rint((p[:, 1] - y0) / cell).astype(np.intp)
        ok = (ix >= 0) & (ix < hc.shape[1]) & (iy >= 0) & (iy < hc.shape[0])
        np.maximum.at(hc, (iy[ok], ix[ok]), p[ok, 2].astype(np.float32))
    return Coarse(hc, x0, y0, cell)


def horizon_field(hc: Coarse, sun_az: float, sun_el: float, reach: float = 3.0) -> Coarse:
    """Height below which a point is in the sun's shadow (casters within ``reach`` m)."""
    k_max = int(reach / hc.cell)
    pad_val = float(np.median(hc.data))
    h = np.pad(hc.data, k_max + 1, constant_values=pad_val)
    ny, nx = hc.data.shape
    out = np.full((ny, nx), -1e3, np.float32)
    ca, sa, te = np.cos(sun_az), np.sin(sun_az), np.tan(sun_el)
    p = k_max + 1
    last = None
    for k in range(1, k_max + 1):
        ox, oy = round(k * ca), round(k * sa)
        if (ox, oy) == last:
            continue
        last = (ox, oy)
        dist = float(np.hypot(ox, oy)) * hc.cell
        np.maximum(out, h[p + oy : p + oy + ny, p + ox : p + ox + nx] - dist * te, out=out)
    return Coarse(out, hc.x0, hc.y0, hc.cell)


def sky_visibility(hc: Coarse, P: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Cosine-weighted share of open sky above points (8 directions, horizon up to 0.6 m)."""
    radii = (0.05, 0.14, 0.32, 0.6)
    pad = int(np.ceil(radii[-1] / hc.cell)) + 1
    h = np.pad(hc.data, pad, mode="edge").ravel()
    nxp = hc.data.shape[1] + 2 * pad
    ix = clamp(np.rint((P[:, 0] - hc.x0) / hc.cell).astype(np.intp), 0, hc.data.shape[1] - 1)
    iy = clamp(np.rint((P[:, 1] - hc.y0) / hc.cell).astype(np.intp), 0, hc.data.shape[0] - 1)
    base = (iy + pad) * nxp + ix + pad
    z = P[:, 2].astype(np.float32)
    vis = np.zeros(len(P), np.float32)
    a0 = rng.uniform(0, np.pi / 4)
    for j in range(8):
        a = a0 + j * np.pi / 4
        slope = np.zeros(len(P), np.float32)
        for r in radii:
            off = round(r * np.sin(a) / hc.cell) * nxp + round(r * np.cos(a) / hc.cell)
            np.maximum(slope, (h[base + off] - z) * np.float32(1 / r), out=slope)
        vis += 1.0 / (1.0 + slope * slope)  # cos^2 of the horizon elevation
    vis /= 8
    covered = h[base] > z + 0.06
    return np.where(covered, vis * 0.12, vis).astype(float)
