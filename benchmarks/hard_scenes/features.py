"""What the plan puts into the rubble: openings (access holes, slits, debris-filled openings),
mounds, ledges, puddles, tarps, stains, and boxes (metal sheets, steep slabs, slabs that
overhang a hole)."""

from __future__ import annotations

import cv2
import numpy as np
from shapes import rect, smooth_noise
from terrain import SLAB
from world import MAT_DEBRIS, MAT_METAL, MAT_PLASTIC, MAT_SLAB, MAT_WATER, NONE, Box, Grid

STAGE = {
    "mound": 0,
    "ledge": 0,
    "no_return_puddle": 1,
    "no_return_plastic": 1,
    "stain": 1,
    "hole": 2,
    "slit": 2,
    "filled_opening": 2,
    "no_return_metal": 3,
    "steep_slab": 3,
}
OPENINGS = ("hole", "slit", "filled_opening")


def apply_features(grid: Grid, rng: np.random.Generator, feats: list[dict]):
    """Build every feature into ``grid``; returns (boxes, openings by feature id)."""
    boxes: list[Box] = []
    openings: dict[int, dict] = {}
    for f in sorted(feats, key=lambda f: (STAGE[f["kind"]], f["id"])):
        kind = f["kind"]
        if kind in OPENINGS:
            op = carve_opening(grid, rng, f)
            if op is not None:
                openings[f["id"]] = op
                if f.get("occluder"):
                    boxes.append(occluding_slab(grid, f, op))
        elif kind == "mound":
            add_mound(grid, rng, f)
        elif kind == "ledge":
            add_ledge(grid, rng, f)
        elif kind == "no_return_puddle":
            add_puddle(grid, rng, f)
        elif kind == "no_return_plastic":
            add_tarp(grid, rng, f)
        elif kind == "stain":
            add_stain(grid, rng, f)
        elif kind == "no_return_metal":
            boxes.append(resting_sheet(grid, rng, f))
        elif kind == "steep_slab":
            boxes.append(steep_slab(grid, f))
    return boxes, openings


def _noise(rng, shape, size_m: float, cell: float):
    return smooth_noise(rng, shape, size_m / cell) if min(shape) > 0 else np.zeros(shape)


def carve_opening(grid: Grid, rng, f: dict) -> dict | None:
    """Cut an opening: T = NONE inside, a floor (or none) below, maybe a lip and a cavity."""
    poly, fid = f["poly"], f["id"]
    cav, lip = f.get("cavity", 0.0), f.get("lip", 0.0)
    sl, X, Y, m = grid.poly_window(poly, max(cav, lip, 0.2) + 0.1)
    if not m.any():
        return None
    cell = grid.cell
    dist = cv2.distanceTransform((~m).astype(np.uint8), cv2.DIST_L2, 5) * cell
    ring = ~m & (dist <= 0.15)
    T = grid.T[sl]
    xc, yc = (float(v) for v in poly.mean(0))
    A = np.stack([np.ones(int(ring.sum())), X[ring] - xc, Y[ring] - yc], 1)
    z0, gx, gy = np.linalg.lstsq(A, T[ring].astype(float), rcond=None)[0]
    g = np.hypot(gx, gy)
    if g > 0.25:
        gx, gy = gx * 0.25 / g, gy * 0.25 / g
    plane = (z0 + gx * (X - xc) + gy * (Y - yc)).astype(np.float32)
    if lip > 0:
        lz = ~m & (dist <= lip)
        T[lz] = plane[lz] + 0.008 * _noise(rng, T.shape, 0.05, cell)[lz]
        tint = np.array(SLAB) * rng.uniform(0.85, 1.15)
        grid.albedo[sl][lz] = tint * (1 + 0.08 * _noise(rng, T.shape, 0.1, cell))[lz][:, None]
    floor = f.get("floor", "void")
    if floor == "debris":
        fv = (
            plane
            - f["depth"]
            + 0.05 * _noise(rng, T.shape, 0.12, cell)
            + 0.02 * _noise(rng, T.shape, 0.04, cell)
        )
        fv = np.minimum(fv, plane - 0.35)
    elif floor == "fill":
        fv = (
            plane
            - f["fill_depth"]
            + 0.012 * _noise(rng, T.shape, 0.08, cell)
            + 0.008 * _noise(rng, T.shape, 0.03, cell)
        )
        fv = np.clip(fv, plane - 0.2, plane - 0.04)
    else:
        fv = np.full(T.shape, NONE, np.float32)
    ext = m.copy()
    if cav > 0:
        ext |= dist <= cav
        under = ext & ~m
        grid.B[sl][under] = T[under] - f["thickness"]
        if floor != "void":
            fv = np.where(under, np.minimum(fv, grid.B[sl] - 0.1), fv)
    grid.F[sl][ext] = fv[ext]
    T[m] = NONE
    grid.open_id[sl][m] = fid
    grid.obj_floor[sl][ext] = fid
    grid.mat_floor[sl][ext] = MAT_DEBRIS
    if floor != "void":
        dark = np.array((0.30, 0.27, 0.23)) * rng.uniform(0.8, 1.3)
        tex = 1 + 0.2 * _noise(rng, T.shape, 0.05, cell) + 0.1 * _noise(rng, T.shape, 0.015, cell)
        grid.albedo[sl][ext] = np.clip(dark * tex[ext][:, None], 0.02, 0.8)
    return {
        "id": fid,
        "kind": f["kind"],
        "poly": poly,
        "plane": (float(z0), float(gx), float(gy), xc, yc),
    }


