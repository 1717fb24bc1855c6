#!/usr/bin/env python3
"""Alien synthetic rubble scenes: an independent RGB-D generator for robustness tests.

This script writes a COCO-style dataset of Xtion-like RGB-D frames of disaster rubble seen
from 2-3.5 m above at dawn, with labelled access holes. It is written from first principles
and shares no code with ``capture/sim``; it needs only numpy, scipy and OpenCV.

Technique
---------
The scene is a set of analytic solids, ray-cast per pixel with a z-buffer (no height field):

* the base ground is the plane z = 0 of a *site frame* (the pile may slope relative to
  gravity); access holes, small holes and cracks are oblique polygonal shafts cut into it
  (a sheared prism with a floor, or no floor within reach), shallow depressions are
  ellipsoidal bowls;
* rubble is convex polyhedra (random convex hulls and corner-cut boxes for concrete chunks,
  boxes for bricks, blocks, slabs, planks, sheets, octagonal prisms for rebar and poles),
  stacked with a coarse height map, plus ellipsoidal dirt mounds and hollow pipes (tubes);
* each polyhedron is intersected (slab test) with the rays under its projected convex
  hull, in vectorised batches of (pixel, object) pairs, nearest objects first, skipping
  pixels already hidden; the nearest hit wins;
* the same caster renders an orthographic shadow map from the sun, so low dawn sun casts
  long shadows, also into holes.

Photometry: Lambert shading from a warm low sun (absent before sunrise) and a bluish sky with
ambient occlusion (screen space, plus an analytic sky view factor inside shafts), triplanar
FFT-noise textures, dust, dark stains; then a camera model: blur, vignetting, Bayer mosaic,
Poisson shot noise at dawn photon counts, read noise, imperfect auto exposure and white
balance (colour casts), demosaicing, gamma.

Depth: Z along the optical axis with surface roughness, lateral jitter and misregistration,
IR projector shadows (projector 75 mm to the right), axial noise sigma = k 1.425e-6 Z_mm^2 mm
(k = 0.6-1.0, partly spatially correlated), 1/8-pixel disparity quantisation, per-scene
maximum range 3.5-4.5 m, dropouts at grazing angles, on dark or wet surfaces, along depth
edges, in speckles and blobs, and an invalid band at the left border.

Ground truth: each access hole (opening at least 0.7 m x 0.45 m across the shaft axis, at
most 1.6 m, inscribed circle at least 0.42 m) is labelled with the bounding box of its rim
projected into the image (pixel edges: pixel i spans [i, i+1)), and its rim polygon as
``segmentation``. ``iscrowd`` = 1 when the rim is cut by the image border, when less than
half the opening is visible (occluded by rubble), or when the rim lies beyond the sensor's
range; holes with under 5 % of their opening visible, or out of view, are not labelled.

Scene distributions: 0/1/2/3 access holes with probability 0.12/0.45/0.29/0.14 (irregular
polygons, rectangular openings, gaps between two slabs, round shafts and tilted pipes; shaft
axes tilted up to 35 deg; floors 1-2.8 m deep or none within 12 m), 80 % of them placed
wholly in view; Poisson numbers of small holes (< 0.3 m), cracks, small pipes, shallow
bowls (< 0.25 m deep), dark or wet stains; slabs, dirt mounds, walls beyond the view that
cast shadows. Camera 2-3.5 m above the median rubble surface, tilted 0-20 deg from nadir,
any yaw, roll ~1.5 deg; the site slopes 0-10 deg; the sun is 3-28 deg high, or below the
horizon in 25 % of scenes. Intrinsics: fx = fy in 560-580 px, centre within 4 px of the
image centre, one draw per dataset (``camera.json``).

Each image record carries a ``scene`` dict (pose, light, contents) and each annotation
``hole_kind``, ``visible_fraction`` and ``rim_depth_m``, for analysis only. Output is a
deterministic function of (seed, image index), whatever ``--jobs``.

Usage::

    python benchmarks/alien_scenes.py OUT --n 60 --seed 7 [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import multiprocessing
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, HalfspaceIntersection

__all__ = ["CameraModel", "generate_dataset", "main"]

_LOG = logging.getLogger("alien_scenes")

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

WIDTH = 640
HEIGHT = 480
BASELINE_M = 0.075  # IR projector to IR camera, projector on the camera's +x side
DISPARITY_STEP_PX = 0.125
GROUND_ID = 0
F_PAD = 14  # plane slots per polyhedron
_EPS = 1e-5


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics shared by the registered RGB and depth images (pixels)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @staticmethod
    def sample(rng: np.random.Generator) -> CameraModel:
        """Draw an Xtion-like camera: fx = fy in 560-580 px, centre within 4 px."""
        f = float(rng.uniform(560.0, 580.0))
        return CameraModel(
            WIDTH,
            HEIGHT,
            f,
            f,
            319.5 + float(rng.uniform(-4, 4)),
            239.5 + float(rng.uniform(-4, 4)),
        )

    def to_json(self) -> dict[str, float | int]:
        """The ``camera.json`` record (depth PNG unit: 1 mm)."""
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "depth_unit_m": 0.001,
        }


# --------------------------------------------------------------------------- geometry


def _mm(a: NDArray[Any], b: NDArray[Any] | list[float]) -> NDArray[Any]:
    """``a @ b`` for many small vectors without BLAS (its threads stall on a busy machine)."""
    b = np.asarray(b, dtype=a.dtype if a.dtype == np.float32 else np.float64)
    if b.ndim == 1:
        return cast(NDArray[Any], np.einsum("...j,j->...", a, b))
    return cast(NDArray[Any], np.einsum("...j,jk->...k", a, b))


def _rot(axis: F64 | tuple[float, float, float], angle: float) -> F64:
    """Rotation matrix about ``axis`` by ``angle`` radians (Rodrigues)."""
    x, y, z = (float(v) for v in axis)
    n = math.sqrt(x * x + y * y + z * z)
    x, y, z = x / n, y / n, z / n
    c, s = math.cos(angle), math.sin(angle)
    C = 1 - c
    return np.array(
        [
            [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
        ]
    )


def _pick(rng: np.random.Generator, items: list[str], p: list[float] | None = None) -> str:
    """One of ``items`` (probabilities ``p``, default uniform); faster than Generator.choice."""
    if p is None:
        return items[int(rng.integers(len(items)))]
    u = rng.random() * sum(p)
    for item, w in zip(items, p, strict=True):
        u -= w
        if u < 0:
            return item
    return items[-1]


def _rz(angle: float) -> F64:
    return _rot(np.array([0.0, 0.0, 1.0]), angle)


def _resting_rotation(rng: np.random.Generator, max_tilt_deg: float) -> F64:
    """Random yaw, then a tilt about a random horizontal axis."""
    az = rng.uniform(0, 2 * math.pi)
    tilt = math.radians(rng.uniform(0, max_tilt_deg))
    axis = np.array([math.cos(az), math.sin(az), 0.0])
    return _rot(axis, tilt) @ _rz(rng.uniform(0, 2 * math.pi))


def _perp_basis(a: F64) -> tuple[F64, F64]:
    ref = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(a, ref)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def _powerlaw(rng: np.random.Generator, lo: float, hi: float, alpha: float) -> float:
    """Sample p(s) ~ s^-alpha on [lo, hi]."""
    e = 1.0 - alpha
    u = rng.uniform()
    return float((lo**e + u * (hi**e - lo**e)) ** (1.0 / e))


# --------------------------------------------------------------------------- textures


@dataclass(frozen=True)
class _Textures:
    """Periodic zero-mean unit-variance noise images (float32, S x S)."""

    smooth: F32
    grain: F32


def _fft_noise(rng: np.random.Generator, size: int, beta: float) -> F32:
    white = rng.standard_normal((size, size))
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    f = np.hypot(fx, fy)
    f[0, 0] = 1.0
    amp = f ** (-beta / 2.0)
    amp[0, 0] = 0.0
    tex = np.fft.irfft2(np.fft.rfft2(white) * amp, s=(size, size))
    tex = (tex - tex.mean()) / tex.std()
    out: F32 = tex.astype(np.float32)
    return out


def _make_textures(rng: np.random.Generator) -> _Textures:
    return _Textures(_fft_noise(rng, 512, 2.6), _fft_noise(rng, 512, 1.1))


def _triplanar(tex: F32, P: F32, w3: F32, inv_texel: F32, off: F32) -> F32:
    """Sample a periodic texture on surfaces by world position (triplanar blend).

    P, w3, off: (H, W, 3); inv_texel: (H, W) texels per metre. Returns (H, W).
    """
    size = tex.shape[0]
    q = np.mod(P * inv_texel[..., None] + off, size).astype(np.float32)
    out = np.zeros(P.shape[:2], np.float32)
    for k, (i, j) in enumerate(((1, 2), (0, 2), (0, 1))):
        s = cv2.remap(tex, q[..., i], q[..., j], cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        out += w3[..., k] * s
    return out


# --------------------------------------------------------------------------- shape library


@dataclass(frozen=True)
class _Shape:
    """A convex polyhedron in its unit box: planes n.x <= d (F_PAD, 4), vertices (V, 3)."""

    planes: F64
    verts: F64


def _shape_from_halfspaces(normals: F64, offsets: F64) -> _Shape:
    hs = np.hstack([normals, -offsets[:, None]])
    verts = HalfspaceIntersection(hs, np.zeros(3)).intersections
    return _finish_shape(normals, offsets, verts)


def _finish_shape(normals: F64, offsets: F64, verts: F64) -> _Shape:
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
    return _Shape(planes, verts)


def _make_library(rng: np.random.Generator) -> list[_Shape]:
    """Index 0: box, 1: octagonal prism along x, then cut boxes, then random hulls."""
    shapes: list[_Shape] = []
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


def _instance(shape: _Shape, dims: F64, R: F64, c: F64) -> tuple[F64, F64]:
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


class _Materials:
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
_M_RGB, _M_CON, _M_DISP, _M_IR, _M_TAG, _M_KIND, _M_OFF, _M_SCALE = 0, 3, 4, 5, 6, 7, 8, 11


# --------------------------------------------------------------------------- scene records


@dataclass(frozen=True)
class _Hole:
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
    mask: NDArray[np.uint8]  # opening raster at _HOLE_RES
    mask_x0: float
    mask_y0: float

    def contains(self, xy: F64) -> NDArray[np.bool_]:
        """Which ground points (N, 2) fall in the opening."""
        i = np.floor((xy[:, 1] - self.mask_y0) / _HOLE_RES).astype(np.int64)
        j = np.floor((xy[:, 0] - self.mask_x0) / _HOLE_RES).astype(np.int64)
        h, w = self.mask.shape
        ok = (i >= 0) & (i < h) & (j >= 0) & (j < w)
        out = np.zeros(len(xy), bool)
        out[ok] = self.mask[i[ok], j[ok]] > 0
        return out


_HOLE_RES = 0.01


@dataclass(frozen=True)
class _Tube:
    """A hollow pipe open at its top end: axis up, top centre, radii, bottom axial offset."""

    top: F64
    axis: F64
    r_in: float
    r_out: float
    s_bottom: float
    out_id: int
    in_id: int

    def corners(self) -> F64:
        u, v = _perp_basis(self.axis)
        pts = []
        for s in (0.0, self.s_bottom):
            for a in (-1, 1):
                for b in (-1, 1):
                    pts.append(self.top + s * self.axis + self.r_out * (a * u + b * v))
        return np.array(pts)


@dataclass(frozen=True)
class _Bowl:
    """A shallow ellipsoidal depression centred on the ground plane."""

    centre: F64  # (3,), z = 0
    M: F64  # (3, 3) world -> unit sphere
    ident: int


@dataclass(frozen=True)
class _Stain:
    centre: F64  # (2,)
    axes: F64  # (2,) semi-axes, m
    angle: float
    strength: float
    wet: bool


@dataclass
class _Scene:
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
    tubes: list[_Tube]
    holes: list[_Hole]
    bowls: list[_Bowl]
    stains: list[_Stain]
    mats: F32
    region: tuple[float, float, float, float]
    meta: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- world grid


class _Grid:
    """A 2 cm raster of the site: keep-out (holes), placement region, rubble height."""

    def __init__(self, x0: float, y0: float, x1: float, y1: float, res: float = 0.02) -> None:
        self.x0, self.y0, self.res = x0, y0, res
        self.nx = math.ceil((x1 - x0) / res)
        self.ny = math.ceil((y1 - y0) / res)
        self.keep = np.zeros((self.ny, self.nx), np.uint8)
        self.region = np.zeros((self.ny, self.nx), np.uint8)
        self.hmap = np.zeros((self.ny, self.nx), np.float32)

    def px(self, xy: F64) -> F64:
        return (np.asarray(xy) - [self.x0, self.y0]) / self.res

    def roi_mask(self, xy: F64, convex: bool = True) -> tuple[int, int, int, int, NDArray[Any]]:
        """Rasterise polygon ``xy`` (N, 2); return rows r0:r1, cols c0:c1 and its mask there."""
        p = self.px(xy)
        c0 = max(int(np.floor(p[:, 0].min())) - 1, 0)
        r0 = max(int(np.floor(p[:, 1].min())) - 1, 0)
        c1 = min(int(np.ceil(p[:, 0].max())) + 2, self.nx)
        r1 = min(int(np.ceil(p[:, 1].max())) + 2, self.ny)
        if c1 <= c0 or r1 <= r0:
            return 0, 0, 0, 0, np.zeros((0, 0), np.uint8)
        m = np.zeros((r1 - r0, c1 - c0), np.uint8)
        q = np.round((p - [c0, r0]) * 16).astype(np.int32)
        if convex:
            cv2.fillConvexPoly(m, cv2.convexHull(q), 1, cv2.LINE_8, 4)
        else:
            cv2.fillPoly(m, [q], 1, cv2.LINE_8, 4)
        return r0, r1, c0, c1, m

    def inside(self, xy: F64) -> bool:
        c, r = self.px(xy)
        return 0 <= r < self.ny and 0 <= c < self.nx and bool(self.region[int(r), int(c)])

    def add_keepout(self, xy: F64, margin: float) -> None:
        r0, r1, c0, c1, m = self.roi_mask(xy, convex=False)
        if m.size == 0:
            return
        k = round(margin / self.res)
        if k > 0:
            pad = k + 1
            big = np.zeros((m.shape[0] + 2 * pad, m.shape[1] + 2 * pad), np.uint8)
            big[pad:-pad, pad:-pad] = m
            ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
            big = cv2.dilate(big, ker)
            rr0, cc0 = r0 - pad, c0 - pad
            sr0, sc0 = max(rr0, 0), max(cc0, 0)
            sr1 = min(rr0 + big.shape[0], self.ny)
            sc1 = min(cc0 + big.shape[1], self.nx)
            sub = big[sr0 - rr0 : sr1 - rr0, sc0 - cc0 : sc1 - cc0]
            self.keep[sr0:sr1, sc0:sc1] |= sub.astype(np.uint8)
        else:
            self.keep[r0:r1, c0:c1] |= m

    def overlaps_keepout(self, xy: F64, convex: bool = True) -> bool:
        r0, r1, c0, c1, m = self.roi_mask(xy, convex)
        if m.size == 0:
            return False
        return bool((self.keep[r0:r1, c0:c1] & m).any())


# --------------------------------------------------------------------------- views


class _View:
    """Rays of an image: origins and directions D, (N, 3) float32, t along D."""

    h: int
    w: int
    origin: F32
    D: F32
    o_const: F64 | None
    d_const: F64 | None

    def pix(self, pts: F64) -> tuple[F64, F64, F64]:  # pragma: no cover - abstract
        """Pixel coordinates and depth of points; each view kind defines it."""
        raise TypeError(f"{type(self).__name__} does not define pix()")

    def rects(self, pts: F64) -> tuple[I64, I64, I64, I64]:
        """Pixel rectangles [u0, u1) x [v0, v1) covering each point set (K, V, 3)."""
        u, v, z = self.pix(pts)
        near = 0.05
        zmin, zmax = z.min(1), z.max(1)
        nan = np.isnan(u) | np.isnan(v)
        u0 = np.floor(np.where(nan, np.inf, u).min(1))
        u1 = np.ceil(np.where(nan, -np.inf, u).max(1)) + 1
        v0 = np.floor(np.where(nan, np.inf, v).min(1))
        v1 = np.ceil(np.where(nan, -np.inf, v).max(1)) + 1
        full = zmin < near
        u0 = np.where(full, 0, u0)
        v0 = np.where(full, 0, v0)
        u1 = np.where(full, self.w, u1)
        v1 = np.where(full, self.h, v1)
        behind = zmax < near
        u0c = np.clip(u0, 0, self.w).astype(np.int64)
        u1c = np.clip(u1, 0, self.w).astype(np.int64)
        v0c = np.clip(v0, 0, self.h).astype(np.int64)
        v1c = np.clip(v1, 0, self.h).astype(np.int64)
        u1c = np.where(behind | (u1c < u0c), u0c, u1c)
        v1c = np.where(behind | (v1c < v0c), v0c, v1c)
        return u0c, u1c, v0c, v1c


class _PerspectiveView(_View):
    def __init__(self, cam: CameraModel, C: F64, R: F64) -> None:
        self.h, self.w = cam.height, cam.width
        self.cam, self.C, self.R = cam, C, R
        v, u = np.mgrid[0 : cam.height, 0 : cam.width]
        d = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(u.shape)], -1).reshape(
            -1, 3
        )
        self.D = _mm(d, R.T).astype(np.float32)
        self.origin = np.broadcast_to(C.astype(np.float32), self.D.shape)
        self.o_const, self.d_const = C, None

    def pix(self, pts: F64) -> tuple[F64, F64, F64]:
        X = _mm(pts - self.C, self.R)
        z = X[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            zz = np.where(z > 0.05, z, np.nan)
            return (
                self.cam.fx * X[..., 0] / zz + self.cam.cx,
                self.cam.fy * X[..., 1] / zz + (self.cam.cy),
                z,
            )


class _OrthoView(_View):
    """Parallel rays towards -s (from the sun), pixel (r, c) at base + c*tx*ea + r*tx*eb."""

    LIFT = 60.0

    def __init__(self, s: F64, pts: F64, max_px: int = 512, min_texel: float = 0.01) -> None:
        self.s = s
        self.ea, self.eb = _perp_basis(s)
        a, b = _mm(pts, self.ea), _mm(pts, self.eb)
        ext = max(np.ptp(a), np.ptp(b))
        self.texel = max(ext / max_px, min_texel)
        self.base = (a.min() - 2 * self.texel) * self.ea + (b.min() - 2 * self.texel) * self.eb
        self.w = math.ceil(np.ptp(a) / self.texel) + 5
        self.h = math.ceil(np.ptp(b) / self.texel) + 5
        r, c = np.mgrid[0 : self.h, 0 : self.w]
        orig = (
            self.base
            + (c.reshape(-1, 1) * self.texel) * self.ea
            + (r.reshape(-1, 1) * self.texel) * self.eb
            + self.LIFT * s
        )
        self.origin = orig.astype(np.float32)
        self.D = np.broadcast_to((-s).astype(np.float32), self.origin.shape)
        self.o_const, self.d_const = None, -s

    def pix(self, pts: F64) -> tuple[F64, F64, F64]:
        rel = pts - self.base
        return (
            _mm(rel, self.ea) / self.texel,
            _mm(rel, self.eb) / self.texel,
            np.ones(pts.shape[:-1]),
        )

    def depth_of(self, P: F64) -> F64:
        return self.LIFT - _mm(P - self.base, self.s)


# --------------------------------------------------------------------------- ray casting


@dataclass
class _Buffers:
    t: F32
    ident: NDArray[np.int32]
    n: F32

    @staticmethod
    def empty(n: int) -> _Buffers:
        return _Buffers(
            np.full(n, np.inf, np.float32), np.full(n, -1, np.int32), np.zeros((n, 3), np.float32)
        )

    def merge(self, pix: I64, t: F64, ident: NDArray[Any], normal: F64) -> None:
        """Z-buffer merge of candidate hits (pixels may repeat)."""
        np.minimum.at(self.t, pix, t.astype(np.float32))
        win = t.astype(np.float32) <= self.t[pix]
        self.ident[pix[win]] = ident[win]
        self.n[pix[win]] = normal[win]


def _pairs(u0: I64, u1: I64, v0: I64, v1: I64, sel: I64, width: int) -> tuple[I64, I64]:
    w = (u1 - u0)[sel]
    n = w * (v1 - v0)[sel]
    total = int(n.sum())
    obj = np.repeat(sel, n)
    start = np.repeat(np.cumsum(n) - n, n)
    local = np.arange(total) - start
    ww = np.repeat(w, n)
    u = np.repeat(u0[sel], n) + local % ww
    v = np.repeat(v0[sel], n) + local // ww
    return obj, v * width + u


def _chunks(area: I64, limit: int) -> list[I64]:
    idx = np.flatnonzero(area > 0)
    if len(idx) == 0:
        return []
    cum = np.cumsum(area[idx])
    cut = np.searchsorted(cum, np.arange(limit, cum[-1] + limit, limit), side="left")
    out, lo = [], 0
    for hi in np.unique(np.minimum(cut + 1, len(idx))):
        if hi > lo:
            out.append(idx[lo:hi])
            lo = hi
    return out


_CHUNK = 40_000


def _cover(view: _View, pts: F64) -> list[I64]:
    """Pixels (flat indices) under the projected convex hull of each point set (K, V, 3)."""
    u, v, z = view.pix(pts)
    out: list[I64] = []
    full = np.arange(view.h * view.w)
    empty = np.zeros(0, np.int64)
    for k in range(len(pts)):
        if z[k].max() < 0.05:
            out.append(empty)
            continue
        if z[k].min() < 0.05:
            out.append(full)
            continue
        c0 = max(int(np.floor(u[k].min())) - 1, 0)
        r0 = max(int(np.floor(v[k].min())) - 1, 0)
        c1 = min(int(np.ceil(u[k].max())) + 2, view.w)
        r1 = min(int(np.ceil(v[k].max())) + 2, view.h)
        if c1 <= c0 or r1 <= r0:
            out.append(empty)
            continue
        m = np.zeros((r1 - r0, c1 - c0), np.uint8)
        q = np.round(np.column_stack([u[k] - c0, v[k] - r0]) * 16).astype(np.int32)
        cv2.fillConvexPoly(m, cv2.convexHull(q), 1, cv2.LINE_8, 4)
        rr, cc = np.nonzero(m)
        out.append((rr + r0) * view.w + cc + c0)
    return out


def _cast_polyhedra(view: _View, buf: _Buffers, sc: _Scene) -> None:
    """Ray-cast all polyhedra, nearest first, skipping pairs already hidden."""
    if len(sc.poly_ids) == 0:
        return
    verts = sc.verts.astype(np.float64)
    covers = _cover(view, verts)
    nlive = (sc.planes[..., :3] != 0).any(-1).sum(-1)
    if isinstance(view, _OrthoView):
        near = view.depth_of(verts).min(1)
    else:
        near = view.pix(verts)[2].min(1)
    order = np.argsort(near)
    batch: list[int] = []
    count = 0
    for i, k in enumerate(order):
        batch.append(int(k))
        count += len(covers[k])
        if count >= _CHUNK or i == len(order) - 1:
            sel = np.array(batch)
            obj = np.repeat(sel, [len(covers[j]) for j in sel])
            pix = np.concatenate([covers[j] for j in sel])
            seen = near[obj] < buf.t[pix]
            _poly_batch(view, buf, sc, obj[seen], pix[seen], int(nlive[sel].max()))
            batch, count = [], 0


def _poly_batch(view: _View, buf: _Buffers, sc: _Scene, obj: I64, pix: I64, F: int) -> None:
    """Slab test of rays against convex polyhedra, for (object, pixel) pairs."""
    if len(pix) == 0:
        return
    n = sc.planes[obj, :F, :3]
    if view.d_const is not None:
        den = _mm(n, view.d_const.astype(np.float32))
    else:
        den = np.einsum("pfk,pk->pf", n, view.D[pix])
    if view.o_const is not None:
        num = sc.planes[obj, :F, 3] - _mm(n, view.o_const.astype(np.float32))
    else:
        num = sc.planes[obj, :F, 3] - np.einsum("pfk,pk->pf", n, view.origin[pix])
    # padded planes have n = 0, d = 1: den = 0 and num > 0, so they never bind
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = num / den
    enter = den < 0
    t_all_in = np.where(enter, tt, -np.inf)
    k_in = np.argmax(t_all_in, 1)
    t_in = np.take_along_axis(t_all_in, k_in[:, None], 1)[:, 0]
    tt[enter | (den == 0)] = np.inf
    hit = (t_in < tt.min(1)) & (t_in > 1e-3)
    if hit.any():
        nrm = n[hit, k_in[hit]]
        buf.merge(pix[hit], t_in[hit], sc.poly_ids[obj[hit]], nrm)


def _cast_ellipsoids(view: _View, buf: _Buffers, sc: _Scene) -> None:
    if len(sc.ell_ids) == 0:
        return
    u0, u1, v0, v1 = view.rects(sc.ell_corners.astype(np.float64))
    for sel in _chunks((u1 - u0) * (v1 - v0), _CHUNK):
        obj, pix = _pairs(u0, u1, v0, v1, sel, view.w)
        M = sc.ell_mat[obj]
        o = np.einsum("pij,pj->pi", M, view.origin[pix] - sc.ell_c[obj])
        d = np.einsum("pij,pj->pi", M, view.D[pix])
        A = (d * d).sum(1)
        B = 2 * (o * d).sum(1)
        Cq = (o * o).sum(1) - 1
        disc = B * B - 4 * A * Cq
        hit = disc > 0
        t = (-B - np.sqrt(np.maximum(disc, 0))) / (2 * A)
        hit &= t > 1e-3
        if not hit.any():
            continue
        p = o[hit] + t[hit, None] * d[hit]
        nw = np.einsum("pji,pj->pi", M[hit], p)
        nw /= np.linalg.norm(nw, axis=1)[:, None]
        buf.merge(pix[hit], t[hit], sc.ell_ids[obj[hit]], nw)


def _cast_tube(view: _View, buf: _Buffers, tb: _Tube) -> None:
    u0, u1, v0, v1 = view.rects(tb.corners()[None])
    _obj, pix = _pairs(u0, u1, v0, v1, np.array([0]), view.w)
    if len(pix) == 0:
        return
    a = tb.axis
    rel = view.origin[pix].astype(np.float64) - tb.top
    D = view.D[pix].astype(np.float64)
    Oa, Da = _mm(rel, a), _mm(D, a)
    Op, Dp = rel - Oa[:, None] * a, D - Da[:, None] * a
    A = np.maximum((Dp * Dp).sum(1), 1e-12)
    B = 2 * (Op * Dp).sum(1)
    OO = (Op * Op).sum(1)
    best = np.full(len(pix), np.inf)
    ident = np.full(len(pix), -1, np.int32)
    normal = np.zeros((len(pix), 3))

    def axial_ok(t: F64) -> NDArray[np.bool_]:
        s = Oa + t * Da
        ok: NDArray[np.bool_] = (s <= 0) & (s >= tb.s_bottom) & (t > 1e-3)
        return ok

    for r, sign, ident_k in ((tb.r_out, -1, tb.out_id), (tb.r_in, +1, tb.in_id)):
        disc = B * B - 4 * A * (OO - r * r)
        t = (-B + sign * np.sqrt(np.maximum(disc, 0))) / (2 * A)
        ok = (disc > 0) & axial_ok(t) & (t < best)
        best[ok] = t[ok]
        ident[ok] = ident_k
        radial = Op[ok] + t[ok, None] * Dp[ok]
        normal[ok] = -sign * radial / r
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = -Oa / Da
    rc = ((Op + tc[:, None] * Dp) ** 2).sum(1)
    ok = (tc > 1e-3) & (rc >= tb.r_in**2) & (rc <= tb.r_out**2) & (tc < best)
    best[ok] = tc[ok]
    ident[ok] = tb.out_id
    normal[ok] = a
    hit = np.isfinite(best)
    if hit.any():
        buf.merge(pix[hit], best[hit], ident[hit], normal[hit])


def _shaft_hit(hole: _Hole, D: F64, t0: F64, Pxy: F64) -> tuple[F64, F64, NDArray[np.int32]]:
    """Continue rays that crossed the ground inside ``hole``'s opening down its shaft."""
    a = hole.axis_down
    kx, ky = a[0] / a[2], a[1] / a[2]
    Dz = np.minimum(D[:, 2], -1e-9)
    Dx = D[:, 0] - kx * D[:, 2]
    Dy = D[:, 1] - ky * D[:, 2]
    s_floor = -hole.depth / Dz
    A = hole.poly
    E = np.roll(A, -1, axis=0) - A
    den = Dx[:, None] * E[None, :, 1] - Dy[:, None] * E[None, :, 0]
    wx = A[None, :, 0] - Pxy[:, 0, None]
    wy = A[None, :, 1] - Pxy[:, 1, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (wx * E[None, :, 1] - wy * E[None, :, 0]) / den
        mu = (wx * Dy[:, None] - wy * Dx[:, None]) / den
    ok = (np.abs(den) > 1e-12) & (s > 1e-6) & (mu >= -1e-6) & (mu <= 1 + 1e-6)
    s = np.where(ok, s, np.inf)
    k = np.argmin(s, 1)
    s_exit = s[np.arange(len(k)), k]
    wall = s_exit < s_floor
    s_hit = np.where(wall, s_exit, s_floor)
    e3 = np.column_stack([E[k], np.zeros(len(k))])
    nw = np.cross(e3, a)
    nw /= np.maximum(np.linalg.norm(nw, axis=1), 1e-12)[:, None]
    nw *= -np.sign((nw * D).sum(1))[:, None]
    normal = np.where(wall[:, None], nw, np.array([0.0, 0.0, 1.0]))
    ident = np.where(wall, hole.wall_id, hole.floor_id).astype(np.int32)
    return t0 + s_hit, normal, ident


def _cast_ground(view: _View, buf: _Buffers, sc: _Scene) -> None:
    D = view.D
    Oz = view.origin[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(D[:, 2] < -1e-9, -Oz / D[:, 2], np.inf)
    idx = np.flatnonzero(np.isfinite(t) & (t > 0))
    tt = t[idx].astype(np.float64)
    P = view.origin[idx].astype(np.float64) + tt[:, None] * D[idx]
    buf.t[idx] = tt
    buf.ident[idx] = GROUND_ID
    buf.n[idx] = (0.0, 0.0, 1.0)
    Pxy = P[:, :2]
    for hole in sc.holes:
        inside = hole.contains(Pxy)
        if not inside.any():
            continue
        ii = idx[inside]
        th, nh, ih = _shaft_hit(hole, D[ii].astype(np.float64), tt[inside], Pxy[inside])
        buf.t[ii], buf.n[ii], buf.ident[ii] = th, nh, ih
    for bowl in sc.bowls:
        q = _mm(P - bowl.centre, bowl.M.T)
        inside = (q[:, 0] ** 2 + q[:, 1] ** 2) < 1.0
        if not inside.any():
            continue
        ii = idx[inside]
        o = _mm(view.origin[ii].astype(np.float64) - bowl.centre, bowl.M.T)
        d = _mm(D[ii].astype(np.float64), bowl.M.T)
        A = (d * d).sum(1)
        B = 2 * (o * d).sum(1)
        Cq = (o * o).sum(1) - 1
        tb = (-B + np.sqrt(np.maximum(B * B - 4 * A * Cq, 0))) / (2 * A)
        p = o + tb[:, None] * d
        nw = -_mm(p, bowl.M)
        nw /= np.linalg.norm(nw, axis=1)[:, None]
        buf.t[ii], buf.n[ii], buf.ident[ii] = tb, nw, bowl.ident


def _render(view: _View, sc: _Scene) -> _Buffers:
    buf = _Buffers.empty(view.h * view.w)
    _cast_ground(view, buf, sc)
    _cast_polyhedra(view, buf, sc)
    _cast_ellipsoids(view, buf, sc)
    for tb in sc.tubes:
        _cast_tube(view, buf, tb)
    return buf


# --------------------------------------------------------------------------- scene sampling

_LIB_BOX, _LIB_PRISM, _LIB_CUT0, _LIB_HULL0 = 0, 1, 2, 34


def _camera_rotation(up: F64, tilt: float, yaw: float, roll: float) -> F64:
    """World-from-camera rotation: tilt from nadir, yaw about gravity, roll about the axis."""
    x, _ = _perp_basis(up)
    x = _rot(up, yaw) @ x
    z = -up
    y = np.cross(z, x)
    rt = _rot(x, tilt)
    z2, y2 = rt @ z, rt @ y
    rr = _rot(z2, roll)
    return np.column_stack([rr @ x, rr @ y2, z2])


def _ground_point(cam: CameraModel, C: F64, R: F64, u: float, v: float) -> F64 | None:
    d = R @ np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
    if d[2] > -0.05:
        return None
    p: F64 = C + (-C[2] / d[2]) * d
    return p


def _footprint(cam: CameraModel, C: F64, R: F64) -> F64:
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
        p = _ground_point(cam, C, R, u, v)
        if p is None:  # ray towards the horizon: stop it 12 m away
            d = R @ np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
            d[2] = 0
            p = C + 12 * d / np.linalg.norm(d)
        pts.append(p[:2])
    return np.array(pts)


def _poly_dims(poly: F64, axis: F64) -> tuple[float, float, float]:
    """Long and short side of the min-area rectangle and inscribed-circle diameter (m) of
    an opening ``poly`` in z = 0, measured across the shaft ``axis``."""
    u, v = _perp_basis(axis)
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


def _polygon_area(p: F64) -> float:
    x, y = p[:, 0], p[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


class _Builder:
    """Accumulates the solids, holes and surfaces of one scene."""

    def __init__(self, rng: np.random.Generator, cam: CameraModel, lib: list[_Shape]) -> None:
        self.rng, self.cam, self.lib = rng, cam, lib
        self.mats = _Materials(rng)
        self.mats.add(_pick(rng, ["dirt", "stone", "concrete"]), KIND_GROUND)
        self.planes: list[F64] = []
        self.verts: list[F64] = []
        self.pids: list[int] = []
        self.ell: list[tuple[F64, F64, F64, int]] = []
        self.tubes: list[_Tube] = []
        self.holes: list[_Hole] = []
        self.bowls: list[_Bowl] = []
        self.stains: list[_Stain] = []
        self.kinds: dict[str, int] = {}
        self.cells: I64 | None = None
        self.pile_cap = float(rng.uniform(0.3, 0.8))  # rubble stops piling above this, m
        self.grid: _Grid
        self.C: F64
        self.R: F64
        self.foot: F64

    # ---------------------------------------------------------------- helpers
    def count(self, kind: str) -> None:
        self.kinds[kind] = self.kinds.get(kind, 0) + 1

    def sample_view_point(self, interior: bool) -> F64 | None:
        r, w, h = self.rng, self.cam.width, self.cam.height
        if interior:
            u, v = r.uniform(0.12 * w, 0.88 * w), r.uniform(0.12 * h, 0.88 * h)
        else:
            u, v = r.uniform(-0.15 * w, 1.15 * w), r.uniform(-0.15 * h, 1.15 * h)
        p = _ground_point(self.cam, self.C, self.R, u, v)
        return None if p is None else p[:2]

    def add_poly(self, shape: int, dims: F64, R: F64, c: F64, mat: int) -> F64:
        planes, verts = _instance(self.lib[shape], dims, R, c)
        self.planes.append(planes)
        self.verts.append(verts)
        self.pids.append(mat)
        return verts

    def add_resting(
        self,
        shape: int,
        dims: F64,
        R: F64,
        xy: F64,
        mat_name: str,
        embed: float,
        check_keep: bool = True,
    ) -> bool:
        """Drop a solid at ``xy`` onto the rubble height map, partly embedded."""
        v = (self.lib[shape].verts * dims) @ R.T
        foot = v[:, :2] + xy
        g = self.grid
        r0, r1, c0, c1, m = g.roi_mask(foot)
        if m.size == 0 or not m.any():
            return False
        if check_keep and (g.keep[r0:r1, c0:c1] & m).any():
            return False
        hroi = g.hmap[r0:r1, c0:c1]
        base = float(hroi[m > 0].max())
        if base > self.pile_cap:
            return False
        zmin, zmax = v[:, 2].min(), v[:, 2].max()
        height = zmax - zmin
        bottom = base * self.rng.uniform(0.4, 0.9) - embed * height
        c = np.array([xy[0], xy[1], bottom - zmin])
        self.add_poly(shape, dims, R, c, self.mats.add(mat_name, KIND_RUBBLE))
        np.maximum(hroi, np.where(m > 0, bottom + 0.85 * height, 0), out=hroi)
        return True

    # ---------------------------------------------------------------- openings
    def opening_polygon(self, kind: str) -> F64:
        """An opening outline centred at the origin (K, 2), counter-clockwise."""
        r = self.rng
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
            c = np.vstack(
                [[0, 0], np.cumsum(step * np.column_stack([np.cos(head), np.sin(head)]), 0)]
            )
            c -= c.mean(0)
            tang = np.gradient(c, axis=0)
            nrm = np.column_stack([-tang[:, 1], tang[:, 0]])
            nrm /= np.linalg.norm(nrm, axis=1)[:, None]
            s = np.linspace(0, 1, n)
            wid = r.uniform(0.03, 0.11) * (np.sin(math.pi * (0.05 + 0.9 * s)) ** 0.6)
            wid *= r.uniform(0.7, 1.3, n)
            p = np.vstack([c + nrm * wid[:, None] / 2, (c - nrm * wid[:, None] / 2)[::-1]])
            lo = hi = 0.0
        p = p @ _rz(r.uniform(0, 2 * math.pi))[:2, :2].T
        if hi > 0:
            (_, _), (a, b), _ = cv2.minAreaRect(p.astype(np.float32))
            p *= r.uniform(lo, hi) / max(a, b)
        signed = np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1))
        if signed < 0:
            p = p[::-1]
        return np.asarray(p, float)

    def hole_mask(self, poly: F64) -> tuple[NDArray[np.uint8], float, float]:
        x0, y0 = poly.min(0) - 0.02
        size = np.ceil((poly.max(0) + 0.02 - (x0, y0)) / _HOLE_RES).astype(int) + 1
        m = np.zeros((size[1], size[0]), np.uint8)
        q = np.round((poly - (x0, y0)) / _HOLE_RES * 16).astype(np.int32)
        cv2.fillPoly(m, [q], 1, cv2.LINE_8, 4)
        return m, float(x0), float(y0)

    def edge_slab(self, A: F64, B: F64, poly: F64, ext: tuple[float, float]) -> F64 | None:
        """A slab whose inner face follows edge A->B of ``poly``, lying outside it.

        Returns the slab's inner top edge (2, 3) at A and B, or None if it did not fit.
        """
        r = self.rng
        L = float(np.linalg.norm(B - A))
        x = np.append((B - A) / L, 0.0)
        y = np.array([x[1], -x[0], 0.0])  # outward for a counter-clockwise polygon
        z = np.array([0.0, 0.0, 1.0])
        T, Ws, sink = r.uniform(0.1, 0.3), r.uniform(0.6, 1.8), r.uniform(0.03, 0.1)
        Rt = _rot(x, math.radians(r.uniform(-10, 8))) @ _rot(y, math.radians(r.uniform(-5, 5)))
        Re = np.column_stack([x, y, z]) @ Rt
        dims = np.array([L + ext[0] + ext[1], Ws, T + sink])
        centre_l = np.array([(L + ext[1] - ext[0]) / 2, Ws / 2, (T - sink) / 2])
        A3 = np.append(A, 0.0)
        c = A3 + Re @ centre_l
        corners = (self.lib[_LIB_BOX].verts * dims) @ Re.T + c
        # the slab must not cover the opening (beyond a few cm) nor other holes
        hull = cv2.convexHull(corners[:, :2].astype(np.float32))
        span = np.linspace(0.08, 0.92, 6)
        inner = [A + t * (B - A) + (s - 0.02) * y[:2] for t in span for s in np.linspace(0, Ws, 4)]
        contour = poly.astype(np.float32).reshape(-1, 1, 2)
        if any(
            cv2.pointPolygonTest(contour, (float(p[0]), float(p[1])), True) > 0.04 for p in inner
        ):
            return None
        if self.grid.overlaps_keepout(hull.reshape(-1, 2).astype(float)):
            return None
        self.add_poly(_LIB_BOX, dims, Re, c, self.mats.add("concrete", KIND_RUBBLE))
        self.grid.add_keepout(hull.reshape(-1, 2).astype(float), 0.0)  # no later hole under it
        r0, r1, c0, c1, m = self.grid.roi_mask(corners[:, :2])
        if m.size:
            hroi = self.grid.hmap[r0:r1, c0:c1]
            np.maximum(hroi, np.where(m > 0, corners[:, 2].max() * 0.9, 0), out=hroi)
        return np.array([A3 + Re @ (0.0, 0.0, T), A3 + Re @ (L, 0.0, T)])

    def shaft_depth(self, access: bool) -> float:
        r = self.rng
        if r.uniform() < (0.35 if access else 0.25):
            return 12.0  # no floor within the sensor's reach
        return float(r.uniform(1.0, 2.8) if access else r.uniform(0.3, 2.0))

    def in_view(self, pts: F64, margin_px: float = 8.0) -> bool:
        """Whether 3-D points (N, 3) all project inside the image, ``margin_px`` from its edges."""
        X = _mm(pts - self.C, self.R)
        if (X[:, 2] < 0.1).any():
            return False
        u = self.cam.fx * X[:, 0] / X[:, 2] + self.cam.cx
        v = self.cam.fy * X[:, 1] / X[:, 2] + self.cam.cy
        m = margin_px
        return bool(
            (u.min() > m) & (v.min() > m) & (u.max() < self.cam.width - m)
            & (v.max() < self.cam.height - m)
        )  # fmt: skip

    def add_prism_hole(self, kind: str, centre: F64, access: bool, whole: bool = False) -> bool:
        r = self.rng
        max_tilt = {"crack": 15.0, "small": 30.0}.get(kind, 35.0)
        tilt = math.radians(r.uniform(0, 5) if r.uniform() < 0.5 else r.uniform(5, max_tilt))
        az = r.uniform(0, 2 * math.pi)
        a = -np.array(
            [math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), math.cos(tilt)]
        )
        poly = self.opening_polygon(kind)
        L, S, ins = _poly_dims(poly, a)
        if access and not (0.7 <= L <= 1.6 and S >= 0.45 and ins >= 0.42):
            return False
        if kind == "small" and L >= 0.3:
            return False
        poly = poly + centre
        if whole:
            p3 = np.column_stack([poly, np.zeros(len(poly))])
            if not self.in_view(np.vstack([p3, p3 + np.array([0.0, 0.0, 0.3])])):
                return False
        margin = r.uniform(0.03, 0.15) if access else r.uniform(0.0, 0.05)
        if self.grid.overlaps_keepout(poly, convex=False) or not self.grid.inside(centre):
            return False
        tag = len(self.holes)
        depth = self.shaft_depth(access)
        # rim: bare ground, or slabs along some edges ("gap": along both long sides)
        K = len(poly)
        lined = np.zeros(K, bool)
        if kind == "gap":
            lined[[0, 2]] = True
        elif kind in ("irregular", "rect") and r.uniform() < 0.5:
            lined = r.uniform(size=K) < 0.6
        rim: list[F64] = []
        for i in range(K):
            A, B = poly[i], poly[(i + 1) % K]
            top = None
            if lined[i] and np.linalg.norm(B - A) > 0.15:
                ext = (r.uniform(0, 0.5), r.uniform(0, 0.5)) if kind == "gap" else (0.0, 0.0)
                top = self.edge_slab(A, B, poly, ext)
            rim.extend(top if top is not None else [np.append(A, 0.0), np.append(B, 0.0)])
        self.grid.add_keepout(poly, margin)
        wall_mat = "concrete" if kind in ("rect", "gap") else _pick(r, ["dirt", "stone"])
        wall_id = self.mats.add(wall_mat, KIND_WALL, tag, disp=r.uniform(0.01, 0.03))
        floor_id = self.mats.add("dirt", KIND_FLOOR, tag, disp=r.uniform(0.02, 0.05))
        self.finish_hole(kind, access, poly, a, depth, np.array(rim), tag, wall_id, floor_id)
        return True

    def finish_hole(
        self,
        kind: str,
        access: bool,
        poly: F64,
        a: F64,
        depth: float,
        rim: F64,
        tag: int,
        wall_id: int,
        floor_id: int,
    ) -> None:
        m, x0, y0 = self.hole_mask(poly)
        u, v = _perp_basis(a)
        p3 = np.column_stack([poly, np.zeros(len(poly))])
        r_eff = math.sqrt(_polygon_area(np.column_stack([p3 @ u, p3 @ v])) / math.pi)
        hole = _Hole(kind, access, poly, a, depth, rim, tag, wall_id, floor_id, r_eff, m, x0, y0)
        self.holes.append(hole)
        self.count(kind if not access else f"access_{kind}")
        if depth < 3.0 and r_eff > 0.2:  # debris on a visible floor
            kx, ky = a[0] / a[2], a[1] / a[2]
            lo, hi = poly.min(0), poly.max(0)
            for _ in range(int(self.rng.integers(0, 6))):
                p = self.rng.uniform(lo, hi)
                if not hole.contains(p[None])[0]:
                    continue
                s = self.rng.uniform(0.08, 0.35)
                dims = s * np.array([1, self.rng.uniform(0.5, 1), self.rng.uniform(0.3, 0.7)])
                z = -depth + dims[2] * 0.25
                c = np.array([p[0] + kx * z, p[1] + ky * z, z])
                shape = int(self.rng.integers(_LIB_HULL0, len(self.lib)))
                mat = self.mats.add(_pick(self.rng, ["concrete", "stone", "brick"]), 1, tag)
                self.add_poly(shape, dims, _resting_rotation(self.rng, 30), c, mat)

    def add_pipe(self, centre: F64, access: bool, whole: bool = False) -> bool:
        r = self.rng
        if access:
            r_in, wall = r.uniform(0.36, 0.62), r.uniform(0.05, 0.12)
            tilt = r.uniform(0, 12) if r.uniform() < 0.5 else r.uniform(15, 35)
            mat = _pick(r, ["concrete", "concrete", "rust"])
        else:
            r_in, wall = r.uniform(0.04, 0.14), r.uniform(0.006, 0.03)
            tilt = r.uniform(20, 75)
            mat = _pick(r, ["pvc", "rust", "concrete", "metal"])
        r_out = r_in + wall
        t, az = math.radians(tilt), r.uniform(0, 2 * math.pi)
        a = np.array([math.sin(t) * math.cos(az), math.sin(t) * math.sin(az), math.cos(t)])
        u, v = _perp_basis(a)
        h_c = r_out * math.sin(t) + r.uniform(0.04, 0.25 if access else 0.2)
        top = np.array([centre[0], centre[1], h_c])
        phi = np.linspace(0, 2 * math.pi, 48, endpoint=False)
        ring = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v

        def at_ground(rad: float) -> F64:
            p = top + rad * ring
            q: F64 = (p - (p[:, 2] / a[2])[:, None] * a)[:, :2]
            return q

        inner_ground = at_ground(r_in)
        foot = np.vstack([(top + r_out * ring)[:, :2], at_ground(r_out)])
        if self.grid.overlaps_keepout(foot) or not self.grid.inside(centre):
            return False
        if whole and not self.in_view(top + r_in * ring):
            return False
        tag = len(self.holes)
        s_b = (-h_c - r_out * math.hypot(u[2], v[2])) / a[2] - 0.3
        out_id = self.mats.add(mat, KIND_PIPE_OUT)
        in_id = self.mats.add(mat, KIND_PIPE_IN, tag)
        self.tubes.append(_Tube(top, a, r_in, r_out, s_b, out_id, in_id))
        hull = cv2.convexHull(foot.astype(np.float32)).reshape(-1, 2).astype(float)
        self.grid.add_keepout(hull, r.uniform(0.02, 0.1))
        for gp in (hull,):
            r0, r1, c0, c1, m = self.grid.roi_mask(gp)
            if m.size:
                hroi = self.grid.hmap[r0:r1, c0:c1]
                np.maximum(hroi, np.where(m > 0, r.uniform(0.0, 0.6) * h_c, 0), out=hroi)
        wall_id = self.mats.add(mat, KIND_WALL, tag, disp=0.004)
        floor_id = self.mats.add("dirt", KIND_FLOOR, tag, disp=r.uniform(0.02, 0.05))
        rim = top + r_in * ring
        self.finish_hole("pipe", access, inner_ground, -a, self.shaft_depth(access), rim, tag,
                         wall_id, floor_id)  # fmt: skip
        return True

    def add_bowl(self, centre: F64) -> bool:
        r = self.rng
        a = r.uniform(0.3, 1.0)
        b, d = a * r.uniform(0.5, 1.0), r.uniform(0.06, 0.25)
        th = r.uniform(0, math.pi)
        phi = np.linspace(0, 2 * math.pi, 32, endpoint=False)
        ell = np.column_stack([a * np.cos(phi), b * np.sin(phi)]) @ _rz(th)[:2, :2].T + centre
        if self.grid.overlaps_keepout(ell) or not self.grid.inside(centre):
            return False
        # no keep-out: rubble may settle into the bowl (holes are all placed already)
        M = np.diag([1 / a, 1 / b, 1 / d]) @ _rz(th).T
        r0, r1, c0, c1, m = self.grid.roi_mask(ell)
        if m.size:
            g = self.grid
            yy, xx = np.mgrid[r0:r1, c0:c1]
            pts = np.column_stack([xx.ravel(), yy.ravel()]) * g.res + (g.x0, g.y0) - centre
            q = _mm(pts, _rz(th)[:2, :2]) / (a, b)
            bowl = -d * np.sqrt(np.clip(1 - (q**2).sum(1), 0, 1)).reshape(m.shape)
            hroi = g.hmap[r0:r1, c0:c1]
            np.minimum(hroi, bowl, out=hroi)
        ident = self.mats.add("dirt", KIND_BOWL, disp=0.01)
        self.bowls.append(_Bowl(np.append(centre, 0.0), M, ident))
        self.count("depression")
        return True

    def add_mound(self, xy: F64) -> bool:
        r = self.rng
        ax = np.array([r.uniform(0.8, 2.2), r.uniform(0.6, 1.8), r.uniform(0.2, 0.6)])
        z0 = -ax[2] * r.uniform(0.2, 0.7)
        k = math.sqrt(1 - (z0 / ax[2]) ** 2)
        th = r.uniform(0, math.pi)
        Rm = _rz(th)
        phi = np.linspace(0, 2 * math.pi, 32, endpoint=False)
        ell = np.column_stack([ax[0] * k * np.cos(phi), ax[1] * k * np.sin(phi)])
        ell = ell @ Rm[:2, :2].T + xy
        if self.grid.overlaps_keepout(ell):
            return False
        c = np.array([xy[0], xy[1], z0])
        M = np.diag(1 / ax) @ Rm.T
        corners = np.array([[i, j, kk] for i in (-1, 1) for j in (-1, 1) for kk in (-1, 1)])
        corners = (corners * ax) @ Rm.T + c
        self.ell.append((c, M, corners, self.mats.add("dirt", KIND_RUBBLE, disp=0.012)))
        r0, r1, c0, c1, m = self.grid.roi_mask(ell)
        if m.size:
            yy, xx = np.mgrid[r0:r1, c0:c1]
            pts = np.column_stack([xx.ravel(), yy.ravel()]) * self.grid.res + (
                self.grid.x0,
                self.grid.y0,
            )
            q = _mm(pts - xy, Rm[:2, :2]) / ax[:2]
            dome = z0 + ax[2] * np.sqrt(np.clip(1 - (q**2).sum(1), 0, 1))
            hroi = self.grid.hmap[r0:r1, c0:c1]
            np.maximum(hroi, dome.reshape(hroi.shape) * (m > 0), out=hroi)
        self.count("mound")
        return True

    # ---------------------------------------------------------------- rubble
    def rubble_piece(self) -> tuple[int, F64, F64, str, float]:
        r = self.rng
        k = _pick(
            r,
            ["chunk", "cut", "brick", "block", "plank", "beam", "rebar", "sheet", "pole"],
            [0.52, 0.2, 0.12, 0.04, 0.04, 0.015, 0.03, 0.02, 0.015],
        )
        if k == "chunk":
            s = _powerlaw(r, 0.08, 0.9, 1.9)
            dims = s * np.array([1, r.uniform(0.55, 1), r.uniform(0.4, 0.85)])
            mat = _pick(r, ["concrete", "brick", "stone", "dark"], [0.68, 0.12, 0.15, 0.05])
            return (
                int(r.integers(_LIB_HULL0, len(self.lib))),
                dims,
                _resting_rotation(r, 35),
                mat,
                r.uniform(0, 0.4),
            )
        if k == "cut":
            s = _powerlaw(r, 0.1, 0.9, 2.0)
            dims = s * np.array([1, r.uniform(0.5, 0.95), r.uniform(0.3, 0.7)])
            return (
                int(r.integers(_LIB_CUT0, _LIB_HULL0)),
                dims,
                _resting_rotation(r, 20),
                "concrete",
                r.uniform(0, 0.3),
            )
        if k == "brick":
            dims = np.array([0.215, 0.1025, 0.065]) * r.uniform(0.95, 1.05)
            if r.uniform() < 0.3:
                dims[0] *= r.uniform(0.4, 0.8)
            return _LIB_BOX, dims, _resting_rotation(r, 40), "brick", r.uniform(0, 0.3)
        if k == "block":
            dims = np.array([0.39, 0.19, 0.19]) * r.uniform(0.9, 1.1)
            return _LIB_BOX, dims, _resting_rotation(r, 25), "concrete", r.uniform(0, 0.3)
        if k == "plank":
            dims = np.array([r.uniform(0.4, 2.5), r.uniform(0.06, 0.25), r.uniform(0.02, 0.06)])
            return _LIB_BOX, dims, _resting_rotation(r, 20), "wood", r.uniform(0, 0.2)
        if k == "beam":
            dims = np.array([r.uniform(1, 3), r.uniform(0.1, 0.25), r.uniform(0.1, 0.25)])
            return (
                _LIB_BOX,
                dims,
                _resting_rotation(r, 12),
                _pick(r, ["wood", "concrete"]),
                r.uniform(0, 0.3),
            )
        if k == "rebar":
            d = r.uniform(0.01, 0.03)
            dims = np.array([r.uniform(0.4, 2.0), d, d])
            return _LIB_PRISM, dims, _resting_rotation(r, 25), "rust", 0.0
        if k == "sheet":
            dims = np.array([r.uniform(0.3, 1.2), r.uniform(0.3, 1.0), r.uniform(0.005, 0.02)])
            return (
                _LIB_BOX,
                dims,
                _resting_rotation(r, 25),
                _pick(r, ["metal", "drywall", "tarp"]),
                0.0,
            )
        d = r.uniform(0.06, 0.2)
        dims = np.array([r.uniform(0.5, 2.5), d, d])
        return (
            _LIB_PRISM,
            dims,
            _resting_rotation(r, 12),
            _pick(r, ["wood", "concrete"]),
            r.uniform(0, 0.3),
        )

    def random_region_point(self) -> F64:
        g = self.grid
        if self.cells is None:
            self.cells = np.flatnonzero(g.region)
        k = int(self.cells[int(self.rng.integers(len(self.cells)))])
        r, c = divmod(k, g.nx)
        return np.array(
            [g.x0 + (c + self.rng.random()) * g.res, g.y0 + (r + self.rng.random()) * g.res]
        )


