"""Alien scenes: the world grid, views and the ray caster."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from alien_scenes.common import F32, F64, GROUND_ID, I64, CameraModel, mm, perp_basis
from alien_scenes.shapes import Hole, Scene, Tube

# --------------------------------------------------------------------------- world grid


class Grid:
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


class PerspectiveView(_View):
    def __init__(self, cam: CameraModel, C: F64, R: F64) -> None:
        self.h, self.w = cam.height, cam.width
        self.cam, self.C, self.R = cam, C, R
        v, u = np.mgrid[0 : cam.height, 0 : cam.width]
        d = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(u.shape)], -1).reshape(
            -1, 3
        )
        self.D = mm(d, R.T).astype(np.float32)
        self.origin = np.broadcast_to(C.astype(np.float32), self.D.shape)
        self.o_const, self.d_const = C, None

    def pix(self, pts: F64) -> tuple[F64, F64, F64]:
        X = mm(pts - self.C, self.R)
        z = X[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            zz = np.where(z > 0.05, z, np.nan)
            return (
                self.cam.fx * X[..., 0] / zz + self.cam.cx,
                self.cam.fy * X[..., 1] / zz + (self.cam.cy),
                z,
            )


class OrthoView(_View):
    """Parallel rays towards -s (from the sun), pixel (r, c) at base + c*tx*ea + r*tx*eb."""

    LIFT = 60.0

    def __init__(self, s: F64, pts: F64, max_px: int = 512, min_texel: float = 0.01) -> None:
        self.s = s
        self.ea, self.eb = perp_basis(s)
        a, b = mm(pts, self.ea), mm(pts, self.eb)
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
            mm(rel, self.ea) / self.texel,
            mm(rel, self.eb) / self.texel,
            np.ones(pts.shape[:-1]),
        )

    def depth_of(self, P: F64) -> F64:
        return self.LIFT - mm(P - self.base, self.s)


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


def _cast_polyhedra(view: _View, buf: _Buffers, sc: Scene) -> None:
    """Ray-cast all polyhedra, nearest first, skipping pairs already hidden."""
    if len(sc.poly_ids) == 0:
        return
    verts = sc.verts.astype(np.float64)
    covers = _cover(view, verts)
    nlive = (sc.planes[..., :3] != 0).any(-1).sum(-1)
    near = view.depth_of(verts).min(1) if isinstance(view, OrthoView) else view.pix(verts)[2].min(1)
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


def _poly_batch(view: _View, buf: _Buffers, sc: Scene, obj: I64, pix: I64, F: int) -> None:
    """Slab test of rays against convex polyhedra, for (object, pixel) pairs."""
    if len(pix) == 0:
        return
    n = sc.planes[obj, :F, :3]
    if view.d_const is not None:
        den = mm(n, view.d_const.astype(np.float32))
    else:
        den = np.einsum("pfk,pk->pf", n, view.D[pix])
    if view.o_const is not None:
        num = sc.planes[obj, :F, 3] - mm(n, view.o_const.astype(np.float32))
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


def _cast_ellipsoids(view: _View, buf: _Buffers, sc: Scene) -> None:
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


def _cast_tube(view: _View, buf: _Buffers, tb: Tube) -> None:
    u0, u1, v0, v1 = view.rects(tb.corners()[None])
    _obj, pix = _pairs(u0, u1, v0, v1, np.array([0]), view.w)
    if len(pix) == 0:
        return
    a = tb.axis
    rel = view.origin[pix].astype(np.float64) - tb.top
    D = view.D[pix].astype(np.float64)
    Oa, Da = mm(rel, a), mm(D, a)
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


def _shaft_hit(hole: Hole, D: F64, t0: F64, Pxy: F64) -> tuple[F64, F64, NDArray[np.int32]]:
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


def _cast_ground(view: _View, buf: _Buffers, sc: Scene) -> None:
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
        q = mm(P - bowl.centre, bowl.M.T)
        inside = (q[:, 0] ** 2 + q[:, 1] ** 2) < 1.0
        if not inside.any():
            continue
        ii = idx[inside]
        o = mm(view.origin[ii].astype(np.float64) - bowl.centre, bowl.M.T)
        d = mm(D[ii].astype(np.float64), bowl.M.T)
        A = (d * d).sum(1)
        B = 2 * (o * d).sum(1)
        Cq = (o * o).sum(1) - 1
        tb = (-B + np.sqrt(np.maximum(B * B - 4 * A * Cq, 0))) / (2 * A)
        p = o + tb[:, None] * d
        nw = -mm(p, bowl.M)
        nw /= np.linalg.norm(nw, axis=1)[:, None]
        buf.t[ii], buf.n[ii], buf.ident[ii] = tb, nw, bowl.ident


def render(view: _View, sc: Scene) -> _Buffers:
    buf = _Buffers.empty(view.h * view.w)
    _cast_ground(view, buf, sc)
    _cast_polyhedra(view, buf, sc)
    _cast_ellipsoids(view, buf, sc)
    for tb in sc.tubes:
        _cast_tube(view, buf, tb)
    return buf
