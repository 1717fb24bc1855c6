"""A synthetic rubble field: metric height map, colour, and the true holes in it.

World frame: metres, origin at the field's south-west corner, x east, y north, z up
(z = 0 is the mean ground level). The field covers ``0 <= x <= size_m[0]``,
``0 <= y <= size_m[1]``. Grid node ``[j, i]`` lies at ``(i * cell_m, j * cell_m)``; between
nodes the surface is bilinear, so a hole's wall is at most one cell wide (vertical walls).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import Literal

import cv2
import numpy as np
import numpy.typing as npt

import holescan.sim._shapes as shp
from holescan.errors import InputError
from holescan.sim._lighting import radiance_map
from holescan.sim._raycast import MaxPyramid, build_pyramid

__all__ = ["AccessHole", "HoleKind", "RubbleWorld", "make_world", "relight"]

_log = logging.getLogger(__name__)

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]

HoleKind = Literal["access", "small_hole", "crack", "depression", "stain", "shadow"]
"""``access``: a human-size opening (the target). The rest are distractors: ``small_hole``
(< 0.3 m), ``crack`` (long, thin, deep), ``depression`` (broad, 0.05-0.25 m deep),
``stain`` (dark albedo only), ``shadow`` (dark albedo patch beside a slab)."""


@dataclass(frozen=True, eq=False)
class AccessHole:
    """Ground truth for one hole-like feature of the world (a true access hole or a distractor).

    id : index in :attr:`RubbleWorld.holes`.
    kind : what it is (see :data:`HoleKind`); :attr:`is_access` for true access holes.
    centre_xy : (x, y) world metres, the opening's centroid.
    rim_z : height of the rim (median of the terrain along the opening), metres.
    opening : (N, 2) float64 ndarray, world x, y metres, counter-clockwise outline.
    floor_depth_m : depth of the floor below the rim, metres (0 for stains and shadows).
    major_m, minor_m : sides of the opening's minimum-area bounding rectangle, metres.
    """

    id: int
    kind: HoleKind
    centre_xy: tuple[float, float]
    rim_z: float
    opening: F64
    floor_depth_m: float
    major_m: float
    minor_m: float

    @property
    def is_access(self) -> bool:
        """True for a human-size access hole, False for a distractor."""
        return self.kind == "access"

    def opening_xyz(self) -> F64:
        """(N, 3) float64: the opening's outline at rim height, world metres."""
        z = np.full((len(self.opening), 1), self.rim_z)
        return np.hstack([self.opening, z])


@dataclass(frozen=True, eq=False)
class RubbleWorld:
    """A rubble field, ready to render.

    seed : what :func:`make_world` was called with.
    cell_m : grid spacing, metres.
    height : (ny, nx) float32 ndarray, metres, z up.
    albedo : (ny, nx, 3) float32 ndarray, linear RGB reflectance in [0, 1].
    radiance : (ny, nx, 3) float32 ndarray, linear RGB radiance under the world's light.
    holes : the true access holes and the distractors.
    sun_azimuth : rad clockwise from north; sun_elevation : rad above the horizon.
    ir_unread : (ny, nx) float32 ndarray, fraction of the infrared pattern each cell's surface
        returns nothing for (soot, char and wet stains: 0.55-0.76); None = 0 everywhere.
    surface : (ny, nx, 4) float32, radiance and ``ir_unread`` stacked (what is rendered).
    """

    seed: int
    cell_m: float
    height: F32
    albedo: F32
    radiance: F32
    holes: tuple[AccessHole, ...]
    sun_azimuth: float
    sun_elevation: float
    ir_unread: F32 | None = None
    pyramid: MaxPyramid = field(init=False, repr=False)
    surface: F32 = field(init=False, repr=False)

    def __post_init__(self) -> None:
        h = self.height
        if h.ndim != 2 or h.dtype != np.float32 or min(h.shape) < 2:
            raise InputError("height must be a (ny, nx) float32 array with ny, nx >= 2")
        for name in ("albedo", "radiance"):
            a = getattr(self, name)
            if a.shape != (*h.shape, 3) or a.dtype != np.float32:
                raise InputError(f"{name} must be (ny, nx, 3) float32 like height")
        if self.ir_unread is not None and self.ir_unread.shape != h.shape:
            raise InputError("ir_unread must be (ny, nx) like height")
        object.__setattr__(self, "pyramid", build_pyramid(h))
        ir = self.ir_unread if self.ir_unread is not None else np.zeros(h.shape, np.float32)
        stack = np.concatenate([self.radiance, ir.astype(np.float32)[..., None]], axis=-1)
        object.__setattr__(self, "surface", np.ascontiguousarray(stack))

    @property
    def size_m(self) -> tuple[float, float]:
        """(x extent, y extent) of the field, metres."""
        ny, nx = self.height.shape
        return ((nx - 1) * self.cell_m, (ny - 1) * self.cell_m)

    @property
    def access_holes(self) -> tuple[AccessHole, ...]:
        return tuple(h for h in self.holes if h.is_access)

    def height_at(self, xy: npt.ArrayLike) -> F64:
        """Terrain height (metres) at world points ``xy`` (N, 2), bilinear."""
        pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return shp.sample_bilinear(self.height, pts, self.cell_m)


