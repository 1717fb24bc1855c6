"""Asus Xtion Pro depth: what the structured-light sensor would report for the true Z.

Two models. :func:`structured_light` (the default) is the project's measured model
(``holescan.sim.structured_light``, validated against real Kinect-v1 frames in
``docs/sensor-model.md``), fed with this generator's surfaces: no return from water, metal
and plastic, and soot/char/wet stains that swallow 55-76 % of the pattern.
:func:`xtion_depth` (``--sensor basic``) is this generator's own earlier model:

- no reading beyond the scene's range cut-off (3.5-4.5 m) or nearer than 0.5 m, nor from
  sheet metal, water or glossy plastic (no infrared return; a few speckles do return);
- axial noise sigma = 1.425e-6 Z^2 (Z in mm; Khoshelham & Elberink 2012), a weak
  low-frequency wobble, then disparity quantised to 1/8 pixel (baseline 75 mm);
- projector shadow: a pixel the projector cannot see (something nearer on its +x side)
  has no reading; dropouts at depth edges, at grazing angles, and random speckle holes.
"""

from __future__ import annotations

import cv2
import numpy as np
from camera import BASELINE_M, MIN_RANGE_M, Intrinsics
from shapes import smooth_noise

from holescan.sim.registration_bands import Bands
from holescan.sim.structured_light import (
    SensorCamera,
    StructuredLight,
    Surface,
    random_motion,
    structured_light_frame,
)

#: Fraction of stains that are soot, char or wet (no infrared return over most of them).
ABSORBING_STAIN_P = 0.7


def structured_light(
    rng: np.random.Generator,
    intr: Intrinsics,
    Z: np.ndarray,
    rgb: np.ndarray,
    no_return: np.ndarray,
    stain: np.ndarray,
    max_range: float,
    bands: Bands | None = None,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """True Z (H, W; inf = nothing) -> (uint16 mm depth, motion-blurred RGB, settings);
    ``bands``: the recording's border bands (drawn for this frame alone when None)."""
    unread = np.where(no_return, 0.97, 0.0).astype(np.float32)
    absorbing = {}
    for sid in np.unique(stain[stain > 0]) if np.any(stain > 0) else ():
        if rng.random() < ABSORBING_STAIN_P:
            frac = float(rng.uniform(0.55, 0.76))
            unread[stain == sid] = np.maximum(unread[stain == sid], frac)
            absorbing[int(sid)] = round(frac, 3)
    finite = np.isfinite(Z)
    centre = float(np.median(Z[finite])) if finite.any() else 2.5
    motion = random_motion(rng, intr.fx, centre)
    params = StructuredLight(max_range_m=max_range, fade_range_m=max_range - 0.3)
    cam = SensorCamera(intr.fx, intr.cx, intr.cy)
    fr = structured_light_frame(
        np.where(finite, Z, 0.0),
        rgb,
        cam,
        seed=rng,
        surface=Surface(ir_unread=unread),
        motion=motion,
        params=params,
        bands=bands,
    )
    d = fr.draws
    return (
        fr.depth_mm,
        fr.rgb,
        {
            "bands_ltrb_px": [d.band_left, d.band_top, d.band_right, d.band_bottom],
            "band_profile": d.band_profile,
            "fattening_px": d.fattening_px,
            "flying_fraction": d.flying_fraction,
            "misregistration_px": list(d.shift_px),
            "time_offset_s": d.time_offset_s,
            "velocity_px_s": list(motion.velocity_px_s),
            "exposure_s": motion.exposure_s,
            "absorbing_stains": absorbing,
        },
    )


def projector_shadow(Z: np.ndarray, fb: float) -> np.ndarray:
    """Pixels whose projector ray is blocked by a nearer surface (projector at +x)."""
    W = Z.shape[1]
    with np.errstate(divide="ignore"):
        up = np.arange(W)[None, :] - np.where(np.isfinite(Z), fb / Z, 0.0)
    rev = np.minimum.accumulate(up[:, ::-1], axis=1)[:, ::-1]
    rmin = np.concatenate([rev[:, 1:], np.full((Z.shape[0], 1), np.inf)], axis=1)
    return np.isfinite(Z) & (up > rmin + 0.35)


def depth_edges(Z: np.ndarray) -> np.ndarray:
    z = np.where(np.isfinite(Z), Z, 50.0)
    jump = np.zeros_like(z)
    for ax in (0, 1):
        d = np.abs(np.diff(z, axis=ax))
        pad = [(0, 0), (0, 0)]
        pad[ax] = (1, 0)
        jump = np.maximum(jump, np.pad(d, pad))
        pad[ax] = (0, 1)
        jump = np.maximum(jump, np.pad(d, pad))
    return jump > 0.02 + 0.03 * np.minimum(z, 10)


def blobs(rng, shape, density: float, grow: int) -> np.ndarray:
    """Random small round-ish blobs: seeds grown ``grow`` times with ragged edges."""
    m = (rng.random(shape) < density).astype(np.uint8)
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    for _ in range(grow):
        grown = cv2.dilate(m, disk)
        m = np.maximum(m, grown * (rng.random(shape) < 0.7))
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, disk)
    return m.astype(bool)


def xtion_depth(
    rng: np.random.Generator,
    intr: Intrinsics,
    Z: np.ndarray,
    no_return: np.ndarray,
    cos_inc: np.ndarray,
    max_range: float,
) -> tuple[np.ndarray, dict]:
    """True axial depth Z (H, W; inf = nothing) -> uint16 mm depth image, and its settings."""
    shape = Z.shape
    fb = intr.fx * BASELINE_M
    finite = np.isfinite(Z)
    zf = np.where(finite, Z, max_range + 10)
    p_edge = rng.uniform(0.3, 0.8)
    speck = rng.uniform(0.0001, 0.0008)
    band = int(rng.integers(4, 11) * intr.width / 640) if rng.random() < 0.4 else 0
    valid = finite & (zf >= MIN_RANGE_M) & (zf <= max_range)
    valid &= ~projector_shadow(Z, fb)
    # no infrared return, but a few speckles come back
    back = blobs(rng, shape, rng.uniform(0.001, 0.008), 2)
    valid &= ~no_return | back
    edge = depth_edges(Z)
    edge = (
        cv2.dilate(edge.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        & (rng.random(shape) < 0.35)
        | edge
    )
    valid &= ~(edge & (rng.random(shape) < p_edge))
    valid &= ~(rng.random(shape) < np.clip((0.22 - cos_inc) / 0.17, 0, 1))
    valid &= ~blobs(rng, shape, speck, int(rng.integers(1, 4)))
    if band:
        valid[:, :band] = False
    sigma = 1.425e-6 * (zf * 1000) ** 2 / 1000
    wob = smooth_noise(rng, shape, 40 * intr.width / 640)
    zn = zf + sigma * (rng.standard_normal(shape) + 0.4 * wob)
    zn = np.where(no_return, zn + 3 * sigma * rng.standard_normal(shape), zn)
    disp = np.maximum(np.round(fb / np.maximum(zn, 0.3) * 8) / 8, 1 / 8)
    zq = fb / disp
    out = np.where(valid, np.round(zq * 1000), 0).astype(np.uint16)
    return out, {
        "edge_drop_p": round(float(p_edge), 3),
        "speckle_density": round(float(speck), 5),
        "left_band_px": band,
    }
