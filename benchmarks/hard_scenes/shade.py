"""Dawn/dusk light and the colour camera.

Radiance = albedo * (low warm sun * n.s * unshadowed + tinted sky * open-sky share) plus, on
water, metal and plastic, a reflection of the sky and the sun's glint. Then a colour camera:
vignetting, a badly set exposure (some frames dark), a colour cast, optics blur, shot and
read noise, gamma, 8 bits.
"""

from __future__ import annotations

import cv2
import numpy as np
from camera import Intrinsics
from raycast import SURF_BOX, SURF_FLOOR, SURF_NONE, SURF_TOP, SURF_UNDER, Hits
from shapes import smooth_noise
from world import MAT_METAL, MAT_PLASTIC, MAT_WATER, Box, Coarse, Grid, sky_visibility

LUMA = np.array([0.2126, 0.7152, 0.0722])


def sun_dir(light: dict) -> np.ndarray:
    el, az = np.radians(light["sun_elevation_deg"]), np.radians(light["sun_azimuth_deg"])
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def sky(light: dict, r: np.ndarray) -> np.ndarray:
    """Sky radiance seen along unit directions r (M, 3); below the horizon, dim ground."""
    zen, hor = np.array(light["zenith_rgb"]), np.array(light["horizon_rgb"])
    m = np.sqrt(np.clip(r[:, 2], 0, 1))[:, None]
    col = hor * (1 - m) + zen * m
    glow = np.clip(r @ sun_dir(light), 0, 1) ** 6
    col = col + glow[:, None] * np.array(light["sun_rgb"]) * (
        0.8 if light["sun_strength"] > 0 else 0.25
    )
    ground = 0.06 * (zen + hor)
    return np.where(r[:, 2:3] < 0, ground, col)


def radiance(
    grid: Grid,
    boxes: list[Box],
    hits: Hits,
    D: np.ndarray,
    light: dict,
    hc: Coarse,
    horizon: Coarse | None,
    rng: np.random.Generator,
) -> np.ndarray:
    n = len(D)
    zen, hor = np.array(light["zenith_rgb"]), np.array(light["horizon_rgb"])
    amb = 0.5 * (zen + hor)
    out = np.tile(amb * 0.004, (n, 1)) * (1 + 0.3 * rng.random((n, 1)))
    hit = np.flatnonzero(hits.surf != SURF_NONE)
    if not hit.size:
        return out
    P, N, surf = hits.pos[hit], hits.normal[hit], hits.surf[hit]
    x, y = P[:, 0], P[:, 1]
    alb = grid.bilinear(grid.albedo, x, y).astype(float)
    mat = np.where(surf == SURF_TOP, grid.nearest(grid.mat_top, x, y), 0).astype(np.int16)
    alb[surf == SURF_UNDER] *= 0.5
    wall = (surf == SURF_TOP) & (N[:, 2] < 0.35)
    alb[wall] *= 0.85
    mat[wall] = 0
    mat[surf == SURF_FLOOR] = 0
    spec_mod = np.ones(len(hit))
    bi = np.flatnonzero(surf == SURF_BOX)
    if bi.size:
        tex = smooth_noise(rng, (256, 256), 6.0) * 0.12 + smooth_noise(rng, (256, 256), 1.0) * 0.05
        rust = smooth_noise(rng, (256, 256), 20.0) > 0.9
        uv = hits.face_uv[hit[bi]]
        iu = (np.floor(uv[:, 0] / 0.01).astype(np.intp)) % 256
        iv = (np.floor(uv[:, 1] / 0.01).astype(np.intp)) % 256
        k = hits.box[hit[bi]]
        base = np.array([boxes[j].albedo for j in range(len(boxes))])[k]
        alb[bi] = base * (1 + tex[iv, iu])[:, None]
        mat[bi] = np.array([b.material for b in boxes])[k]
        corr = np.array([b.extra.get("corrugation", 0.0) for b in boxes])[k]
        wavy = corr > 0
        spec_mod[bi[wavy]] = 0.55 + 0.45 * np.sin(2 * np.pi * uv[wavy, 0] / corr[wavy])
        is_metal = mat[bi] == MAT_METAL
        rusty = is_metal & rust[iv, iu]
        alb[bi[rusty]] = np.array((0.35, 0.17, 0.08)) * (1 + tex[iv[rusty], iu[rusty]])[:, None]
        spec_mod[bi[rusty]] *= 0.3
    s = sun_dir(light)
    Q = P + 0.03 * N  # look-ups a little off the surface: no self-shadowing by the raster
    vis = sky_visibility(hc, Q, rng)
    sky_in = amb * (vis * (0.55 + 0.45 * np.clip(N[:, 2], -1, 1)))[:, None]
    sun_in = np.zeros(len(hit))
    if light["sun_strength"] > 0 and horizon is not None:
        lit = np.clip((Q[:, 2] - horizon.bilinear(Q[:, 0], Q[:, 1])) / 0.04 + 0.5, 0, 1)
        sun_in = light["sun_strength"] * np.clip(N @ s, 0, None) * lit
    else:
        lit = np.zeros(len(hit))
    col = alb * (sky_in + sun_in[:, None] * np.array(light["sun_rgb"]))
    # reflections
    V = D[hit]
    R = V - 2 * np.sum(V * N, 1, keepdims=True) * N
    for m_code, refl, rough, shine, keep in (
        (MAT_WATER, 0.45, 0.02, 300, 0.6),
        (MAT_METAL, 0.6, 0.12, 40, 0.5),
        (MAT_PLASTIC, 0.12, 0.05, 60, 1.0),
    ):
        sel = np.flatnonzero(mat == m_code)
        if not sel.size:
            continue
        r = R[sel] + rng.normal(0, rough, (sel.size, 3))
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        k = refl * spec_mod[sel] * np.sqrt(vis[sel])
        glint = light["sun_strength"] * 2.0 * np.clip(r @ s, 0, 1) ** shine * lit[sel]
        col[sel] = (
            col[sel] * keep
            + k[:, None] * sky(light, r)
            + glint[:, None] * np.array(light["sun_rgb"]) * spec_mod[sel, None]
        )
    out[hit] = col
    return out


def develop(rng: np.random.Generator, lin: np.ndarray, light: dict, intr: Intrinsics):
    """Linear radiance (H, W, 3) -> 8-bit RGB as a cheap camera would record it at dawn."""
    H, W = lin.shape[:2]
    yy, xx = np.mgrid[0:H, 0:W]
    r2 = ((xx - intr.cx) / (W / 2)) ** 2 + ((yy - intr.cy) / (H / 2)) ** 2
    lin = lin * (1 - rng.uniform(0.05, 0.3) * r2 / 2)[..., None]
    med = float(np.percentile(lin @ LUMA, 50))
    gain = light["exposure_target"] ** 2.2 / max(med, 1e-6)
    img = (lin * gain * np.array(light["colour_gains"])).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.45, 0.9))
    dark = light["dark_frame"]
    shot = rng.uniform(0.002, 0.006) * (2.5 if dark else 1.0)
    read = rng.uniform(0.002, 0.005) * (2.0 if dark else 1.0)
    img = img + rng.standard_normal(img.shape).astype(np.float32) * np.sqrt(
        np.clip(img, 0, None) * shot + read * read
    )
    img = np.clip(img, 0, 1) ** (1 / 2.2)
    return np.round(img * 255).astype(np.uint8)