def relight(world: RubbleWorld, sun_azimuth: float, sun_elevation: float) -> RubbleWorld:
    """The same world under another sun (angles in rad)."""
    rad = radiance_map(world.height, world.albedo, world.cell_m, sun_azimuth, sun_elevation)
    return replace(world, radiance=rad, sun_azimuth=sun_azimuth, sun_elevation=sun_elevation)


# ----------------------------------------------------------------------------- generation


def _noise(rng: np.random.Generator, shape: tuple[int, int], cell_m: float, scale_m: float) -> F32:
    """Smooth unit-variance-ish noise with features ~``scale_m`` across."""
    ny, nx = shape
    n_r = max(2, math.ceil(ny * cell_m / scale_m) + 2)
    n_c = max(2, math.ceil(nx * cell_m / scale_m) + 2)
    coarse = rng.standard_normal((n_r, n_c)).astype(np.float32)
    return np.asarray(cv2.resize(coarse, (nx, ny), interpolation=cv2.INTER_CUBIC), np.float32)


@dataclass
class _Builder:
    rng: np.random.Generator
    cell: float
    height: F32
    colour: F32
    shade: F32  # multiplicative albedo factor (stains, shadows, dust)
    # Fraction of the infrared pattern a cell's surface swallows (soot, char, wet patches),
    # and the generator of those draws (apart, so the rest of the world is unchanged).
    ir_unread: F32
    ir_rng: np.random.Generator
    # Slabs as (centre, length, width, yaw), for the shadow distractors.
    slabs: list[tuple[tuple[float, float], float, float, float]] = field(default_factory=list)
    occupied: list[tuple[float, float, float]] = field(default_factory=list)
    holes: list[AccessHole] = field(default_factory=list)

    @property
    def size(self) -> tuple[float, float]:
        ny, nx = self.height.shape
        return ((nx - 1) * self.cell, (ny - 1) * self.cell)

    # --- blocks --------------------------------------------------------------------------
    def block(
        self,
        centre: tuple[float, float],
        length: float,
        width: float,
        thickness: float,
        slope: float,
        colour: tuple[float, float, float],
        base_percentile: float,
        yaw: float,
    ) -> None:
        poly = shp.rectangle(centre, length, width, yaw)
        win = shp.rasterise(poly, self.cell, self.height.shape, pad=0)
        if win is None or not win[2].any():
            return
        rows, cols, mask = win
        h = self.height[rows, cols]
        base = float(np.percentile(h[mask], base_percentile))
        tilt_dir = self.rng.uniform(0.0, 2.0 * math.pi)
        x, y = shp.window_xy(rows, cols, self.cell)
        plane = (
            base
            + thickness
            + slope * (math.cos(tilt_dir) * (x - centre[0]) + math.sin(tilt_dir) * (y - centre[1]))
        )
        won = mask & (plane > h)
        h[won] = plane[won]
        self.colour[rows, cols][won] = colour

    def slab(self) -> None:
        rng = self.rng
        length = rng.uniform(0.6, 2.6)
        width = rng.uniform(0.4, min(1.6, length))
        centre = (rng.uniform(0, self.size[0]), rng.uniform(0, self.size[1]))
        grey = rng.uniform(0.30, 0.55)
        tint = rng.normal(0.0, 0.03, 3)
        colour = (grey * (1 + tint[0]), grey * (1 + tint[1]), grey * (1 + tint[2]) * 0.97)
        thickness = rng.uniform(0.10, 0.35)
        yaw = rng.uniform(0.0, math.pi)
        slope = math.tan(rng.uniform(0.0, 0.45))
        self.block(centre, length, width, thickness, slope, colour, 60, yaw)
        self.slabs.append((centre, length, width, yaw))

    def debris(self) -> None:
        rng = self.rng
        length = math.exp(rng.uniform(math.log(0.04), math.log(0.35)))
        width = length * rng.uniform(0.5, 1.0)
        thickness = width * rng.uniform(0.3, 0.8)
        centre = (rng.uniform(0, self.size[0]), rng.uniform(0, self.size[1]))
        kind = rng.uniform()
        if kind < 0.1:  # brick
            colour = (0.42, 0.20, 0.14)
        elif kind < 0.2:  # dark (charred, wet)
            colour = (0.14, 0.13, 0.12)
        elif kind < 0.25:  # wood
            colour = (0.42, 0.31, 0.19)
        else:
            g = rng.uniform(0.28, 0.6)
            colour = (g, g * 0.98, g * 0.95)
        slope = math.tan(rng.uniform(0.0, 0.3))
        self.block(centre, length, width, thickness, slope, colour, 50, rng.uniform(0.0, math.pi))

    # --- holes and distractors ----------------------------------------------------------
    def place(self, radius: float, margin: float = 0.5, gap: float = 0.25) -> tuple[float, float]:
        """A free centre for a feature of ``radius`` metres, or raise LookupError."""
        sx, sy = self.size
        lo = radius + margin
        if sx - 2 * lo <= 0 or sy - 2 * lo <= 0:
            raise LookupError("field too small")
        for _ in range(300):
            c = (self.rng.uniform(lo, sx - lo), self.rng.uniform(lo, sy - lo))
            if all(math.hypot(c[0] - x, c[1] - y) > radius + r + gap for x, y, r in self.occupied):
                return c
        raise LookupError("no free room")

    def add(self, kind: HoleKind, poly: F64, floor_depth: float) -> AccessHole:
        poly = shp.ccw(poly)
        rim = shp.sample_bilinear(self.height, shp.densify(poly, self.cell), self.cell)
        major, minor = shp.axes(poly)
        c = poly.mean(axis=0)
        hole = AccessHole(
            id=len(self.holes),
            kind=kind,
            centre_xy=(float(c[0]), float(c[1])),
            rim_z=float(np.median(rim)),
            opening=poly,
            floor_depth_m=float(floor_depth),
            major_m=major,
            minor_m=minor,
        )
        radius = float(np.max(np.hypot(*(poly - c).T)))
        self.occupied.append((float(c[0]), float(c[1]), radius))
        self.holes.append(hole)
        return hole

    def outline(self, a: float, b: float, centre: tuple[float, float]) -> F64:
        if self.rng.uniform() < 0.5:
            return shp.irregular_ellipse(self.rng, centre, a, b)
        return shp.irregular_polygon(self.rng, centre, a, b)

    def pit(self, kind: HoleKind, a: float, b: float, depth: float) -> None:
        poly = self.outline(a, b, (0.0, 0.0))
        if kind == "access":  # guarantee a human-size opening after the wobble
            major, minor = shp.axes(poly)
            poly = poly * max(1.0, 0.72 / major, 0.41 / minor)
        poly = poly + self.place(float(np.max(np.hypot(*poly.T))))
        hole = self.add(kind, poly, depth)
        win = shp.rasterise(poly, self.cell, self.height.shape)
        if win is None:
            return
        rows, cols, mask = win
        rough = 0.04 * _noise(self.rng, mask.shape, self.cell, 0.12)
        floor = hole.rim_z - depth + rough
        self.height[rows, cols][mask] = floor[mask]
        self.shade[rows, cols][mask] *= 0.8

    def crack(self) -> None:
        rng = self.rng
        length, width = rng.uniform(1.0, 4.0), rng.uniform(0.02, 0.08)
        poly = shp.crack_polygon(rng, (0.0, 0.0), length, width)
        c = poly.mean(axis=0)
        radius = float(np.max(np.hypot(*(poly - c).T)))
        centre = self.place(radius)
        poly = poly - c + centre
        depth = rng.uniform(0.2, 0.8)
        self.add("crack", poly, depth)
        win = shp.rasterise(poly, self.cell, self.height.shape)
        if win is not None:
            rows, cols, mask = win
            self.height[rows, cols][mask] -= depth

    def depression(self) -> None:
        rng = self.rng
        a = rng.uniform(0.4, 1.25)
        b = a * rng.uniform(0.6, 1.0)
        depth = rng.uniform(0.05, 0.25)
        centre = self.place(a * 1.15)
        poly = shp.irregular_ellipse(rng, centre, a, b)
        self.add("depression", poly, depth)
        win = shp.rasterise(poly, self.cell, self.height.shape)
        if win is not None:
            rows, cols, mask = win
            dist = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5) * self.cell
            s = np.clip(dist / b, 0.0, 1.0)
            self.height[rows, cols] -= (depth * s * s * (3 - 2 * s)).astype(np.float32)

    def darken(self, kind: HoleKind, poly: F64, factor: float, ir_unread: float = 0.0) -> None:
        self.add(kind, poly, 0.0)
        win = shp.rasterise(poly, self.cell, self.height.shape, pad=8)
        if win is not None:
            rows, cols, mask = win
            soft = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 2.5)
            self.shade[rows, cols] *= 1.0 - (1.0 - factor) * soft
            if ir_unread > 0:
                cur = self.ir_unread[rows, cols]
                self.ir_unread[rows, cols] = np.maximum(cur, ir_unread * (soft > 0.5))

    def stain(self) -> None:
        a = self.rng.uniform(0.2, 0.75)
        b = a * self.rng.uniform(0.5, 1.0)
        centre = self.place(a * 1.15)
        # Two stains in three are soot, char or wet: they swallow 55-76 % of the pattern.
        ir = float(self.ir_rng.uniform(0.55, 0.76)) if self.ir_rng.random() < 2 / 3 else 0.0
        self.darken("stain", self.outline(a, b, centre), self.rng.uniform(0.25, 0.55), ir)

    def shadow(self) -> None:
        rng = self.rng
        for _ in range(20):
            centre, length, width, yaw = self.slabs[int(rng.integers(len(self.slabs)))]
            pw, pl = rng.uniform(0.2, 0.6), length * rng.uniform(0.7, 1.0)
            normal = np.array([-math.sin(yaw), math.cos(yaw)]) * rng.choice([-1.0, 1.0])
            c = np.asarray(centre) + normal * (width / 2 + pw / 2)
            radius = math.hypot(pl / 2, pw / 2)
            sx, sy = self.size
            ok = radius + 0.5 < c[0] < sx - radius - 0.5 and radius + 0.5 < c[1] < sy - radius - 0.5
            if ok and all(
                math.hypot(c[0] - x, c[1] - y) > radius + r + 0.25 for x, y, r in self.occupied
            ):
                poly = shp.rectangle((float(c[0]), float(c[1])), pl, pw, yaw)
                self.darken("shadow", poly, rng.uniform(0.3, 0.6))
                return
        raise LookupError("no slab with free room beside it")


