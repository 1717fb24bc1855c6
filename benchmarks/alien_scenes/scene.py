"""Alien scenes: sampling one scene."""

from __future__ import annotations

import math

import cv2
import numpy as np

from alien_scenes.builder import Builder
from alien_scenes.common import (
    F64,
    F_PAD,
    CameraModel,
    perp_basis,
    pick,
    resting_rotation,
    rot,
    rz,
)
from alien_scenes.raycast import Grid
from alien_scenes.sampling import LIB_BOX, camera_rotation, footprint, rubble_piece
from alien_scenes.shapes import Scene, Shape, Stain


def sample_scene(rng: np.random.Generator, cam: CameraModel, lib: list[Shape]) -> Scene:
    """Draw one scene: site, camera pose, light, holes, distractors and rubble."""
    b = Builder(rng, cam, lib)
    slope, saz = math.radians(rng.uniform(0, 10)), rng.uniform(0, 2 * math.pi)
    up = np.array(
        [math.sin(slope) * math.cos(saz), math.sin(slope) * math.sin(saz), math.cos(slope)]
    )
    height = rng.uniform(2.0, 3.5)  # camera height above the rubble surface, m
    tilt = rng.uniform(0, 20)
    R = camera_rotation(
        up, math.radians(tilt), rng.uniform(0, 2 * math.pi), math.radians(rng.normal(0, 1.5))
    )
    z_axis = R[:, 2]
    C = (height + 0.3) * up[2] / z_axis[2] * z_axis
    b.C, b.R = C, R
    foot = footprint(cam, C, R)
    b.foot = foot
    # light: a low dawn sun (or none yet) and a bluish sky
    sun: F64 | None = None
    sun_h = np.zeros(2)
    elev = -3.0
    hx, _ = perp_basis(up)
    h = rot(up, rng.uniform(0, 2 * math.pi)) @ hx
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
    g = Grid(lo[0], lo[1], hi[0], hi[1])
    b.grid = g
    fm = np.zeros((g.ny, g.nx), np.uint8)
    cv2.fillPoly(fm, [np.round(g.px(foot) * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    dist = cv2.distanceTransform(1 - fm, cv2.DIST_L2, 5)
    g.region[:] = dist * g.res <= margin
    # access holes, then distractors
    n_access = int(rng.choice(4, p=[0.12, 0.45, 0.29, 0.14]))
    for _ in range(n_access):
        kind = pick(rng, ["irregular", "gap", "pipe", "rect"], [0.4, 0.25, 0.2, 0.15])
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
                Stain(c, ax, rng.uniform(0, math.pi), rng.uniform(0.35, 0.8), rng.uniform() < 0.3)
            )
            b.count("stain")
    # big pieces: mounds, slabs, shadow-casting walls beyond the view
    for _ in range(int(rng.integers(0, 4))):
        b.add_mound(b.random_region_point())
    for _ in range(int(rng.integers(0, 5))):
        dims = np.array([rng.uniform(1, 2.8), rng.uniform(0.8, 2.2), rng.uniform(0.1, 0.3)])
        for _try in range(10):
            if b.add_resting(
                LIB_BOX, dims, resting_rotation(rng, 18), b.random_region_point(), "concrete", 0.2
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
            if b.add_resting(LIB_BOX, dims, rz(yaw), p, pick(rng, ["concrete", "brick"]), 0.1):
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
        shape, dims, Rr, mat, embed = rubble_piece(b.rng, len(b.lib))
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
    return Scene(
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
