"""Alien scenes: the shape library, materials and scene records."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, HalfspaceIntersection

from alien_scenes.common import F32, F64, F_PAD, perp_basis

# --------------------------------------------------------------------------- shape library


@dataclass(frozen=True)
class Shape:
    """A convex polyhedron in its unit box: planes n.x <= d (F_PAD, 4), vertices (V, 3)."""

    planes: F64
    verts: F64


def _shape_from_halfspaces(normals: F64, offsets: F64) -> Shape:
    hs = np.hstack([normals, -offsets[:, None]])
    verts = HalfspaceIntersection(hs, np.zeros(3)).intersections
    return _finish_shape(normals, offsets, verts)


def _finish_shape(normals: F64, offsets: F64, verts: F64) -> Shape:
    lo, hi = verts.min(0), verts.max(0)
    centre, ext = (lo + hi) / 2, hi - lo
    verts = (verts - centre) / ext
    # plane n.(x*ext + c) <= d  ->  (n*ext).x <= d - n.c
    n2 = normals * ext
    d2 = offsets - normals @ centre
    norm = np.linalg.norm(n2, axis=1)
    planes = np.zeros((F_PAD, 4))
    planes[:, 3] = 1.0
    planes[: len(n2), :3] = n2 / norm[:, None]
    planes[: len(n2), 3] = d2 / norm
    return Shape(planes, verts)


def make_library(rng: np.random.Generator) -> list[Shape]:
    """Index 0: box, 1: octagonal prism along x, then cut boxes, then random hulls."""
    shapes: list[Shape] = []
    box_n = np.vstack([np.eye(3), -np.eye(3)])
    shapes.append(_shape_from_halfspaces(box_n, np.full(6, 0.5)))
    ang = np.arange(8) * math.pi / 4 + math.pi / 8
    pn = np.column_stack([np.zeros(8), np.cos(ang), np.sin(ang)])
    pn = np.vstack([pn, [[1, 0, 0], [-1, 0, 0]]])
    po = np.concatenate([np.full(8, 0.5 * math.cos(math.pi / 8)), [0.5, 0.5]])
    shapes.append(_shape_from_halfspaces(pn, po))
    for _ in range(32):
        cuts = int(rng.integers(1, 5))
        n = [box_n]
        o = [np.full(6, 0.5)]
        for _c in range(cuts):
            c = rng.choice([-1.0, 1.0], 3) + rng.normal(0, 0.35, 3)
            c /= np.linalg.norm(c)
            far = np.abs(c).sum() * 0.5
            n.append(c[None])
            o.append(np.array([far * rng.uniform(0.45, 0.85)]))
        shapes.append(_shape_from_halfspaces(np.vstack(n), np.concatenate(o)))
    while len(shapes) < 34 + 48:
        k = int(rng.integers(6, 8))
        d = rng.normal(size=(k, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        pts = d * (1 + 0.22 * rng.normal(size=(k, 1)))
        try:
            hull = ConvexHull(pts)
        except RuntimeError:  # a degenerate draw (QhullError)
            continue
        if len(hull.equations) > 10:
            continue
        eq = hull.equations
        shapes.append(_finish_shape(eq[:, :3], -eq[:, 3], pts[hull.vertices]))
    return shapes


def instance(shape: Shape, dims: F64, R: F64, c: F64) -> tuple[F64, F64]:
    """World planes (F_PAD, 4) and vertices (V, 3) of a scaled, rotated, moved shape."""
    n = shape.planes[:, :3]
    d = shape.planes[:, 3]
    m = (n / dims) @ R.T
    norm = np.linalg.norm(m, axis=1)
    live = norm > 1e-12
    planes = np.zeros((F_PAD, 4))
    planes[:, 3] = 1.0
    planes[live, :3] = m[live] / norm[live, None]
    planes[live, 3] = d[live] / norm[live] + planes[live, :3] @ c
    verts = (shape.verts * dims) @ R.T + c
    return planes, verts


# --------------------------------------------------------------------------- materials


_PRESETS: dict[str, tuple[tuple[float, float, float], float, float, float, float]] = {
    # name: (linear albedo, brightness spread, texture contrast, roughness m, IR reflectance)
    "concrete": ((0.36, 0.35, 0.33), 0.35, 0.30, 0.006, 0.55),
    "brick": ((0.42, 0.19, 0.12), 0.30, 0.25, 0.004, 0.45),
    "stone": ((0.30, 0.28, 0.26), 0.35, 0.35, 0.008, 0.5),
    "dirt": ((0.25, 0.20, 0.15), 0.30, 0.55, 0.008, 0.4),
    "wood": ((0.36, 0.25, 0.15), 0.35, 0.35, 0.003, 0.5),
    "rust": ((0.30, 0.14, 0.07), 0.30, 0.45, 0.002, 0.3),
    "dark": ((0.05, 0.05, 0.05), 0.30, 0.30, 0.003, 0.05),
    "metal": ((0.40, 0.41, 0.43), 0.20, 0.20, 0.001, 0.15),
    "drywall": ((0.62, 0.60, 0.56), 0.15, 0.15, 0.002, 0.6),
    "tarp": ((0.08, 0.18, 0.45), 0.25, 0.10, 0.003, 0.4),
    "pvc": ((0.55, 0.25, 0.07), 0.20, 0.10, 0.001, 0.5),
}

KIND_GROUND, KIND_RUBBLE, KIND_WALL, KIND_FLOOR, KIND_PIPE_OUT, KIND_PIPE_IN, KIND_BOWL = range(7)


class Materials:
    """Per-object surface table; row index = object id in the z-buffer."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.rows: list[tuple[float, ...]] = []

    def add(self, name: str, kind: int, tag: int = -1, disp: float | None = None) -> int:
        rgb, spread, contrast, rough, ir = _PRESETS[name]
        r = self.rng
        col = np.array(rgb) * r.uniform(1 - spread, 1 + spread) * (1 + r.normal(0, 0.05, 3))
        off = r.uniform(0, 512, 3)
        row = (
            *np.clip(col, 0.01, 0.9),
            contrast * r.uniform(0.7, 1.3),
            rough if disp is None else disp,
            ir * r.uniform(0.8, 1.2),
            float(tag),
            float(kind),
            *off,
            r.uniform(0.7, 1.4),  # texture scale factor
        )
        self.rows.append(row)
        return len(self.rows) - 1

    def table(self) -> F32:
        return np.asarray(self.rows, np.float32)