def rim_z(op: dict, x, y):
    z0, gx, gy, xc, yc = op["plane"]
    return z0 + gx * (np.asarray(x) - xc) + gy * (np.asarray(y) - yc)


def add_mound(grid: Grid, rng, f: dict) -> None:
    x, y, R, H = f["x"], f["y"], f["R"], f["H"]
    sl, X, Y = grid.window((x - 1.7 * R, y - 1.7 * R), (x + 1.7 * R, y + 1.7 * R))
    c, s = np.cos(f["angle"]), np.sin(f["angle"])
    u, v = (X - x) * c + (Y - y) * s, -(X - x) * s + (Y - y) * c
    r = np.hypot(u / R, v / (R * f["aniso"])) * (1 + 0.12 * _noise(rng, X.shape, 0.3, grid.cell))
    bump = H * np.exp(-(r ** f["p"]))
    bump *= 1 + 0.08 * _noise(rng, X.shape, 0.07, grid.cell)
    grid.T[sl] += bump.astype(np.float32)
    grid.obj_top[sl][bump > 0.25 * H] = f["id"]


def add_ledge(grid: Grid, rng, f: dict) -> None:
    sl, X, Y, m = grid.poly_window(f["poly"], 0.1)
    soft = cv2.GaussianBlur(m.astype(np.float32), (0, 0), 1.2)
    x, y = f["poly"].mean(0)
    gx, gy = rng.normal(0, 0.06, 2)
    top = f["H"] + gx * (X - x) + gy * (Y - y) + 0.02 * _noise(rng, X.shape, 0.1, grid.cell)
    grid.T[sl] += (soft * top).astype(np.float32)
    grid.obj_top[sl][m] = f["id"]
    grid.albedo[sl][m] = grid.albedo[sl][m] * 0.5 + np.array(SLAB) * rng.uniform(0.4, 0.6)


def add_puddle(grid: Grid, rng, f: dict) -> None:
    sl, X, _, m = grid.poly_window(f["poly"])
    if not m.any():
        return
    T = grid.T[sl]
    level = np.float32(np.percentile(T[m], rng.uniform(65, 88)))
    water = m & (level >= T)
    T[water] = level
    grid.mat_top[sl][water] = MAT_WATER
    grid.obj_top[sl][m] = f["id"]
    murk = np.array((0.30, 0.27, 0.22)) * rng.uniform(0.8, 1.4)
    tex = 1 + 0.15 * _noise(rng, X.shape, 0.08, grid.cell)
    grid.albedo[sl][water] = murk * tex[water][:, None]


TARP_COLOURS = (
    (0.08, 0.22, 0.62),
    (0.85, 0.33, 0.06),
    (0.80, 0.80, 0.78),
    (0.15, 0.40, 0.18),
    (0.62, 0.63, 0.66),
)


def add_tarp(grid: Grid, rng, f: dict) -> None:
    sl, X, Y, m = grid.poly_window(f["poly"], 0.1)
    if not m.any():
        return
    T = grid.T[sl]
    sm = cv2.GaussianBlur(T, (0, 0), 0.06 / grid.cell)
    a = rng.uniform(0, np.pi)
    lam = rng.uniform(0.15, 0.4)
    ph = (X * np.cos(a) + Y * np.sin(a)) * 2 * np.pi / lam
    ph += 2 * _noise(rng, X.shape, 0.4, grid.cell)
    folds = 0.025 * np.sin(ph) * (0.5 + 0.5 * _noise(rng, X.shape, 0.5, grid.cell))
    T[m] = (np.maximum(sm, T - 0.03) + 0.012 + folds)[m]
    grid.mat_top[sl][m] = MAT_PLASTIC
    grid.obj_top[sl][m] = f["id"]
    colour = np.array(TARP_COLOURS[f["colour"]])
    tex = 1 + 0.06 * _noise(rng, X.shape, 0.2, grid.cell) + 0.15 * np.cos(ph)
    grid.albedo[sl][m] = np.clip(colour * tex[m][:, None], 0.02, 0.95)


