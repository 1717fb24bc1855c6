"""What the Xtion makes of a perfect image: depth noise, quantisation, dropouts, colour noise.

Random numbers come from the simulators' xorshift64* stream (:mod:`holescan.sim._xorshift`).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import numpy.typing as npt
from numba import njit

from holescan.sim._camera_model import XTION_NOISE_COEFF_PER_MM, Conditions
from holescan.sim._xorshift import normal as _normal
from holescan.sim._xorshift import normal_table as _normal_table
from holescan.sim._xorshift import stream_state as _state
from holescan.sim._xorshift import uniform as _uniform

__all__ = ["colour_image", "depth_image"]

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]
U16 = npt.NDArray[np.uint16]
U64 = npt.NDArray[np.uint64]


@functools.cache
def _gamma_lut() -> U8:
    x = np.arange(65536, dtype=np.float64) / 65535.0
    return np.round(255.0 * x ** (1.0 / 2.2)).astype(np.uint8)


@njit(cache=True)
def _depth(
    depth_m: F32,
    state: U64,
    table: F64,
    fx: float,
    baseline_mm: float,
    noise_scale: float,
    step_px: float,
    min_mm: float,
    fade_mm: float,
    max_mm: float,
    p_drop: float,
) -> U16:
    height, width = depth_m.shape
    out = np.zeros((height, width), dtype=np.uint16)
    fb = fx * baseline_mm  # disparity (px) = fb / Z (mm)
    # Noise sigma = coeff Z^2 in all; quantisation (step q = Z^2 step_px / fb) contributes
    # q^2 / 12 of the variance, also ~Z^4, so the added noise is a fixed fraction of it.
    quantise = fb > 0.0 and step_px > 0.0
    sig_coeff = noise_scale * XTION_NOISE_COEFF_PER_MM
    fb_steps = 0.0
    if quantise:
        fb_steps = fb / step_px
        var = sig_coeff * sig_coeff - (step_px / fb) ** 2 / 12.0
        sig_coeff = math.sqrt(var) if var > 0.0 else 0.0
    for v in range(height):
        # Projector shadow: the projector sits at +x, so a point is hidden from it when a
        # pixel to its right maps to a smaller projector column u - fb / Z.
        run_min = 1e30
        for u in range(width - 1, -1, -1):
            z = depth_m[v, u] * 1000.0
            if z <= 0.0:
                continue
            if fb > 0.0:
                up = u - fb / z
                if up > run_min:
                    continue
                run_min = up
            if z < min_mm or z > max_mm:
                continue
            if z > fade_mm and _uniform(state) < (z - fade_mm) / (max_mm - fade_mm):
                continue
            if p_drop > 0.0 and _uniform(state) < p_drop:
                continue
            z = z + sig_coeff * z * z * _normal(state, table)
            if quantise:
                if z <= 0.0:
                    continue
                n_steps = math.floor(fb_steps / z + 0.5)  # disparity in steps of step_px
                if n_steps <= 0:
                    continue
                z = fb_steps / n_steps
            if z < min_mm or z > max_mm:
                continue
            out[v, u] = np.uint16(min(int(z + 0.5), 65535))
    return out


@njit(cache=True)
def _colour(
    rad: F32,
    state: U64,
    table: F64,
    lut: U8,
    gain_r: float,
    gain_g: float,
    gain_b: float,
    vignetting: float,
    read_noise: float,
    shot_noise: float,
    cx: float,
    cy: float,
) -> U8:
    height, width = rad.shape[0], rad.shape[1]
    out = np.empty((height, width, 3), dtype=np.uint8)
    r_norm = 1.0 / (cx * cx + cy * cy)
    read2 = read_noise * read_noise
    shot2 = shot_noise * shot_noise
    noisy = read2 > 0.0 or shot2 > 0.0
    for v in range(height):
        dv = (v - cy) * (v - cy)
        for u in range(width):
            vig = 1.0 - vignetting * ((u - cx) * (u - cx) + dv) * r_norm
            sr = rad[v, u, 0] * gain_r * vig
            sg = rad[v, u, 1] * gain_g * vig
            sb = rad[v, u, 2] * gain_b * vig
            if noisy:
                sr += math.sqrt(read2 + shot2 * max(sr, 0.0)) * _normal(state, table)
                sg += math.sqrt(read2 + shot2 * max(sg, 0.0)) * _normal(state, table)
                sb += math.sqrt(read2 + shot2 * max(sb, 0.0)) * _normal(state, table)
            out[v, u, 0] = lut[int(min(max(sr, 0.0), 1.0) * 65535.0 + 0.5)]
            out[v, u, 1] = lut[int(min(max(sg, 0.0), 1.0) * 65535.0 + 0.5)]
            out[v, u, 2] = lut[int(min(max(sb, 0.0), 1.0) * 65535.0 + 0.5)]
    return out


def depth_image(depth_m: F32, fx: float, conditions: Conditions, rng: np.random.Generator) -> U16:
    """The Xtion's reading of an exact depth image.

    depth_m : (H, W) float32, metres along the optical axis, 0 = nothing there.
    Returns (H, W) uint16, millimetres, 0 = no reading.
    """
    c = conditions
    return _depth(
        np.ascontiguousarray(depth_m, dtype=np.float32),
        _state(rng),
        _normal_table(),
        float(fx),
        1000.0 * c.baseline_m,
        c.depth_noise,
        c.disparity_step_px,
        1000.0 * c.min_range_m,
        1000.0 * min(c.fade_range_m, c.max_range_m),
        1000.0 * c.max_range_m,
        c.dropout_fraction,
    )


def colour_image(
    radiance: F32, cx: float, cy: float, conditions: Conditions, rng: np.random.Generator
) -> U8:
    """8-bit RGB from linear scene radiance (H, W, 3) float32: exposure, noise, gamma."""
    c = conditions
    wb = c.white_balance
    return _colour(
        np.ascontiguousarray(radiance, dtype=np.float32),
        _state(rng),
        _normal_table(),
        _gamma_lut(),
        c.exposure * wb[0],
        c.exposure * wb[1],
        c.exposure * wb[2],
        c.vignetting,
        c.read_noise,
        c.shot_noise,
        float(cx),
        float(cy),
    )