def make_world(
    seed: int,
    size_m: tuple[float, float] = (20.0, 20.0),
    *,
    cell_m: float = 0.02,
    n_access_holes: int = 10,
    n_small_holes: int = 12,
    n_cracks: int = 10,
    n_depressions: int = 8,
    n_stains: int = 10,
    n_shadows: int = 8,
    slabs_per_m2: float = 0.22,
    debris_per_m2: float = 6.0,
    sun_azimuth_deg: float | None = None,
    sun_elevation_deg: float | None = None,
) -> RubbleWorld:
    """Build a rubble field; the same arguments always give the same world.

    Parameters
    ----------
    seed : random seed.
    size_m : (x, y) extent in metres (origin at the south-west corner).
    cell_m : grid spacing, metres (0.02: a pixel at 3 m covers ~5 mm, so ~4 px per cell).
    n_access_holes : human-size openings (0.7-1.5 m by >= 0.4 m, floors 0.8-3 m deep).
    n_small_holes, n_cracks, n_depressions, n_stains, n_shadows : distractors.
    slabs_per_m2, debris_per_m2 : density of tilted slabs and small blocks.
    sun_azimuth_deg, sun_elevation_deg : the low sun; random dawn (east) or dusk (west),
        3-15 deg high, when None.

    Features that find no free room are skipped (logged at debug level); ``holes`` says
    what exists.
    """
    sx, sy = float(size_m[0]), float(size_m[1])
    if not (2.0 <= sx <= 500.0 and 2.0 <= sy <= 500.0):
        raise InputError(f"size_m must be 2-500 m per side, got {size_m}")
    if not 0.004 <= cell_m <= 0.2:
        raise InputError(f"cell_m must be 0.004-0.2 m, got {cell_m}")
    counts = (n_access_holes, n_small_holes, n_cracks, n_depressions, n_stains, n_shadows)
    if min(counts) < 0 or slabs_per_m2 < 0 or debris_per_m2 < 0:
        raise InputError("feature counts and densities must be >= 0")
    nx, ny = round(sx / cell_m) + 1, round(sy / cell_m) + 1
    if nx * ny > 60_000_000:
        raise InputError(f"{nx}x{ny} grid is too large: use a coarser cell_m or a smaller field")

    rng = np.random.default_rng(seed)
    shape = (ny, nx)
    height = (
        0.12 * _noise(rng, shape, cell_m, 4.0)
        + 0.04 * _noise(rng, shape, cell_m, 1.0)
        + 0.012 * _noise(rng, shape, cell_m, 0.25)
        + 0.005 * _noise(rng, shape, cell_m, 0.06)
    ).astype(np.float32)
    grey = 0.38 + 0.05 * _noise(rng, shape, cell_m, 2.0)
    dirt = np.clip(0.5 + 0.6 * _noise(rng, shape, cell_m, 3.0), 0.0, 1.0) * 0.7
    colour = np.empty((ny, nx, 3), dtype=np.float32)
    for ch, (g_tint, b_tint) in enumerate(((1.0, 1.16), (1.0, 0.95), (1.02, 0.72))):
        colour[..., ch] = grey * ((1 - dirt) * g_tint + dirt * b_tint)
    ir_unread = np.zeros(shape, dtype=np.float32)
    ir_rng = np.random.default_rng([seed, 0x1F])
    b = _Builder(rng, cell_m, height, colour, np.ones(shape, dtype=np.float32), ir_unread, ir_rng)

    area = sx * sy
    for _ in range(round(slabs_per_m2 * area)):
        b.slab()
    for _ in range(round(debris_per_m2 * area)):
        b.debris()
    plan: list[tuple[str, int]] = [
        ("access", n_access_holes),
        ("small_hole", n_small_holes),
        ("crack", n_cracks),
        ("depression", n_depressions),
        ("stain", n_stains),
        ("shadow", n_shadows if b.slabs else 0),
    ]
    for kind, n in plan:
        made = 0
        for _ in range(n):
            try:
                if kind == "access":
                    a = rng.uniform(0.35, 0.75)
                    b.pit("access", a, max(0.2, a * rng.uniform(0.5, 1.0)), rng.uniform(0.8, 3.0))
                elif kind == "small_hole":
                    a = rng.uniform(0.05, 0.14)
                    b.pit("small_hole", a, a * rng.uniform(0.6, 1.0), rng.uniform(0.2, 1.2))
                else:
                    getattr(b, kind)()
                made += 1
            except LookupError:
                pass
        if made < n:
            _log.debug("world %d: placed %d of %d %s features (no room)", seed, made, n, kind)

    texture = (
        1.0 + 0.10 * _noise(rng, shape, cell_m, 0.04) + 0.07 * _noise(rng, shape, cell_m, 0.15)
    )
    albedo = np.clip(colour * (b.shade * texture)[..., None], 0.02, 0.9).astype(np.float32)

    if sun_azimuth_deg is None:
        dawn = rng.uniform() < 0.5
        sun_azimuth_deg = float(rng.uniform(60, 120) if dawn else rng.uniform(240, 300))
    if sun_elevation_deg is None:
        sun_elevation_deg = float(rng.uniform(3.0, 15.0))
    az, el = math.radians(sun_azimuth_deg), math.radians(sun_elevation_deg)
    rad = radiance_map(height, albedo, cell_m, az, el)
    return RubbleWorld(seed, cell_m, height, albedo, rad, tuple(b.holes), az, el, ir_unread)