def add_stain(grid: Grid, rng, f: dict) -> None:
    sl, X, _, m = grid.poly_window(f["poly"], 0.1)
    soft = cv2.GaussianBlur(m.astype(np.float32), (0, 0), 0.03 / grid.cell)
    soft *= np.clip(0.75 + 0.35 * _noise(rng, X.shape, 0.12, grid.cell), 0, 1)
    k = (f["strength"] * soft)[..., None]
    tint = np.array(f["tint"])
    grid.albedo[sl] = grid.albedo[sl] * (1 - k + 0.1 * tint * k)  # x 0.1-0.5 where full
    grid.stain[sl][soft > 0.4] = f["id"]


def resting_sheet(grid: Grid, rng, f: dict) -> Box:
    """A thin metal sheet lying on the rubble (resting on its highest points)."""
    x, y, L, W, yaw, thk = f["x"], f["y"], f["L"], f["W"], f["yaw"], 0.012
    sl, X, Y, m = grid.poly_window(rect((x, y), L, W, yaw))
    gx, gy = f["slope"]
    T = grid.T[sl]
    ok = m & (T > NONE + 1)
    z0 = float(np.max(T[ok] - gx * (X[ok] - x) - gy * (Y[ok] - y))) + 0.004 if ok.any() else 0.0
    n = np.array([-gx, -gy, 1.0])
    n /= np.linalg.norm(n)
    e1 = np.array([np.cos(yaw), np.sin(yaw), gx * np.cos(yaw) + gy * np.sin(yaw)])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    grey = rng.uniform(0.35, 0.6)
    return Box(
        np.array([x, y, z0]) + n * thk / 2,
        np.stack([e1, e2, n], 1),
        np.array([L / 2, W / 2, thk / 2]),
        MAT_METAL,
        (grey, grey, grey * 1.04),
        f["id"],
        "no_return_metal",
        {"corrugation": float(f["corrugation"])},
    )


def steep_slab(grid: Grid, f: dict) -> Box:
    """A broken slab standing steeply out of the rubble, its foot embedded."""
    x, y, L, W, thk, yaw, p = (f[k] for k in ("x", "y", "L", "W", "thk", "yaw", "pitch"))
    hdir = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    e2 = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    e1 = np.cos(p) * hdir + np.array([0, 0, np.sin(p)])
    e3 = np.cross(e1, e2)
    zg = float(grid.bilinear(grid.T, np.array([x]), np.array([y]))[0])
    zg = zg if zg > NONE + 1 else 0.0
    centre = np.array([x, y, zg]) + e1 * (L / 2 - 0.12)
    return Box(
        centre,
        np.stack([e1, e2, e3], 1),
        np.array([L / 2, W / 2, thk / 2]),
        MAT_SLAB,
        tuple(np.array(SLAB) * f["shade"]),
        f["id"],
        "steep_slab",
    )


def occluding_slab(grid: Grid, f: dict, op: dict) -> Box:
    """A slab whose edge lies across a hole, covering ``cover`` of it from above."""
    o = f["occluder"]
    poly = f["poly"]
    c = poly.mean(0)
    u = np.array([np.cos(o["dir"]), np.sin(o["dir"])])
    proj = (poly - c) @ u
    lo, hi = float(proj.min()), float(proj.max())
    s = hi - o["cover"] * (hi - lo)
    E, Fp = c + u * s, c + u * (s + o["L"])
    z_e = float(rim_z(op, E[0], E[1])) + o["clearance"]
    zf = float(grid.bilinear(grid.T, np.array([Fp[0]]), np.array([Fp[1]]))[0])
    z_f = (zf if zf > NONE + 1 else z_e - o["clearance"]) - 0.03
    e1 = np.array([u[0] * o["L"], u[1] * o["L"], z_f - z_e])
    e1 /= np.linalg.norm(e1)
    e2 = np.array([-u[1], u[0], 0.0])
    e3 = np.cross(e1, e2)
    if e3[2] < 0:
        e2, e3 = -e2, -e3
    bottom = (np.array([E[0], E[1], z_e]) + np.array([Fp[0], Fp[1], z_f])) / 2
    centre = bottom + e3 * o["thk"] / 2
    return Box(
        centre,
        np.stack([e1, e2, e3], 1),
        np.array([o["L"] / 2, o["W"] / 2, o["thk"] / 2]),
        MAT_SLAB,
        tuple(np.array(SLAB) * o["shade"]),
        o["id"],
        "occluding_slab",
        {"hole": f["id"]},
    )