# columns of the material table
_M_RGB, M_CON, M_DISP, M_IR, M_TAG, M_KIND, M_OFF, M_SCALE = 0, 3, 4, 5, 6, 7, 8, 11


# --------------------------------------------------------------------------- scene records


@dataclass(frozen=True)
class Hole:
    """An opening in the ground plane continued by an oblique prism shaft."""

    kind: str
    access: bool
    poly: F64  # (K, 2) opening in the ground plane z = 0, metres
    axis_down: F64  # (3,) unit, z < 0
    depth: float  # floor at z = -depth
    rim: F64  # (M, 3) rim polygon in 3-D
    tag: int
    wall_id: int
    floor_id: int
    r_eff: float  # radius of the disc with the cross-section's area, m
    mask: NDArray[np.uint8]  # opening raster at HOLE_RES
    mask_x0: float
    mask_y0: float

    def contains(self, xy: F64) -> NDArray[np.bool_]:
        """Which ground points (N, 2) fall in the opening."""
        i = np.floor((xy[:, 1] - self.mask_y0) / HOLE_RES).astype(np.int64)
        j = np.floor((xy[:, 0] - self.mask_x0) / HOLE_RES).astype(np.int64)
        h, w = self.mask.shape
        ok = (i >= 0) & (i < h) & (j >= 0) & (j < w)
        out = np.zeros(len(xy), bool)
        out[ok] = self.mask[i[ok], j[ok]] > 0
        return out


HOLE_RES = 0.01


@dataclass(frozen=True)
class Tube:
    """A hollow pipe open at its top end: axis up, top centre, radii, bottom axial offset."""

    top: F64
    axis: F64
    r_in: float
    r_out: float
    s_bottom: float
    out_id: int
    in_id: int

    def corners(self) -> F64:
        u, v = perp_basis(self.axis)
        pts = []
        for s in (0.0, self.s_bottom):
            for a in (-1, 1):
                for b in (-1, 1):
                    pts.append(self.top + s * self.axis + self.r_out * (a * u + b * v))
        return np.array(pts)


@dataclass(frozen=True)
class Bowl:
    """A shallow ellipsoidal depression centred on the ground plane."""

    centre: F64  # (3,), z = 0
    M: F64  # (3, 3) world -> unit sphere
    ident: int


@dataclass(frozen=True)
class Stain:
    centre: F64  # (2,)
    axes: F64  # (2,) semi-axes, m
    angle: float
    strength: float
    wet: bool


@dataclass
class Scene:
    C: F64
    R: F64  # world-from-camera, columns = camera x, y, z axes
    up: F64
    sun: F64 | None
    sun_rgb: F64
    glow: F64  # horizontal unit vector towards the sunrise glow
    glow_strength: float
    sky_rgb: F64
    e_sun: float
    zmax: float
    planes: F32
    verts: F32
    poly_ids: NDArray[np.int32]
    ell_c: F32
    ell_mat: F32
    ell_corners: F32
    ell_ids: NDArray[np.int32]
    tubes: list[Tube]
    holes: list[Hole]
    bowls: list[Bowl]
    stains: list[Stain]
    mats: F32
    region: tuple[float, float, float, float]
    meta: dict[str, Any] = field(default_factory=dict)
