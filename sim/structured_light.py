"""What a structured-light depth camera (Asus Xtion / Kinect v1) makes of an ideal frame.

One seeded, pure function, :func:`structured_light_frame`: ideal axial depth, the colour
image, the surfaces' infrared properties, the camera and its motion in; the registered
depth image and the colour image the sensor delivers out, with the frame's random draws
(:class:`FrameDraws`) so that tests and the validation script can check each effect. Every
effect and its size comes from real PrimeSense frames (``docs/sensor-model.md`` compares
the statistics of this model's frames with the real ones):

* **disparity quantised** in 1/8 px (``f b`` with baseline 7.5 cm): depth steps of
  ~11.5 / 18 / 26 mm at 2 / 2.5 / 3 m; axial noise so that noise and rounding together are
  0.8-1.0 x 1.425e-3 Z^2 (m);
* the **projector's shadow** on the LEFT of a nearer surface (the projector is at +x of the
  infrared camera): raw width ~1.2 f b (1/Z_near - 1/Z_far) px, narrower after the depth is
  registered to the colour camera (``registration_baseline_m`` closer);
* the correlation window **fattens** the nearer surface by 1-2 px, and **flying pixels**
  (values between the two plateaus) sit at 1-18 % of the edge crossings;
* **IR dropouts**: surfaces that absorb the pattern (soot, char, wet or black material;
  ``Surface.ir_unread``) lose that fraction of each patch's pixels as on real frames: in
  connected clumps (a field correlated over ~``dropout_clump_px``, ragged at its edges)
  that leave islands of readings on the patch, not scattered specks; grazing surfaces
  (incidence cosine below ~0.1-0.25) lose theirs;
* **RGB-to-depth misregistration** (a 1-4 px shift and ~1 % scale) plus the depth/colour
  **time offset** (up to ~16 ms) times the image motion;
* **unread registration bands** at the frame border, fixed for a recording (the warp of the
  depth onto the colour camera is the device's and the driver's): one :class:`BandProfile`
  per way of registering, drawn per flight or recording with :func:`draw_bands` (Kinect v1
  registered on the host: right 24-45 px, top 8-15, bottom 6-13, left 0-14; OpenNI2's own
  registration, as on an Xtion: left 19-27, right 12-20, top 14-18, bottom 4-8; at 640 px
  wide; :mod:`sim.registration_bands`);
* colour **motion blur** over the exposure (shot noise at dawn exposures is the colour
  pipelines' own: :func:`sim._sensor.colour_image` and the scene generators' cameras).

Examples
--------
>>> z = np.full((48, 64), 2.0, np.float32)
>>> z[:, 32:] = 1.0  # a nearer surface on the right half
>>> cam = SensorCamera(fx=72.5, cx=31.5, cy=23.5)
>>> out = structured_light_frame(z, None, cam, seed=3, params=StructuredLight(bands=False))
>>> bool((out.depth_mm[24, 24:32] == 0).any())  # the shadow: left of the near edge
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypeVar

import cv2
import numpy as np
import numpy.typing as npt
from numba import njit

from holescan.sim._xorshift import normal as _normal
from holescan.sim._xorshift import normal_table as _normal_table
from holescan.sim._xorshift import stream_state as _state
from holescan.sim._xorshift import uniform as _uniform
from holescan.sim.registration_bands import BAND_PROFILES, BandProfile, Bands, draw_bands

__all__ = [
    "FrameDraws",
    "Motion",
    "SensorCamera",
    "SensorFrame",
    "StructuredLight",
    "Surface",
    "incidence_cosine",
    "predicted_shadow_px",
    "random_motion",
    "structured_light_frame",
]

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]
U16 = npt.NDArray[np.uint16]
Range = tuple[float, float]
_T = TypeVar("_T", bound=np.generic)

#: sigma_Z = coeff * Z^2 (Z in metres): Khoshelham & Elberink 2012 (1.425e-6 per mm).
NOISE_COEFF_PER_M = 1.425e-3


@dataclass(frozen=True)
class StructuredLight:
    """The sensor's parameters; each ``(lo, hi)`` range is drawn uniformly per frame.

    Widths in pixels are for a 640 px wide frame and scale with the width.
    """

    baseline_m: float = 0.075
    disparity_step_px: float = 0.125
    #: The correlation widens the shadow to this many times the geometric one (raw depth).
    shadow_widening: float = 1.2
    #: Registration onto the colour camera narrows the shadow by f x this x (1/Zn - 1/Zf).
    registration_baseline_m: float = 0.025
    #: Noise and rounding together, as a fraction of 1.425e-3 Z^2.
    noise_fraction: Range = (0.8, 1.0)
    fattening_px: tuple[int, int] = (1, 2)
    flying_fraction: Range = (0.01, 0.18)
    bands: bool = True
    #: The ways of registering a recording can come from (one drawn per recording).
    band_profiles: tuple[BandProfile, ...] = BAND_PROFILES
    misregistration_px: Range = (1.0, 4.0)
    misregistration_scale: float = 0.01
    max_time_offset_s: float = 0.016
    #: Incidence cosine below which a surface returns nothing (drawn per frame).
    grazing_cos: Range = (0.1, 0.25)
    #: Correlation length of absorbing-surface dropouts (the clumps), pixels, drawn per
    #: frame, and the weight of a fine ragged component (~``dropout_ragged_px``) at their
    #: edges.
    dropout_clump_px: Range = (10.0, 18.0)
    dropout_ragged_px: float = 2.5
    dropout_ragged_weight: float = 0.35
    min_range_m: float = 0.5
    max_range_m: float = 4.0
    #: Readings thin out from here to ``max_range_m`` (the pattern fades).
    fade_range_m: float = 3.5

    def __post_init__(self) -> None:
        if self.baseline_m <= 0 or self.disparity_step_px <= 0:
            raise ValueError("baseline_m and disparity_step_px must be positive")
        if not 0 <= self.min_range_m < self.max_range_m <= 65.0:
            raise ValueError("need 0 <= min_range_m < max_range_m <= 65 (uint16 millimetres)")
        if self.bands and not self.band_profiles:
            raise ValueError("bands=True needs at least one band profile")


@dataclass(frozen=True)
class SensorCamera:
    """Pinhole intrinsics of the registered frame (pixels)."""

    fx: float
    cx: float
    cy: float


@dataclass(frozen=True)
class Surface:
    """Infrared properties of what each pixel sees (None = ordinary rubble everywhere).

    ir_unread : (H, W) float, fraction of the pixels of that surface that return no
        infrared (0 = rubble, 0.55-0.76 = soot, char, wet or black patches, 1 = no return).
    cos_incidence : (H, W) float, cosine between the line of sight and the surface normal;
        computed from the depth when None.
    """

    ir_unread: F32 | None = None
    cos_incidence: F32 | None = None


@dataclass(frozen=True)
class Motion:
    """The camera's motion during the frame, as image motion.

    velocity_px_s : (du/dt, dv/dt) of the scene in the image, pixels per second.
    exposure_s : colour exposure time (motion blur = velocity x exposure).
    """

    velocity_px_s: tuple[float, float] = (0.0, 0.0)
    exposure_s: float = 0.0


@dataclass(frozen=True)
class FrameDraws:
    """The random draws of one frame (pixels at the frame's width)."""

    band_left: int
    band_right: int
    band_top: int
    band_bottom: int
    fattening_px: int
    flying_fraction: float
    noise_fraction: float
    grazing_cos: float
    shift_px: tuple[float, float]
    scale: float
    time_offset_s: float
    #: Correlation length of this frame's absorbing-surface dropout clumps.
    dropout_clump_px: float = 0.0
    #: The band profile of the recording ("" without bands).
    band_profile: str = ""


@dataclass(frozen=True)
class SensorFrame:
    """What the sensor delivers.

    depth_mm : (H, W) uint16, millimetres, 0 = no reading, registered to ``rgb``.
    rgb : (H, W, 3) uint8 (None when no colour was given).
    draws : the frame's random draws.
    flying : (H, W) bool, pixels given a value between two plateaus (for validation).
    """

    depth_mm: U16
    rgb: U8 | None
    draws: FrameDraws
    flying: npt.NDArray[np.bool_] = field(repr=False)


def random_motion(
    rng: np.random.Generator,
    fx: float,
    distance_m: float,
    max_speed_m_s: float = 1.5,
    exposure_s: Range = (0.005, 0.02),
) -> Motion:
    """A survey drone's image motion: 0-``max_speed_m_s`` across a scene ``distance_m`` away
    (any direction), colour exposure drawn in ``exposure_s`` (long at dawn).

    >>> m = random_motion(np.random.default_rng(0), 580.0, 2.5)
    >>> math.hypot(*m.velocity_px_s) <= 1.5 * 580.0 / 2.5
    True
    """
    speed = float(rng.uniform(0.0, max_speed_m_s)) * fx / max(distance_m, 0.1)
    ang = float(rng.uniform(0.0, 2 * math.pi))
    return Motion(
        (round(speed * math.cos(ang), 2), round(speed * math.sin(ang), 2)),
        round(float(rng.uniform(*exposure_s)), 4),
    )


def predicted_shadow_px(
    z_near_m: float, z_far_m: float, fx: float, params: StructuredLight, registered: bool = True
) -> float:
    """Projector-shadow width (px) beside a near edge at ``z_near_m`` over ``z_far_m``.

    >>> round(predicted_shadow_px(1.0, 2.0, 580.0, StructuredLight(), registered=False), 1)
    26.1
    """
    base = params.shadow_widening * params.baseline_m
    if registered:
        base -= params.registration_baseline_m
    return fx * base * (1.0 / z_near_m - 1.0 / z_far_m)


def incidence_cosine(z: F64, fx: float, cx: float, cy: float) -> F64:
    """|cos| between each pixel's line of sight and its surface normal, from depth (m).

    For ``P = z (x', y', 1)`` the normal is ``(-z_u, -z_v, z_u x' + z_v y' + z / f)`` and its
    product with the ray ``z / f``, with ``z_u``, ``z_v`` the depth's image gradients.
    Pixels without depth (0) get 1.

    >>> z = np.full((5, 5), 2.0)  # a wall facing the camera
    >>> round(float(incidence_cosine(z, 100.0, 2.0, 2.0)[2, 2]), 3)
    1.0
    """
    zz = np.asarray(z, np.float32)
    zf, n2, r2 = _normal_terms(zz, fx, cx, cy)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.abs(zf) / np.sqrt(n2 * r2)
    return np.where((zz > 0) & np.isfinite(c), c, 1.0).astype(np.float64)


def _normal_terms(z: F32, fx: float, cx: float, cy: float) -> tuple[F32, F32, F32]:
    """``z / f``, the squared norm of the (unnormalised) surface normal and of the ray, per
    pixel (see :func:`incidence_cosine`), in float32."""
    h, w = z.shape
    gu, gv = _smaller_difference(z, 1), _smaller_difference(z, 0)
    xs = ((np.arange(w, dtype=np.float32) - np.float32(cx)) / np.float32(fx))[None, :]
    ys = ((np.arange(h, dtype=np.float32) - np.float32(cy)) / np.float32(fx))[:, None]
    zf = z / np.float32(fx)
    nz = gu * xs
    nz += gv * ys
    nz += zf
    n2 = gu * gu
    n2 += gv * gv
    n2 += nz * nz
    r2 = xs * xs + ys * ys + np.float32(1.0)
    return zf, n2, r2


def _grazing(z: F32, fx: float, cx: float, cy: float, cos_min: float) -> npt.NDArray[np.bool_]:
    """Read pixels seen at an incidence cosine below ``cos_min``, judged on every second
    pixel (grazing surfaces are wide; a quarter of the work) and spread back to full size.
    No square root, no division: ``cos^2 < c^2`` as ``(z/f)^2 < c^2 |n|^2 |r|^2``."""
    h, w = z.shape
    zs = np.ascontiguousarray(z[::2, ::2])
    # Pixel j of the half grid is pixel 2j of the full one: intrinsics halved.
    zf, n2, r2 = _normal_terms(zs, fx / 2.0, cx / 2.0, cy / 2.0)
    n2 *= r2
    n2 *= np.float32(cos_min * cos_min)
    small = zf * zf < n2
    full = np.repeat(np.repeat(small, 2, axis=0), 2, axis=1)[:h, :w]
    return (z > 0) & full


def _smaller_difference(z: F32, axis: int) -> F32:
    """Per pixel, the forward or backward difference along ``axis``, whichever is smaller:
    a surface's slope, not the jump to another surface at a depth edge."""
    d = np.diff(z, axis=axis)
    ad = np.abs(d)
    out = np.empty_like(z)
    if axis == 1:
        np.copyto(out[:, 1:-1], np.where(ad[:, :-1] < ad[:, 1:], d[:, :-1], d[:, 1:]))
        out[:, :1], out[:, -1:] = d[:, :1], d[:, -1:]
    else:
        np.copyto(out[1:-1], np.where(ad[:-1] < ad[1:], d[:-1], d[1:]))
        out[:1], out[-1:] = d[:1], d[-1:]
    return out


def _resample_nearest(img: npt.NDArray[_T], uu: F64, vv: F64) -> npt.NDArray[_T]:
    """``out[r, c] = img[round(vv[r]), round(uu[c])]``, 0 where that falls off the image
    (a separable nearest-neighbour warp: shift and scale per axis)."""
    h, w = img.shape[:2]
    ui = np.floor(uu + 0.5).astype(np.intp)
    vi = np.floor(vv + 0.5).astype(np.intp)
    u_ok = (ui >= 0) & (ui < w)
    v_ok = (vi >= 0) & (vi < h)
    out = img.take(np.clip(vi, 0, h - 1), axis=0).take(np.clip(ui, 0, w - 1), axis=1)
    out[~v_ok] = 0
    out[:, ~u_ok] = 0
    return out


def _draw_int(rng: np.random.Generator, r: tuple[int, int], s: float = 1.0) -> int:
    return round(int(rng.integers(r[0], r[1] + 1)) * s)


def _jump(z: F32) -> F32:
    """Threshold (m) for a depth discontinuity between neighbours at depth z."""
    return np.float32(0.04) + np.float32(0.03) * z


def _fatten(z: F32, r: int) -> F32:
    """The nearer surface grows by ``r`` px into the farther one (correlation window)."""
    if r <= 0:
        return z
    big = np.where(z > 0, z, np.float32(np.inf))
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    near = np.asarray(cv2.erode(big, k), np.float32)
    grow = (z > 0) & np.isfinite(near) & (z - near > _jump(near))
    return np.where(grow, near, z)


def _flying(z: F32, fraction: float, rng: np.random.Generator) -> tuple[F32, npt.NDArray[np.bool_]]:
    """At ``fraction`` of the horizontal edge crossings, the far pixel next to the near one
    takes a value between the two plateaus."""
    out = z.copy()
    flying = np.zeros(z.shape, bool)
    if fraction <= 0.0:
        return out, flying
    a, b = z[:, :-1], z[:, 1:]
    step = np.abs(a - b) > _jump(np.minimum(a, b))
    step &= a > 0
    step &= b > 0
    rows, cols = np.nonzero(step)
    keep = rng.random(rows.size) < fraction
    rows, cols = rows[keep], cols[keep]
    za, zb = a[rows, cols], b[rows, cols]
    tt = rng.uniform(0.2, 0.8, size=rows.size).astype(np.float32)
    far_is_a = za > zb
    c = np.where(far_is_a, cols, cols + 1)
    near, far = np.minimum(za, zb), np.maximum(za, zb)
    out[rows, c] = near + tt * (far - near)
    flying[rows, c] = True
    return out, flying


@njit(cache=True)
def _read(
    z: F32,
    drop: npt.NDArray[np.bool_],
    state: npt.NDArray[np.uint64],
    table: F64,
    fb_shadow: float,
    fb_steps: float,
    noise_coeff: float,
    min_m: float,
    fade_m: float,
    max_m: float,
) -> U16:
    """The readings (mm) of the depth ``z`` (m) in one pass per row, right to left.

    A pixel is unread when ``drop`` says so, when the projector (at +x) cannot light it (a
    pixel to its right maps more than half a pixel left of it: ``u - fb_shadow / z``), out
    of range, or fading past ``fade_m``; else it reads ``z`` plus noise ``noise_coeff z^2``,
    rounded to the disparity step (``fb_steps / z`` steps).
    """
    height, width = z.shape
    out = np.zeros((height, width), dtype=np.uint16)
    span = max(max_m - fade_m, 1e-6)
    for v in range(height):
        run_min = np.inf
        for u in range(width - 1, -1, -1):
            zz = z[v, u]
            if zz <= 0.0:
                continue
            up = u - fb_shadow / zz
            shadowed = up > run_min + 0.5
            run_min = min(run_min, up)
            if shadowed or drop[v, u] or zz < min_m or zz > max_m:
                continue
            if zz > fade_m and _uniform(state) < (zz - fade_m) / span:
                continue
            zn = zz + noise_coeff * zz * zz * _normal(state, table)
            if zn <= 0.0:
                continue
            steps = math.floor(fb_steps / zn + 0.5)
            if steps <= 0:
                continue
            zq = fb_steps / steps
            if zq < min_m or zq > max_m:
                continue
            out[v, u] = np.uint16(int(zq * 1000.0 + 0.5))
    return out


def _smooth_field(shape: tuple[int, int], corr_px: float, rng: np.random.Generator) -> F32:
    """Zero-mean smooth noise with features ~``corr_px`` (bilinear upsampling of white noise
    on a grid that coarse), unit variance."""
    h, w = shape
    s = max(corr_px, 1.0)
    small = rng.standard_normal((max(2, math.ceil(h / s) + 1), max(2, math.ceil(w / s) + 1)))
    big = cv2.resize(small.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
    out = np.asarray(big, np.float32)
    sd = float(out.std())
    return out / np.float32(sd if sd > 0 else 1.0)


def _clumps(
    where: npt.NDArray[np.bool_],
    clump_px: float,
    ragged_px: float,
    ragged_weight: float,
    rng: np.random.Generator,
) -> F32:
    """Per pixel of ``where`` its rank in [0, 1] within its own connected patch of a field
    correlated over ``clump_px`` (with a ragged ``ragged_px`` component); 1 elsewhere.

    ``rank < f`` then drops exactly the fraction ``f`` of every patch, as connected clumps
    around the field's lows with read islands at its highs.
    """
    h, w = where.shape
    ys, xs = np.nonzero(where)
    y0, y1, x0, x1 = int(ys.min()), int(ys.max()) + 1, int(xs.min()), int(xs.max()) + 1
    sub = where[y0:y1, x0:x1]
    shape = (y1 - y0, x1 - x0)
    field = _smooth_field(shape, clump_px, rng)
    field += np.float32(ragged_weight) * _smooth_field(shape, ragged_px, rng)
    n, lab = cv2.connectedComponents(sub.astype(np.uint8), connectivity=8)
    lab = np.asarray(lab, np.int32)
    idx = np.flatnonzero(sub.ravel())
    labels = lab.ravel()[idx]
    vals = field.ravel()[idx]
    order = np.lexsort((vals, labels))  # by patch, then by value
    counts = np.bincount(labels, minlength=n).astype(np.float64)
    start = np.concatenate([[0.0], np.cumsum(counts)[:-1]])
    pos = np.arange(idx.size, dtype=np.float64) - start[labels[order]]
    ranks = np.empty(idx.size, np.float32)
    ranks[order] = ((pos + 0.5) / counts[labels[order]]).astype(np.float32)
    out = np.ones((h, w), np.float32)
    part = np.ones(shape, np.float32).ravel()
    part[idx] = ranks
    out[y0:y1, x0:x1] = part.reshape(shape)
    return out


def _motion_blur(rgb: U8, velocity: tuple[float, float], exposure_s: float) -> U8:
    du, dv = velocity[0] * exposure_s, velocity[1] * exposure_s
    length = math.hypot(du, dv)
    if length < 1.0:
        return rgb
    n = math.ceil(length) + 1
    size = 2 * n + 1
    kernel = np.zeros((size, size), np.float32)
    for t in np.linspace(-0.5, 0.5, 4 * n + 1):
        kernel[round(n + t * dv), round(n + t * du)] += 1.0
    kernel /= kernel.sum()
    return np.asarray(cv2.filter2D(rgb, -1, kernel, borderType=cv2.BORDER_REFLECT), np.uint8)


def structured_light_frame(
    depth_m: npt.ArrayLike,
    rgb: U8 | None,
    camera: SensorCamera,
    *,
    seed: int | np.random.Generator,
    surface: Surface | None = None,
    motion: Motion | None = None,
    params: StructuredLight | None = None,
    bands: Bands | None = None,
) -> SensorFrame:
    """The sensor's registered depth (and colour) for an ideal frame (module docstring).

    Parameters
    ----------
    depth_m : (H, W) float, metres along the optical axis of the colour camera, 0 or
        non-finite = nothing there.
    rgb : (H, W, 3) uint8 colour image, or None.
    camera : intrinsics of the frame.
    seed : seed or generator of the frame's randomness (same seed, same frame).
    surface, motion, params : see :class:`Surface`, :class:`Motion`, :class:`StructuredLight`.
    bands : the recording's border bands (:func:`draw_bands`, once per flight or recording);
        when None (and ``params.bands``) the frame is a recording of its own and draws them.
    """
    p = params if params is not None else StructuredLight()
    m = motion if motion is not None else Motion()
    s = surface if surface is not None else Surface()
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    z = np.asarray(depth_m, dtype=np.float32)
    if z.ndim != 2:
        raise ValueError(f"depth_m must be (H, W), got shape {z.shape}")
    z = np.where(np.isfinite(z) & (z > 0), z, np.float32(0.0))
    h, w = z.shape
    k = w / 640.0
    if not p.bands:
        bd = Bands(0, 0, 0, 0)
    elif bands is None:
        bd = draw_bands(rng, w, p.band_profiles)
    else:
        bd = bands
    fat = int(rng.integers(p.fattening_px[0], p.fattening_px[1] + 1))
    fat = max(0, round(fat * k)) if k < 1 else fat
    fly = float(rng.uniform(*p.flying_fraction))
    noise_frac = float(rng.uniform(*p.noise_fraction))
    graze = float(rng.uniform(*p.grazing_cos))
    clump = float(rng.uniform(*p.dropout_clump_px))
    mag = float(rng.uniform(*p.misregistration_px)) * k
    ang = float(rng.uniform(0.0, 2 * math.pi))
    scale = 1.0 + float(rng.uniform(-p.misregistration_scale, p.misregistration_scale))
    dt = float(rng.uniform(-p.max_time_offset_s, p.max_time_offset_s))
    draws = FrameDraws(
        band_left=bd.left,
        band_right=bd.right,
        band_top=bd.top,
        band_bottom=bd.bottom,
        fattening_px=fat,
        flying_fraction=round(fly, 4),
        noise_fraction=round(noise_frac, 4),
        grazing_cos=round(graze, 4),
        shift_px=(round(mag * math.cos(ang), 3), round(mag * math.sin(ang), 3)),
        scale=round(scale, 5),
        time_offset_s=round(dt, 5),
        dropout_clump_px=round(clump * max(k, 0.25), 2),
        band_profile=bd.profile,
    )

    # Surfaces that return nothing: grazing, absorbing; judged on the true geometry.
    if s.cos_incidence is not None:
        drop = (z > 0) & (np.asarray(s.cos_incidence, np.float32) < graze)
    else:
        drop = _grazing(z, camera.fx, camera.cx, camera.cy, graze)
    if s.ir_unread is not None:
        unread = np.clip(np.asarray(s.ir_unread, np.float32), 0.0, 1.0)
        absorbing = unread > 0
        if absorbing.any():
            ranks = _clumps(
                absorbing,
                clump * max(k, 0.25),
                p.dropout_ragged_px * max(k, 0.25),
                p.dropout_ragged_weight,
                rng,
            )
            drop |= ranks < unread
    # The correlation window: the nearer surface fattens, some crossings fly.
    zf = _fatten(z, fat)
    zf, flying = _flying(zf, fly, rng)
    # The projector's shadow on the fattened surfaces (registered: narrower than raw), the
    # range (nothing nearer than the minimum, readings thinning out toward the maximum),
    # then noise and the disparity rounded to its step: together noise_frac x 1.425e-3 Z^2.
    fb = camera.fx * p.baseline_m
    fb_shadow = camera.fx * (p.shadow_widening * p.baseline_m - p.registration_baseline_m)
    q_var = (p.disparity_step_px / fb) ** 2 / 12.0  # rounding variance / Z^4
    coeff2 = (noise_frac * NOISE_COEFF_PER_M) ** 2 - q_var
    mm = _read(
        np.ascontiguousarray(zf, np.float32),
        np.ascontiguousarray(drop),
        _state(rng),
        _normal_table(),
        max(fb_shadow, 0.0),
        fb / p.disparity_step_px,
        math.sqrt(coeff2) if coeff2 > 0 else 0.0,
        p.min_range_m,
        p.fade_range_m,
        p.max_range_m,
    )

    # Registration onto the colour camera: shift, scale and the time offset under motion.
    sx = draws.shift_px[0] + m.velocity_px_s[0] * dt
    sy = draws.shift_px[1] + m.velocity_px_s[1] * dt
    uu = (np.arange(w, dtype=np.float64) - camera.cx) * scale + camera.cx + sx
    vv = (np.arange(h, dtype=np.float64) - camera.cy) * scale + camera.cy + sy
    mm = _resample_nearest(mm, uu, vv)
    fl = _resample_nearest(flying, uu, vv) if flying.any() else flying
    left, right, top, bottom = bd.left, bd.right, bd.top, bd.bottom
    if left:
        mm[:, :left] = 0
    if right:
        mm[:, w - right :] = 0
    if top:
        mm[:top, :] = 0
    if bottom:
        mm[h - bottom :, :] = 0
    fl &= mm > 0
    out_rgb = None if rgb is None else _motion_blur(rgb, m.velocity_px_s, m.exposure_s)
    return SensorFrame(mm, out_rgb, draws, fl)