def _sample_scene(rng: np.random.Generator, cam: CameraModel, lib: list[_Shape]) -> _Scene:
    """Draw one scene: site, camera pose, light, holes, distractors and rubble."""
    b = _Builder(rng, cam, lib)
    slope, saz = math.radians(rng.uniform(0, 10)), rng.uniform(0, 2 * math.pi)
    up = np.array(
        [math.sin(slope) * math.cos(saz), math.sin(slope) * math.sin(saz), math.cos(slope)]
    )
    height = rng.uniform(2.0, 3.5)  # camera height above the rubble surface, m
    tilt = rng.uniform(0, 20)
    R = _camera_rotation(
        up, math.radians(tilt), rng.uniform(0, 2 * math.pi), math.radians(rng.normal(0, 1.5))
    )
    z_axis = R[:, 2]
    C = (height + 0.3) * up[2] / z_axis[2] * z_axis
    b.C, b.R = C, R
    foot = _footprint(cam, C, R)
    b.foot = foot
    # light: a low dawn sun (or none yet) and a bluish sky
    sun: F64 | None = None
    sun_h = np.zeros(2)
    elev = -3.0
    hx, _ = _perp_basis(up)
    h = _rot(up, rng.uniform(0, 2 * math.pi)) @ hx
    glow = h
    if rng.uniform() > 0.25:
        elev = rng.uniform(3, 28)
        e = math.radians(elev)
        sun = math.cos(e) * h + math.sin(e) * up
        sun_h = h[:2] / np.linalg.norm(h[:2])
    margin = 0.9
    pts = [foot]
    if sun is not None:
        pts.append(foot + sun_h * min(3.0, 1.2 / math.tan(math.radians(elev))))
    allp = np.vstack(pts)
    lo, hi = allp.min(0) - margin - 0.2, allp.max(0) + margin + 0.2
    g = _Grid(lo[0], lo[1], hi[0], hi[1])
    b.grid = g
    fm = np.zeros((g.ny, g.nx), np.uint8)
    cv2.fillPoly(fm, [np.round(g.px(foot) * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    dist = cv2.distanceTransform(1 - fm, cv2.DIST_L2, 5)
    g.region[:] = dist * g.res <= margin
    # access holes, then distractors
    n_access = int(rng.choice(4, p=[0.12, 0.45, 0.29, 0.14]))
    for _ in range(n_access):
        kind = _pick(rng, ["irregular", "gap", "pipe", "rect"], [0.4, 0.25, 0.2, 0.15])
        whole = rng.uniform() < 0.8  # else anywhere, often cut by the image border
        for _try in range(60):
            c = b.sample_view_point(interior=whole)
            if c is None:
                continue
            if kind == "pipe":
                ok = b.add_pipe(c, True, whole)
            else:
                ok = b.add_prism_hole(kind, c, True, whole)
            if ok:
                break
    for kind, lam in (("small", 1.4), ("crack", 1.0), ("small_pipe", 0.5), ("bowl", 1.2)):
        for _ in range(int(rng.poisson(lam))):
            for _try in range(20):
                c = b.sample_view_point(interior=False)
                if c is None:
                    continue
                if kind == "small_pipe":
                    ok = b.add_pipe(c, False)
                elif kind == "bowl":
                    ok = b.add_bowl(c)
                else:
                    ok = b.add_prism_hole(kind, c, False)
                if ok:
                    break
    for _ in range(int(rng.poisson(1.5))):
        c = b.sample_view_point(interior=False)
        if c is not None:
            ax = rng.uniform(0.15, 0.7) * np.array([1, rng.uniform(0.4, 1)])
            b.stains.append(
                _Stain(c, ax, rng.uniform(0, math.pi), rng.uniform(0.35, 0.8), rng.uniform() < 0.3)
            )
            b.count("stain")
    # big pieces: mounds, slabs, shadow-casting walls beyond the view
    for _ in range(int(rng.integers(0, 4))):
        b.add_mound(b.random_region_point())
    for _ in range(int(rng.integers(0, 5))):
        dims = np.array([rng.uniform(1, 2.8), rng.uniform(0.8, 2.2), rng.uniform(0.1, 0.3)])
        for _try in range(10):
            if b.add_resting(
                _LIB_BOX, dims, _resting_rotation(rng, 18), b.random_region_point(), "concrete", 0.2
            ):
                b.count("slab")
                break
    if sun is not None:
        contour = foot.astype(np.float32).reshape(-1, 1, 2)
        centre = foot.mean(0)
        for _ in range(int(rng.integers(0, 3))):
            p = centre.copy()
            while cv2.pointPolygonTest(contour, (float(p[0]), float(p[1])), False) > 0:
                p += sun_h * 0.1
            p += sun_h * rng.uniform(0.2, 1.0) + np.array([-sun_h[1], sun_h[0]]) * rng.uniform(
                -2, 2
            )
            dims = np.array([rng.uniform(1.5, 3.5), rng.uniform(0.15, 0.3), rng.uniform(0.6, 1.6)])
            yaw = math.atan2(sun_h[1], sun_h[0]) + math.pi / 2 + rng.normal(0, 0.5)
            if b.add_resting(_LIB_BOX, dims, _rz(yaw), p, _pick(rng, ["concrete", "brick"]), 0.1):
                b.count("wall")
    # rubble until the region is covered about `coverage` times
    area = float(g.region.sum()) * g.res**2
    target = rng.uniform(1.1, 2.0) * area
    acc, tries = 0.0, 0
    while acc < target and tries < 3500 and len(b.pids) < 1800:
        tries += 1
        xy = b.random_region_point()
        c, r = g.px(xy).astype(int)
        if g.hmap[r, c] > b.pile_cap or g.keep[r, c]:
            continue
        shape, dims, Rr, mat, embed = b.rubble_piece()
        if b.add_resting(shape, dims, Rr, xy, mat, embed):
            acc += float(dims[0] * dims[1]) * 0.8
    # camera height is measured above the rubble surface under the view
    med = float(np.median(g.hmap[fm > 0])) if fm.any() else 0.0
    C = C + (med - 0.3) * up
    meta = {
        "camera_height_m": round(float(height), 3),
        "tilt_deg": round(float(tilt), 2),
        "slope_deg": round(math.degrees(slope), 2),
        "sun_elevation_deg": round(float(elev), 2),
        "rubble_median_m": round(med, 3),
        "n_solids": len(b.pids) + len(b.ell) + len(b.tubes),
        "contents": dict(sorted(b.kinds.items())),
    }
    e_sun = 0.0 if sun is None else rng.uniform(2.0, 5.0) * min(1.0, 0.4 + elev / 20)
    warm = 1 - min(elev, 25) / 25 if sun is not None else 0.0
    sun_rgb = np.array([1.0, 0.86 - 0.3 * warm, 0.72 - 0.45 * warm])
    sky_rgb = np.array([0.78, 0.84, 1.1]) if sun is not None else np.array([0.9, 0.8, 1.1])
    sky_rgb = sky_rgb * (1 + rng.normal(0, 0.05, 3))
    planes = np.array(b.planes, np.float32).reshape(-1, F_PAD, 4)
    vmax = max((len(v) for v in b.verts), default=1)
    verts = np.zeros((len(b.verts), vmax, 3), np.float32)
    for i, v in enumerate(b.verts):
        verts[i, : len(v)] = v
        verts[i, len(v) :] = v[0]
    return _Scene(
        C=C,
        R=R,
        up=up,
        sun=sun,
        sun_rgb=sun_rgb,
        glow=glow,
        glow_strength=float(rng.uniform(0.15, 0.6)),
        sky_rgb=sky_rgb,
        e_sun=float(e_sun),
        zmax=float(rng.uniform(3.5, 4.5)),
        planes=planes,
        verts=verts,
        poly_ids=np.array(b.pids, np.int32),
        ell_c=np.array([e[0] for e in b.ell], np.float32).reshape(-1, 3),
        ell_mat=np.array([e[1] for e in b.ell], np.float32).reshape(-1, 3, 3),
        ell_corners=np.array([e[2] for e in b.ell], np.float32).reshape(-1, 8, 3),
        ell_ids=np.array([e[3] for e in b.ell], np.int32),
        tubes=b.tubes,
        holes=b.holes,
        bowls=b.bowls,
        stains=b.stains,
        mats=b.mats.table(),
        region=(g.x0, g.y0, g.x0 + g.nx * g.res, g.y0 + g.ny * g.res),
        meta=meta,
    )


# --------------------------------------------------------------------------- shading


def _shadow_factor(sc: _Scene, P: F64, n: F64, valid: NDArray[np.bool_]) -> F64:
    """Fraction (N,) of the sun's disc seen from surface points P (N, 3), from a shadow map."""
    out = np.zeros(len(P))
    if sc.sun is None:
        return out
    x0, y0, x1, y1 = sc.region
    box = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (-0.5, 2.5)])
    view = _OrthoView(sc.sun, box)
    smap = _render(view, sc).t.reshape(view.h, view.w)
    a, b, _ = view.pix(P[valid])
    tp = view.depth_of(P[valid])
    cosang = np.clip(_mm(n[valid], sc.sun), 0.05, 1.0)
    bias = 0.012 + np.clip(1.5 * view.texel * np.sqrt(1 - cosang**2) / cosang, 0, 0.12)
    j0, i0 = np.floor(a).astype(np.int64), np.floor(b).astype(np.int64)
    fa, fb = a - j0, b - i0
    lit = np.zeros(len(tp))
    for di, dj, wgt in (
        (0, 0, (1 - fa) * (1 - fb)),
        (0, 1, fa * (1 - fb)),
        (1, 0, (1 - fa) * fb),
        (1, 1, fa * fb),
    ):
        ii = np.clip(i0 + di, 0, view.h - 1)
        jj = np.clip(j0 + dj, 0, view.w - 1)
        lit += wgt * (tp - bias <= smap[ii, jj])
    out[valid] = lit
    return out


@dataclass(frozen=True)
class _Surface:
    """Per-pixel surface data of the camera view, (H, W[, 3])."""

    Z: F64  # metres along the optical axis, inf = nothing
    P: F64
    n: F64
    ident: NDArray[np.int32]
    tag: NDArray[np.int32]
    disp: F64  # roughness displacement along the ray, m
    ir: F64  # IR reflectance
    cos_inc: F64  # |cos| of the incidence angle
    radiance: F32


def _shade(
    rng: np.random.Generator, sc: _Scene, view: _PerspectiveView, tex: _Textures
) -> _Surface:
    h, w = view.h, view.w
    buf = _render(view, sc)
    valid = np.isfinite(buf.t)
    t = np.where(valid, buf.t, 0.0).astype(np.float64)
    D = view.D.astype(np.float64)
    P = sc.C + t[:, None] * D
    ident = np.where(valid, buf.ident, GROUND_ID)
    n = buf.n.astype(np.float64)
    n /= np.maximum(np.linalg.norm(n, axis=1), 1e-9)[:, None]
    n *= np.where((n * D).sum(1) > 0, -1.0, 1.0)[:, None]
    mat = sc.mats[ident]
    shadow = _shadow_factor(sc, P, n, valid)
    # textures (triplanar, per-object offsets)
    Pi, ni = P.reshape(h, w, 3).astype(np.float32), n.reshape(h, w, 3)
    w3 = np.abs(ni) ** 4 + 1e-6
    w3 = (w3 / w3.sum(2, keepdims=True)).astype(np.float32)
    scale = mat[:, _M_SCALE].reshape(h, w)
    off = mat[:, _M_OFF : _M_OFF + 3].reshape(h, w, 3)
    grain = _triplanar(tex.grain, Pi, w3, (250.0 / scale).astype(np.float32), off).reshape(-1)
    smooth = _triplanar(tex.smooth, Pi, w3, (30.0 / scale).astype(np.float32), off * 0.37).reshape(
        -1
    )
    albedo = mat[:, 0:3] * np.exp(mat[:, _M_CON] * (0.75 * smooth + 0.45 * grain))[:, None]
    ir = mat[:, _M_IR].astype(np.float64).copy()
    # dust settles on upward faces
    dust_k = rng.uniform(0.05, 0.35)
    dust = np.array([0.42, 0.40, 0.37]) * rng.uniform(0.8, 1.1)
    f = dust_k * np.clip(_mm(n, sc.up), 0, 1) ** 2 * np.clip(0.6 + 0.3 * smooth, 0, 1)
    albedo = albedo * (1 - f[:, None]) + dust * f[:, None]
    for st in sc.stains:
        c, s_ = math.cos(st.angle), math.sin(st.angle)
        d = P[:, :2] - st.centre
        q = (_mm(d, [c, s_]) / st.axes[0]) ** 2 + (_mm(d, [-s_, c]) / st.axes[1]) ** 2
        m = np.clip((1.15 - q * (1 + 0.3 * smooth)) / 0.3, 0, 1) * (P[:, 2] < 0.6) * valid
        albedo *= (1 - st.strength * m)[:, None]
        if st.wet:
            ir *= 1 - 0.85 * m
    kind = mat[:, _M_KIND].astype(np.int64)
    tag = np.where(valid, mat[:, _M_TAG], -1).astype(np.int32)
    disp = mat[:, _M_DISP] * (0.7 * grain + 0.8 * smooth)
    # bump normals from the screen-space gradient of the displacement
    dimg = disp.reshape(h, w)
    same_u = np.zeros((h, w), bool)
    same_u[:, :-1] = ident.reshape(h, w)[:, 1:] == ident.reshape(h, w)[:, :-1]
    same_v = np.zeros((h, w), bool)
    same_v[:-1] = ident.reshape(h, w)[1:] == ident.reshape(h, w)[:-1]
    gu = np.zeros((h, w))
    gv = np.zeros((h, w))
    gu[:, :-1] = np.diff(dimg, axis=1)
    gv[:-1] = np.diff(dimg, axis=0)
    zz = np.maximum(t.reshape(h, w), 0.3)
    gu = np.where(same_u, gu, 0) * view.cam.fx / zz
    gv = np.where(same_v, gv, 0) * view.cam.fy / zz
    grad = gu.reshape(-1, 1) * sc.R[:, 0] + gv.reshape(-1, 1) * sc.R[:, 1]
    grad -= (grad * n).sum(1)[:, None] * n
    nb = n + np.clip(grad, -2, 2)
    nb /= np.maximum(np.linalg.norm(nb, axis=1), 1e-9)[:, None]
    # ambient occlusion: lower than the neighbourhood, and the sky view from inside shafts
    hgt = np.clip(P[:, 2], -0.6, 1.5).reshape(h, w).astype(np.float32)
    ao = np.exp(-1.5 * np.maximum(cv2.GaussianBlur(hgt, (0, 0), 10) - hgt, 0))
    ao *= np.exp(-3.0 * np.maximum(cv2.GaussianBlur(hgt, (0, 0), 3) - hgt, 0))
    ao = np.clip(ao, 0.35, 1).reshape(-1)
    for hole in sc.holes:
        sel = tag == hole.tag
        if not sel.any():
            continue
        below = np.maximum(hole.rim[:, 2].mean() - P[sel, 2], 0)
        vf = hole.r_eff**2 / (hole.r_eff**2 + below**2)
        vf *= np.where(kind[sel] == KIND_WALL, 0.65, 1.0)
        ao[sel] = np.minimum(ao[sel], 0.03 + vf)
    nu = _mm(nb, sc.up)
    light = (
        sc.e_sun * sc.sun_rgb * (np.clip(_mm(nb, sc.sun), 0, 1) * shadow)[:, None]
        if sc.sun is not None
        else np.zeros((len(nb), 3))
    )
    light = light + sc.sky_rgb * (ao * (0.55 + 0.45 * nu))[:, None]
    glow = np.clip(_mm(nb, sc.glow), 0, 1) * ao  # the bright dawn sky low over the sunrise
    light = light + np.array([1.0, 0.75, 0.6]) * (sc.glow_strength * glow)[:, None]
    bounce = (0.3 + 0.1 * sc.e_sun) * np.array([0.3, 0.27, 0.23]) * (0.5 - 0.5 * nu)[:, None]
    light = light + bounce * ao[:, None]
    rad = (albedo * light).reshape(h, w, 3).astype(np.float32)
    cos_inc = np.abs((n * D).sum(1)) / np.linalg.norm(D, axis=1)
    return _Surface(
        Z=np.where(valid, t, np.inf).reshape(h, w),
        P=P.reshape(h, w, 3),
        n=n.reshape(h, w, 3),
        ident=ident.reshape(h, w).astype(np.int32),
        tag=tag.reshape(h, w),
        disp=disp.reshape(h, w).astype(np.float64),
        ir=ir.reshape(h, w),
        cos_inc=cos_inc.reshape(h, w),
        radiance=rad,
    )


# --------------------------------------------------------------------------- sensors


def _rgb_sensor(rng: np.random.Generator, sc: _Scene, rad: F32) -> NDArray[np.uint8]:
    """Dawn colour camera: blur, vignetting, Bayer, shot/read noise, AE, AWB, gamma."""
    h, w = rad.shape[:2]
    img: NDArray[Any] = rad.copy()
    if rng.uniform() < 0.3:  # a little motion blur from the airframe
        length = rng.uniform(1.5, 4.0)
        k = np.zeros((9, 9), np.float32)
        ang = rng.uniform(0, math.pi)
        for s in np.linspace(-length / 2, length / 2, 15):
            k[round(4 + s * math.sin(ang)), round(4 + s * math.cos(ang))] += 1
        img = cv2.filter2D(img, -1, k / k.sum())
    img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.5, 0.9))
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    img *= (1 - rng.uniform(0.15, 0.45) * r2 - rng.uniform(0, 0.15) * r2**2)[..., None]
    sens = np.array([0.85, 1.0, 0.7]) * (1 + rng.normal(0, 0.04, 3))
    img = img * sens
    ch = np.zeros((h, w), np.int64)  # RGGB
    ch[0::2, 1::2] = 1
    ch[1::2, 0::2] = 1
    ch[1::2, 1::2] = 2
    raw = np.take_along_axis(img, ch[..., None], 2)[..., 0]
    e_mid = math.exp(rng.uniform(math.log(15), math.log(150)))  # photons are scarce at dawn
    green = raw[ch == 1]
    gain = e_mid / max(float(np.median(green)), 1e-6)
    el = rng.poisson(np.maximum(raw * gain, 0)).astype(np.float64)
    el += rng.normal(0, rng.uniform(1.5, 4.0), el.shape) + rng.normal(0, 0.6, (h, 1))
    dn = el / e_mid * 0.13 * 2 ** rng.normal(0, 0.5)
    illum = sens * (sc.e_sun * sc.sun_rgb * 0.4 + sc.sky_rgb)
    gains = (illum[1] / illum) ** rng.uniform(0.2, 0.85) * (1 + rng.normal(0, 0.06, 3))
    dn *= (gains / gains[1])[ch]
    mosaic = (np.clip(dn, 0, 1) * 65535).astype(np.uint16)
    rgb = cv2.cvtColor(mosaic, cv2.COLOR_BayerBG2RGB).astype(np.float64) / 65535
    y = rgb ** (1 / 2.2)
    y = np.clip(0.5 + (y - 0.5) * rng.uniform(1.0, 1.15), 0, 1)
    out: NDArray[np.uint8] = np.round(y * 255).astype(np.uint8)
    return out


