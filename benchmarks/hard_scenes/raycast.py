"""Ray casting: analytic boxes, then an adaptive march through the layered height field.

The march steps along each ray while the ray stays above an envelope (the highest matter
within one step, a max filter of max(T, F)), with steps from 1 m down to 1.5 cm; where
it may dip into matter it applies the exact solid test and refines the crossing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from camera import Intrinsics, project
from scipy.ndimage import maximum_filter, minimum_filter
from world import NONE, Box, Grid, clamp

LEVELS = (1.0, 0.32, 0.08, 0.03, 0.015)  # ray steps (m), coarse to fine
Z_BOTTOM = -2.0  # rays that get this low have fallen into a void: nothing more to see
SURF_NONE, SURF_TOP, SURF_FLOOR, SURF_UNDER, SURF_BOX = range(5)


@dataclass
class Hits:
    t: np.ndarray  # (N,) distance along the unit ray, inf = nothing
    surf: np.ndarray  # (N,) SURF_*
    box: np.ndarray  # (N,) box index or -1
    pos: np.ndarray  # (N, 3)
    normal: np.ndarray  # (N, 3)
    face_uv: np.ndarray  # (N, 2) box face coordinates (m), for textures


def intersect_boxes(boxes: list[Box], intr: Intrinsics, R, C, dirs):
    n = len(dirs)
    t = np.full(n, np.inf)
    which = np.full(n, -1, np.int32)
    normal = np.zeros((n, 3))
    uv = np.zeros((n, 2))
    for k, b in enumerate(boxes):
        u, v, z = project(intr, R, C, b.corners())
        if np.any(z <= 0.05):
            sub = np.arange(n)
        else:
            u0, u1 = max(0, int(np.floor(u.min())) - 1), min(intr.width, int(np.ceil(u.max())) + 2)
            v0, v1 = max(0, int(np.floor(v.min())) - 1), min(intr.height, int(np.ceil(v.max())) + 2)
            if u0 >= u1 or v0 >= v1:
                continue
            vv, uu = np.mgrid[v0:v1, u0:u1]
            sub = (vv * intr.width + uu).ravel()
        o = (C - b.centre) @ b.axes
        d = dirs[sub] @ b.axes
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            t1 = (-b.half - o) * inv
            t2 = (b.half - o) * inv
        t1 = np.nan_to_num(t1, nan=-np.inf)
        t2 = np.nan_to_num(t2, nan=np.inf)
        lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
        tn, tf = lo.max(1), hi.min(1)
        hit = (tn <= tf) & (tn > 0) & (tn < t[sub])
        if not hit.any():
            continue
        s = sub[hit]
        ax = lo[hit].argmax(1)
        t[s] = tn[hit]
        which[s] = k
        sign = -np.sign(d[hit, ax])
        normal[s] = sign[:, None] * b.axes[:, ax].T
        local = o + tn[hit, None] * d[hit]
        others = np.array([[1, 2], [0, 2], [0, 1]])[ax]
        uv[s] = np.take_along_axis(local, others, 1)
    return t, which, normal, uv


def _refine(grid: Grid, C, d, lo, hi):
    """Crossing between lo (outside) and hi (inside): secant on the top of the matter where
    no sheet has an underside there (matter is z <= max(T, F)) or onto a sheet's top,
    bisection elsewhere."""
    xl, yl, zl = C[0] + lo * d[:, 0], C[1] + lo * d[:, 1], C[2] + lo * d[:, 2]
    xh, yh, zh = C[0] + hi * d[:, 0], C[1] + hi * d[:, 1], C[2] + hi * d[:, 2]
    tl, fl_, bl, _ = grid.surfaces(xl, yl)
    th, fh_, bh, _ = grid.surfaces(xh, yh)
    fl = zl - np.maximum(tl, fl_)
    fh = zh - np.maximum(th, fh_)
    sec = (bl <= NONE) & (bh <= NONE) & (fl > 0) & (fh <= 0)
    top = ~sec & (zh >= bh) & (zl > tl) & (zh <= th)  # onto the top of a sheet with an underside
    fl[top], fh[top] = zl[top] - tl[top], zh[top] - th[top]
    sec |= top
    out = hi.copy()
    out[sec] = lo[sec] + (hi[sec] - lo[sec]) * fl[sec] / (fl[sec] - fh[sec])
    b = np.flatnonzero(~sec)
    if b.size:
        out[b] = _bisect(grid, C, d[b], lo[b], hi[b])
    return out


def _bisect(grid: Grid, C, d, lo, hi):
    for _ in range(4):
        mid = 0.5 * (lo + hi)
        ins = grid.solid(C[0] + mid * d[:, 0], C[1] + mid * d[:, 1], C[2] + mid * d[:, 2])
        hi = np.where(ins, mid, hi)
        lo = np.where(ins, lo, mid)
    return hi


def _span(idx: np.ndarray, pad: int, n: int) -> tuple[int, int]:
    return max(0, int(idx[0]) - pad), min(n, int(idx[-1]) + pad + 1)


def _envelopes(grid: Grid, U, radii):
    """Per radius: highest matter (ET), highest matter reachable from below every sheet's
    underside (EL: floors, and tops of plain columns), lowest underside (BM); flattened.
    Away from sheets EL is ET and BM is out of reach, so those two are filtered only in the
    window around the sheets."""
    sheet = grid.B > NONE
    ET, EL, BM = [], [], []
    rows, cols = np.nonzero(sheet.any(1))[0], np.nonzero(sheet.any(0))[0]
    for r in radii:
        size = 2 * r + 1
        et = maximum_filter(U, size=size, mode="nearest")
        el, bm = et.copy(), np.full(U.shape, np.float32(1e3))
        if rows.size:  # filter a window with room for the filter, keep its inner part
            i0, i1 = _span(rows, 2 * r + 2, U.shape[0])
            j0, j1 = _span(cols, 2 * r + 2, U.shape[1])
            k0, k1 = _span(rows, r + 1, U.shape[0])
            l0, l1 = _span(cols, r + 1, U.shape[1])
            s, u = sheet[i0:i1, j0:j1], U[i0:i1, j0:j1]
            e = maximum_filter(np.where(s, grid.F[i0:i1, j0:j1], u), size=size, mode="nearest")
            b = np.where(s, grid.B[i0:i1, j0:j1], np.float32(1e3))
            b = minimum_filter(b, size=size, mode="nearest")
            el[k0:k1, l0:l1] = e[k0 - i0 : k1 - i0, l0 - j0 : l1 - j0]
            bm[k0:k1, l0:l1] = b[k0 - i0 : k1 - i0, l0 - j0 : l1 - j0]
        ET.append(et.ravel())
        EL.append(el.ravel())
        BM.append(bm.ravel())
    return np.concatenate(ET), np.concatenate(EL), np.concatenate(BM)


def march(grid: Grid, C, D, t_limit):
    """Distance to the height field's matter along each ray (inf: none before t_limit).

    Adaptive stepping: a ray advances by LEVELS[k] while it stays above envelope k (the
    highest matter it could meet within that step); when it would not, it drops to the next
    finer level (within the same pass); at the finest level the end of every unsafe step gets
    the exact solid test, and a crossing is refined. Two safe steps in a row go back up a
    level.
    """
    U = np.maximum(grid.T, grid.F)
    hmax = float(np.max(np.hypot(D[:, 0], D[:, 1])))
    radii = [int(np.ceil(s * hmax / grid.cell)) + 1 for s in LEVELS] + [1]
    ET, EL, BM = _envelopes(grid, U, radii)
    ncell, nx, ny = U.size, grid.nx, grid.ny
    pt = len(LEVELS) * ncell  # offset of the point-test bounds
    steps = np.array(LEVELS, np.float32)
    fine = len(LEVELS) - 1
    f32 = np.float32
    inv = 1.0 / grid.cell
    t0 = (C[2] - (float(U.max()) + 0.02)) / -D[:, 2]
    t_end_all = np.minimum((C[2] - Z_BOTTOM) / -D[:, 2], t_limit)
    idx = np.flatnonzero(t0 < t_end_all)
    # ray state, float32: t, grid-unit direction (ax, ay), dz, end
    t, t_end = t0[idx].astype(f32), t_end_all[idx].astype(f32)
    ax, ay = (D[idx, 0] * inv).astype(f32), (D[idx, 1] * inv).astype(f32)
    dz = D[idx, 2].astype(f32)
    bx, by = f32((C[0] - grid.x0) * inv + 0.5), f32((C[1] - grid.y0) * inv + 0.5)
    cz = f32(C[2])
    lev = np.zeros(idx.size, np.int8)
    run = np.zeros(idx.size, np.int8)
    t_hit = np.full(len(D), np.inf)
    while idx.size:
        ix = clamp((bx + t * ax).astype(np.int32), 0, nx - 1)
        iy = clamp((by + t * ay).astype(np.int32), 0, ny - 1)
        cell = iy * nx + ix
        zt = cz + t * dz
        safe = np.zeros(idx.size, bool)
        todo = np.arange(idx.size)
        while True:  # the coarsest safe level at or below each ray's current one
            lv = lev[todo]
            ci = lv * np.int64(ncell) + cell[todo]
            zq = zt[todo] + steps[lv] * dz[todo]
            ok = zq > ET[ci]
            u = np.flatnonzero(~ok)
            if u.size:  # below every sheet's underside around: only floors and walls count
                cu = ci[u]
                ok[u] = (zt[todo[u]] < BM[cu]) & (zq[u] > EL[cu])
            safe[todo[ok]] = True
            todo = todo[~ok & (lv < fine)]
            if not todo.size:
                break
            lev[todo] += 1
        tn = t + steps[lev]
        zn = cz + tn * dz
        hit = np.zeros(idx.size, bool)
        at_fine = lev == fine
        test = np.flatnonzero(~safe & at_fine)
        if test.size:
            tt = tn[test]
            gx, gy, zt = bx + tt * ax[test], by + tt * ay[test], zn[test]
            cj = pt + (
                clamp(gy.astype(np.int32), 0, ny - 1) * np.int64(nx)
                + clamp(gx.astype(np.int32), 0, nx - 1)
            )
            pre = np.flatnonzero((zt <= ET[cj]) & ~((zt < BM[cj]) & (zt > EL[cj])))
            if pre.size:
                tp = tt[pre].astype(float)
                j = test[pre]
                hit[j] = grid.solid(
                    C[0] + tp * ax[j] * grid.cell, C[1] + tp * ay[j] * grid.cell, C[2] + tp * dz[j]
                )
        if hit.any():
            h = np.flatnonzero(hit)
            d = D[idx[h]]
            t_hit[idx[h]] = _refine(grid, C, d, t[h].astype(float), tn[h].astype(float))
        t = np.where(safe | (at_fine & ~hit), tn, t)
        run = np.where(safe, run + 1, 0).astype(np.int8)
        up = (run >= 2) & (lev > 0)
        lev[up] -= 1
        run[up] = 0
        keep = ~hit & (t < t_end)
        if not keep.all():
            idx, t, t_end, ax, ay, dz, lev, run = (
                a[keep] for a in (idx, t, t_end, ax, ay, dz, lev, run)
            )
    t_hit[t_hit > t_limit] = np.inf
    return t_hit


def cast(grid: Grid, boxes: list[Box], intr: Intrinsics, R, C, D) -> Hits:
    tb, which, nb, uvb = intersect_boxes(boxes, intr, R, C, D)
    th = march(grid, C, D, tb)
    n = len(D)
    surf = np.full(n, SURF_NONE, np.int8)
    t = np.minimum(th, tb)
    pos = C + np.where(np.isfinite(t), t, 0.0)[:, None] * D
    normal = np.zeros((n, 3))
    normal[:, 2] = 1.0
    is_box = np.isfinite(tb) & (tb <= th)
    surf[is_box] = SURF_BOX
    normal[is_box] = nb[is_box]
    hf = np.flatnonzero(np.isfinite(th) & ~is_box)
    if hf.size:
        x, y, z = pos[hf, 0], pos[hf, 1], pos[hf, 2]
        tv, fv, bv, _ = grid.surfaces(x, y)
        dist = np.stack([np.abs(z - tv), np.abs(z - fv), np.abs(z - bv)], 1)
        which_s = dist.argmin(1)
        surf[hf] = np.array([SURF_TOP, SURF_FLOOR, SURF_UNDER], np.int8)[which_s]
        nrm = np.zeros((hf.size, 3))
        for s_code, name in ((0, "T"), (1, "F")):
            m = which_s == s_code
            if m.any():
                nrm[m] = grid.normals(name, x[m], y[m])
        nrm[which_s == 2] = (0.0, 0.0, -1.0)
        normal[hf] = nrm
    return Hits(t, surf, np.where(is_box, which, -1), pos, normal, uvb)
