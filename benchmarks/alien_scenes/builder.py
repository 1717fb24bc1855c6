"""Alien scenes: the scene builder (holes, rubble, distractors)."""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from alien_scenes.common import (
    F64,
    I64,
    CameraModel,
    mm,
    perp_basis,
    pick,
    resting_rotation,
    rot,
    rz,
)
from alien_scenes.raycast import Grid
from alien_scenes.sampling import (
    LIB_BOX,
    LIB_HULL0,
    ground_point,
    opening_polygon,
    poly_dims,
    polygon_area,
)
from alien_scenes.shapes import (
    HOLE_RES,
    KIND_BOWL,
    KIND_FLOOR,
    KIND_GROUND,
    KIND_PIPE_IN,
    KIND_PIPE_OUT,
    KIND_RUBBLE,
    KIND_WALL,
    Bowl,
    Hole,
    Materials,
    Shape,
    Stain,
    Tube,
    instance,
)


class Builder:
    """Accumulates the solids, holes and surfaces of one scene."""

    def __init__(self, rng: np.random.Generator, cam: CameraModel, lib: list[Shape]) -> None:
        self.rng, self.cam, self.lib = rng, cam, lib
        self.mats = Materials(rng)
        self.mats.add(pick(rng, ["dirt", "stone", "concrete"]), KIND_GROUND)
        self.planes: list[F64] = []
        self.verts: list[F64] = []
        self.pids: list[int] = []
        self.ell: list[tuple[F64, F64, F64, int]] = []
        self.tubes: list[Tube] = []
        self.holes: list[Hole] = []
        self.bowls: list[Bowl] = []
        self.stains: list[Stain] = []
        self.kinds: dict[str, int] = {}
        self.cells: I64 | None = None
        self.pile_cap = float(rng.uniform(0.3, 0.8))  # rubble stops piling above this, m
        self.grid: Grid
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
        p = ground_point(self.cam, self.C, self.R, u, v)
        return None if p is None else p[:2]

    def add_poly(self, shape: int, dims: F64, R: F64, c: F64, mat: int) -> F64:
        planes, verts = instance(self.lib[shape], dims, R, c)
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
    def hole_mask(self, poly: F64) -> tuple[NDArray[np.uint8], float, float]:
        x0, y0 = poly.min(0) - 0.02
        size = np.ceil((poly.max(0) + 0.02 - (x0, y0)) / HOLE_RES).astype(int) + 1
        m = np.zeros((size[1], size[0]), np.uint8)
        q = np.round((poly - (x0, y0)) / HOLE_RES * 16).astype(np.int32)
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
        Rt = rot(x, math.radians(r.uniform(-10, 8))) @ rot(y, math.radians(r.uniform(-5, 5)))
        Re = np.column_stack([x, y, z]) @ Rt
        dims = np.array([L + ext[0] + ext[1], Ws, T + sink])
        centre_l = np.array([(L + ext[1] - ext[0]) / 2, Ws / 2, (T - sink) / 2])
        A3 = np.append(A, 0.0)
        c = A3 + Re @ centre_l
        corners = (self.lib[LIB_BOX].verts * dims) @ Re.T + c
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
        self.add_poly(LIB_BOX, dims, Re, c, self.mats.add("concrete", KIND_RUBBLE))
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
        X = mm(pts - self.C, self.R)
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
        poly = opening_polygon(r, kind)
        L, S, ins = poly_dims(poly, a)
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
        wall_mat = "concrete" if kind in ("rect", "gap") else pick(r, ["dirt", "stone"])
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
        u, v = perp_basis(a)
        p3 = np.column_stack([poly, np.zeros(len(poly))])
        r_eff = math.sqrt(polygon_area(np.column_stack([p3 @ u, p3 @ v])) / math.pi)
        hole = Hole(kind, access, poly, a, depth, rim, tag, wall_id, floor_id, r_eff, m, x0, y0)
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
                shape = int(self.rng.integers(LIB_HULL0, len(self.lib)))
                mat = self.mats.add(pick(self.rng, ["concrete", "stone", "brick"]), 1, tag)
                self.add_poly(shape, dims, resting_rotation(self.rng, 30), c, mat)

    def add_pipe(self, centre: F64, access: bool, whole: bool = False) -> bool:
        r = self.rng
        if access:
            r_in, wall = r.uniform(0.36, 0.62), r.uniform(0.05, 0.12)
            tilt = r.uniform(0, 12) if r.uniform() < 0.5 else r.uniform(15, 35)
            mat = pick(r, ["concrete", "concrete", "rust"])
        else:
            r_in, wall = r.uniform(0.04, 0.14), r.uniform(0.006, 0.03)
            tilt = r.uniform(20, 75)
            mat = pick(r, ["pvc", "rust", "concrete", "metal"])
        r_out = r_in + wall
        t, az = math.radians(tilt), r.uniform(0, 2 * math.pi)
        a = np.array([math.sin(t) * math.cos(az), math.sin(t) * math.sin(az), math.cos(t)])
        u, v = perp_basis(a)
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
        self.tubes.append(Tube(top, a, r_in, r_out, s_b, out_id, in_id))
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
        ell = np.column_stack([a * np.cos(phi), b * np.sin(phi)]) @ rz(th)[:2, :2].T + centre
        if self.grid.overlaps_keepout(ell) or not self.grid.inside(centre):
            return False
        # no keep-out: rubble may settle into the bowl (holes are all placed already)
        M = np.diag([1 / a, 1 / b, 1 / d]) @ rz(th).T
        r0, r1, c0, c1, m = self.grid.roi_mask(ell)
        if m.size:
            g = self.grid
            yy, xx = np.mgrid[r0:r1, c0:c1]
            pts = np.column_stack([xx.ravel(), yy.ravel()]) * g.res + (g.x0, g.y0) - centre
            q = mm(pts, rz(th)[:2, :2]) / (a, b)
            bowl = -d * np.sqrt(np.clip(1 - (q**2).sum(1), 0, 1)).reshape(m.shape)
            hroi = g.hmap[r0:r1, c0:c1]
            np.minimum(hroi, bowl, out=hroi)
        ident = self.mats.add("dirt", KIND_BOWL, disp=0.01)
        self.bowls.append(Bowl(np.append(centre, 0.0), M, ident))
        self.count("depression")
        return True

    def add_mound(self, xy: F64) -> bool:
        r = self.rng
        ax = np.array([r.uniform(0.8, 2.2), r.uniform(0.6, 1.8), r.uniform(0.2, 0.6)])
        z0 = -ax[2] * r.uniform(0.2, 0.7)
        k = math.sqrt(1 - (z0 / ax[2]) ** 2)
        th = r.uniform(0, math.pi)
        Rm = rz(th)
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
            q = mm(pts - xy, Rm[:2, :2]) / ax[:2]
            dome = z0 + ax[2] * np.sqrt(np.clip(1 - (q**2).sum(1), 0, 1))
            hroi = self.grid.hmap[r0:r1, c0:c1]
            np.maximum(hroi, dome.reshape(hroi.shape) * (m > 0), out=hroi)
        self.count("mound")
        return True

    def random_region_point(self) -> F64:
        g = self.grid
        if self.cells is None:
            self.cells = np.flatnonzero(g.region)
        k = int(self.cells[int(self.rng.integers(len(self.cells)))])
        r, c = divmod(k, g.nx)
        return np.array(
            [g.x0 + (c + self.rng.random()) * g.res, g.y0 + (r + self.rng.random()) * g.res]
        )