def _depth_sensor(
    rng: np.random.Generator, sc: _Scene, cam: CameraModel, s: _Surface
) -> NDArray[np.uint16]:
    """Xtion-like structured-light depth (uint16 mm, 0 = no reading)."""
    h, w = s.Z.shape
    Z: NDArray[Any] = (s.Z + s.disp).astype(np.float32)
    # lateral jitter of the 9x9 correlation window and a small misregistration
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    jit = []
    for glob in (rng.uniform(-1, 1), rng.uniform(-0.6, 0.6)):
        f = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 1.5)
        jit.append(f / f.std() * 0.35 + glob)
    Z = cv2.remap(Z, xx + jit[0], yy + jit[1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
    fb_mm = cam.fx * BASELINE_M * 1000.0
    finite = np.isfinite(Z)
    Zmm = np.where(finite, Z * 1000.0, 1e9).astype(np.float64)
    # IR projector shadow: projector column u - f b / Z must increase along each row
    upj = xx - fb_mm / Zmm
    runmin = np.minimum.accumulate(upj[:, ::-1], axis=1)[:, ::-1]
    right = np.concatenate([runmin[:, 1:], np.full((h, 1), np.inf)], axis=1)
    shadow = upj > right + 0.3
    # axial noise (partly correlated) and disparity quantisation
    wn = rng.standard_normal((h, w)).astype(np.float32)
    cn = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 1.2)
    noise = 0.6 * wn + 0.8 * cn / cn.std()
    noise /= noise.std()
    sigma = rng.uniform(0.6, 1.0) * 1.425e-6 * Zmm**2
    Zn = np.maximum(Zmm + sigma * noise, 100.0)
    disp_px = np.round(fb_mm / Zn / DISPARITY_STEP_PX) * DISPARITY_STEP_PX
    with np.errstate(divide="ignore"):
        Zq = np.where(disp_px > 0, fb_mm / disp_px, np.inf)
    zmax_mm = sc.zmax * 1000.0
    drop = ~finite | shadow | (Zq > zmax_mm) | (Zq < 500)
    # probabilistic dropouts
    p_graz = np.clip((0.25 - s.cos_inc) / 0.17, 0, 1) * 0.9
    p_dark = np.clip((0.14 - s.ir) / 0.1, 0, 1) * 0.8
    zf = np.where(finite, Z, 50.0)
    jump = np.zeros((h, w), bool)
    jump[:, 1:] |= np.abs(np.diff(zf, axis=1)) > 0.04 * zf[:, 1:]
    jump[1:] |= np.abs(np.diff(zf, axis=0)) > 0.04 * zf[1:]
    jump = cv2.dilate(jump.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    p_edge = jump * rng.uniform(0.2, 0.5)
    p_far = np.clip((Zq - (zmax_mm - 300)) / 300, 0, 1) * 0.3
    p_speck = rng.uniform(0.0005, 0.004)
    keep = (1 - p_graz) * (1 - p_dark) * (1 - p_edge) * (1 - p_far) * (1 - p_speck)
    drop |= rng.uniform(size=(h, w)) > keep
    blob = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 6)
    frac = rng.uniform(0, 0.02)
    if frac > 0.001:
        drop |= blob > np.quantile(blob, 1 - frac)
    drop[:, : int(rng.integers(0, 9))] = True
    out = np.where(drop, 0, np.clip(np.round(Zq), 0, 65535))
    return out.astype(np.uint16)


# --------------------------------------------------------------------------- ground truth


def _clip_polygon(p: F64, x0: float, y0: float, x1: float, y1: float) -> F64:
    """Sutherland-Hodgman clip of polygon (N, 2) to a rectangle."""
    for axis, val, ge in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if len(p) == 0:
            break
        out = []
        for i in range(len(p)):
            a, b = p[i - 1], p[i]
            ina = a[axis] >= val if ge else a[axis] <= val
            inb = b[axis] >= val if ge else b[axis] <= val
            if ina != inb:
                f = (val - a[axis]) / (b[axis] - a[axis])
                out.append(a + f * (b - a))
            if inb:
                out.append(b)
        p = np.array(out).reshape(-1, 2)
    return p


def _annotate(sc: _Scene, cam: CameraModel, s: _Surface) -> list[dict[str, Any]]:
    """COCO annotations (without ids) of the access holes in view."""
    anns = []
    for hole in sc.holes:
        if not hole.access:
            continue
        X = (hole.rim - sc.C) @ sc.R
        if (X[:, 2] <= 0.05).any():
            continue
        uv = np.column_stack(
            [cam.fx * X[:, 0] / X[:, 2] + cam.cx + 0.5, cam.fy * X[:, 1] / X[:, 2] + cam.cy + 0.5]
        )
        clipped = _clip_polygon(uv, 0, 0, cam.width, cam.height)
        if len(clipped) < 3 or _polygon_area(clipped) < 4:
            continue
        m = np.zeros((cam.height, cam.width), np.uint8)
        cv2.fillPoly(m, [np.round((clipped - 0.5) * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
        npx = int(m.sum())
        if npx == 0:
            continue
        vis = float(((s.tag == hole.tag) & (m > 0)).sum()) / npx
        if vis < 0.05:
            continue
        cut = bool(((uv < 0) | (uv > [cam.width, cam.height])).any())
        far = float(np.median(X[:, 2])) > sc.zmax
        lo, hi = clipped.min(0), clipped.max(0)
        anns.append(
            {
                "category_id": 1,
                "bbox": [round(float(v), 2) + 0.0 for v in (*lo, *(hi - lo))],  # no -0.0
                "area": round(_polygon_area(clipped), 2),
                "segmentation": [[round(float(v), 2) for v in clipped.ravel()]],
                "iscrowd": int(cut or vis < 0.5 or far),
                "hole_kind": hole.kind,
                "visible_fraction": round(vis, 3),
                "rim_depth_m": round(float(np.median(X[:, 2])), 3),
            }
        )
    return anns


# --------------------------------------------------------------------------- dataset


@dataclass(frozen=True)
class _Job:
    index: int
    seed: int
    cam: CameraModel
    out: Path


def _assets(seed: int) -> tuple[list[_Shape], _Textures]:
    rng = np.random.default_rng([seed, 0xA11E])
    return _make_library(rng), _make_textures(rng)


def _render_image(
    job: _Job, lib: list[_Shape], tex: _Textures
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    rng = np.random.default_rng([job.seed, job.index, 1])
    sc = _sample_scene(rng, job.cam, lib)
    view = _PerspectiveView(job.cam, sc.C, sc.R)
    surf = _shade(rng, sc, view, tex)
    rgb = _rgb_sensor(rng, sc, surf.radiance)
    depth = _depth_sensor(rng, sc, job.cam, surf)
    anns = _annotate(sc, job.cam, surf)
    name = f"alien_{job.index:05d}.png"
    if not cv2.imwrite(str(job.out / "rgb" / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f"cannot write {job.out / 'rgb' / name}")
    if not cv2.imwrite(str(job.out / "depth" / name), depth):
        raise OSError(f"cannot write {job.out / 'depth' / name}")
    image = {
        "id": job.index + 1,
        "file_name": f"rgb/{name}",
        "depth_file_name": f"depth/{name}",
        "width": job.cam.width,
        "height": job.cam.height,
        "scene": sc.meta
        | {
            "max_range_m": round(sc.zmax, 3),
            "valid_depth_fraction": round(float((depth > 0).mean()), 3),
        },
    }
    return image, anns


_WORKER_ASSETS: dict[int, tuple[list[_Shape], _Textures]] = {}


def _worker(job: _Job) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    if job.seed not in _WORKER_ASSETS:
        _WORKER_ASSETS[job.seed] = _assets(job.seed)
    lib, tex = _WORKER_ASSETS[job.seed]
    return _render_image(job, lib, tex)


def generate_dataset(out: Path, n: int, seed: int, jobs: int = 1) -> dict[str, Any]:
    """Write ``n`` scenes to ``out`` (annotations.json, camera.json, rgb/, depth/).

    Deterministic for (n, seed) whatever ``jobs`` is. Returns a summary: images, holes,
    crowd, empty images, seconds.
    """
    if n < 1:
        raise ValueError("n must be >= 1")
    t0 = time.monotonic()
    out = Path(out)
    (out / "rgb").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(parents=True, exist_ok=True)
    cam = CameraModel.sample(np.random.default_rng([seed, 0xCA]))
    work = [_Job(i, seed, cam, out) for i in range(n)]
    if jobs > 1:
        ctx = multiprocessing.get_context("fork")
        with ctx.Pool(jobs) as pool:
            results = pool.map(_worker, work, chunksize=1)
    else:
        results = [_worker(j) for j in work]
    images: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for image, anns in results:
        images.append(image)
        for a in anns:
            annotations.append({"id": len(annotations) + 1, "image_id": image["id"]} | a)
    coco = {
        "info": {
            "description": "alien synthetic rubble scenes (benchmarks/alien_scenes.py)",
            "seed": seed,
            "version": "1",
        },
        "images": images,
        "annotations": annotations,
        "categories": [{"id": 1, "name": "access_hole", "supercategory": "hole"}],
    }
    (out / "annotations.json").write_text(json.dumps(coco, indent=1))
    (out / "camera.json").write_text(json.dumps(cam.to_json(), indent=1))
    crowd = sum(a["iscrowd"] for a in annotations)
    with_hole = {a["image_id"] for a in annotations if not a["iscrowd"]}
    return {
        "images": n,
        "holes": len(annotations) - crowd,
        "crowd": crowd,
        "images_without_hole": n - len(with_hole),
        "seconds": round(time.monotonic() - t0, 1),
    }


def main(argv: list[str] | None = None) -> int:
    """Command line: ``alien_scenes.py OUT [--n N] [--seed S] [--jobs J]``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("out", type=Path, help="output folder")
    ap.add_argument("--n", type=int, default=60, help="number of images (default 60)")
    ap.add_argument("--seed", type=int, default=7, help="random seed (default 7)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    summary = generate_dataset(args.out, args.n, args.seed, args.jobs)
    print(
        f"images {summary['images']}, holes {summary['holes']} (+{summary['crowd']} crowd), "
        f"images without a hole {summary['images_without_hole']}, {summary['seconds']} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
