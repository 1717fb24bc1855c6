"""Alien scenes: shading and the RGB and depth sensor models."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from alien_scenes.common import (
    BASELINE_M,
    DISPARITY_STEP_PX,
    F32,
    F64,
    GROUND_ID,
    CameraModel,
    Textures,
    mm,
    triplanar,
)
from alien_scenes.raycast import OrthoView, PerspectiveView, render
from alien_scenes.shapes import (
    KIND_WALL,
    M_CON,
    M_DISP,
    M_IR,
    M_KIND,
    M_OFF,
    M_SCALE,
    M_TAG,
    Scene,
)

# --------------------------------------------------------------------------- shading


def _shadow_factor(sc: Scene, P: F64, n: F64, valid: NDArray[np.bool_]) -> F64:
    """Fraction (N,) of the sun's disc seen from surface points P (N, 3), from a shadow map."""
    out = np.zeros(len(P))
    if sc.sun is None:
        return out
    x0, y0, x1, y1 = sc.region
    box = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (-0.5, 2.5)])
    view = OrthoView(sc.sun, box)
    smap = render(view, sc).t.reshape(view.h, view.w)
    a, b, _ = view.pix(P[valid])
    tp = view.depth_of(P[valid])
    cosang = np.clip(mm(n[valid], sc.sun), 0.05, 1.0)
    bias = 0.012 + np.clip(1.5 * view.texel * np.sqrt(1 - cosang**2) / cosang, 0, 0.12)
    j0, i0 = np.floor(a).astype(np.int64), np.floor(b).astype(np.int64)
    fa, fb = a - j0, b - i0
    lit = np.zeros(len(tp))
    for di, dj, wgt in (
        (0, 0, (1 - fa) * (1 - fb)),
        (0, 1, fa * (1 - fb)),
        (1, 0, (1 - fa) * fb),
        (1, 1, fa * fb),
    ):
        ii = np.clip(i0 + di, 0, view.h - 1)
        jj = np.clip(j0 + dj, 0, view.w - 1)
        lit += wgt * (tp - bias <= smap[ii, jj])
    out[valid] = lit
    return out


@dataclass(frozen=True)
class Surface:
    """Per-pixel surface data of the camera view, (H, W[, 3])."""

    Z: F64  # metres along the optical axis, inf = nothing
    P: F64
    n: F64
    ident: NDArray[np.int32]
    tag: NDArray[np.int32]
    disp: F64  # roughness displacement along the ray, m
    ir: F64  # IR reflectance
    cos_inc: F64  # |cos| of the incidence angle
    radiance: F32
    stain: NDArray[np.int32]  # 1 + index into Scene.stains where that stain's core is, else 0


def shade(rng: np.random.Generator, sc: Scene, view: PerspectiveView, tex: Textures) -> Surface:
    h, w = view.h, view.w
    buf = render(view, sc)
    valid = np.isfinite(buf.t)
    t = np.where(valid, buf.t, 0.0).astype(np.float64)
    D = view.D.astype(np.float64)
    P = sc.C + t[:, None] * D
    ident = np.where(valid, buf.ident, GROUND_ID)
    n = buf.n.astype(np.float64)
    n /= np.maximum(np.linalg.norm(n, axis=1), 1e-9)[:, None]
    n *= np.where((n * D).sum(1) > 0, -1.0, 1.0)[:, None]
    mat = sc.mats[ident]
    shadow = _shadow_factor(sc, P, n, valid)
    # textures (triplanar, per-object offsets)
    Pi, ni = P.reshape(h, w, 3).astype(np.float32), n.reshape(h, w, 3)
    w3 = np.abs(ni) ** 4 + 1e-6
    w3 = (w3 / w3.sum(2, keepdims=True)).astype(np.float32)
    scale = mat[:, M_SCALE].reshape(h, w)
    off = mat[:, M_OFF : M_OFF + 3].reshape(h, w, 3)
    grain = triplanar(tex.grain, Pi, w3, (250.0 / scale).astype(np.float32), off).reshape(-1)
    smooth = triplanar(tex.smooth, Pi, w3, (30.0 / scale).astype(np.float32), off * 0.37).reshape(
        -1
    )
    albedo = mat[:, 0:3] * np.exp(mat[:, M_CON] * (0.75 * smooth + 0.45 * grain))[:, None]
    ir = mat[:, M_IR].astype(np.float64).copy()
    # dust settles on upward faces
    dust_k = rng.uniform(0.05, 0.35)
    dust = np.array([0.42, 0.40, 0.37]) * rng.uniform(0.8, 1.1)
    f = dust_k * np.clip(mm(n, sc.up), 0, 1) ** 2 * np.clip(0.6 + 0.3 * smooth, 0, 1)
    albedo = albedo * (1 - f[:, None]) + dust * f[:, None]
    stain_id = np.zeros(len(P), np.int32)
    for k, st in enumerate(sc.stains):
        c, s_ = math.cos(st.angle), math.sin(st.angle)
        d = P[:, :2] - st.centre
        q = (mm(d, [c, s_]) / st.axes[0]) ** 2 + (mm(d, [-s_, c]) / st.axes[1]) ** 2
        m = np.clip((1.15 - q * (1 + 0.3 * smooth)) / 0.3, 0, 1) * (P[:, 2] < 0.6) * valid
        albedo *= (1 - st.strength * m)[:, None]
        stain_id[m > 0.5] = k + 1
        if st.wet:
            ir *= 1 - 0.85 * m
    kind = mat[:, M_KIND].astype(np.int64)
    tag = np.where(valid, mat[:, M_TAG], -1).astype(np.int32)
    disp = mat[:, M_DISP] * (0.7 * grain + 0.8 * smooth)
    # bump normals from the screen-space gradient of the displacement
    dimg = disp.reshape(h, w)
    same_u = np.zeros((h, w), bool)
    same_u[:, :-1] = ident.reshape(h, w)[:, 1:] == ident.reshape(h, w)[:, :-1]
    same_v = np.zeros((h, w), bool)
    same_v[:-1] = ident.reshape(h, w)[1:] == ident.reshape(h, w)[:-1]
    gu = np.zeros((h, w))
    gv = np.zeros((h, w))
    gu[:, :-1] = np.diff(dimg, axis=1)
    gv[:-1] = np.diff(dimg, axis=0)
    zz = np.maximum(t.reshape(h, w), 0.3)
    gu = np.where(same_u, gu, 0) * view.cam.fx / zz
    gv = np.where(same_v, gv, 0) * view.cam.fy / zz
    grad = gu.reshape(-1, 1) * sc.R[:, 0] + gv.reshape(-1, 1) * sc.R[:, 1]
    grad -= (grad * n).sum(1)[:, None] * n
    nb = n + np.clip(grad, -2, 2)
    nb /= np.maximum(np.linalg.norm(nb, axis=1), 1e-9)[:, None]
    # ambient occlusion: lower than the neighbourhood, and the sky view from inside shafts
    hgt = np.clip(P[:, 2], -0.6, 1.5).reshape(h, w).astype(np.float32)
    ao = np.exp(-1.5 * np.maximum(cv2.GaussianBlur(hgt, (0, 0), 10) - hgt, 0))
    ao *= np.exp(-3.0 * np.maximum(cv2.GaussianBlur(hgt, (0, 0), 3) - hgt, 0))
    ao = np.clip(ao, 0.35, 1).reshape(-1)
    for hole in sc.holes:
        sel = tag == hole.tag
        if not sel.any():
            continue
        below = np.maximum(hole.rim[:, 2].mean() - P[sel, 2], 0)
        vf = hole.r_eff**2 / (hole.r_eff**2 + below**2)
        vf *= np.where(kind[sel] == KIND_WALL, 0.65, 1.0)
        ao[sel] = np.minimum(ao[sel], 0.03 + vf)
    nu = mm(nb, sc.up)
    light = (
        sc.e_sun * sc.sun_rgb * (np.clip(mm(nb, sc.sun), 0, 1) * shadow)[:, None]
        if sc.sun is not None
        else np.zeros((len(nb), 3))
    )
    light = light + sc.sky_rgb * (ao * (0.55 + 0.45 * nu))[:, None]
    glow = np.clip(mm(nb, sc.glow), 0, 1) * ao  # the bright dawn sky low over the sunrise
    light = light + np.array([1.0, 0.75, 0.6]) * (sc.glow_strength * glow)[:, None]
    bounce = (0.3 + 0.1 * sc.e_sun) * np.array([0.3, 0.27, 0.23]) * (0.5 - 0.5 * nu)[:, None]
    light = light + bounce * ao[:, None]
    rad = (albedo * light).reshape(h, w, 3).astype(np.float32)
    cos_inc = np.abs((n * D).sum(1)) / np.linalg.norm(D, axis=1)
    return Surface(
        Z=np.where(valid, t, np.inf).reshape(h, w),
        P=P.reshape(h, w, 3),
        n=n.reshape(h, w, 3),
        ident=ident.reshape(h, w).astype(np.int32),
        tag=tag.reshape(h, w),
        disp=disp.reshape(h, w).astype(np.float64),
        ir=ir.reshape(h, w),
        cos_inc=cos_inc.reshape(h, w),
        radiance=rad,
        stain=stain_id.reshape(h, w),
    )


# --------------------------------------------------------------------------- sensors


def rgb_sensor(rng: np.random.Generator, sc: Scene, rad: F32) -> NDArray[np.uint8]:
    """Dawn colour camera: blur, vignetting, Bayer, shot/read noise, AE, AWB, gamma."""
    h, w = rad.shape[:2]
    img: NDArray[Any] = rad.copy()
    if rng.uniform() < 0.3:  # a little motion blur from the airframe
        length = rng.uniform(1.5, 4.0)
        k = np.zeros((9, 9), np.float32)
        ang = rng.uniform(0, math.pi)
        for s in np.linspace(-length / 2, length / 2, 15):
            k[round(4 + s * math.sin(ang)), round(4 + s * math.cos(ang))] += 1
        img = cv2.filter2D(img, -1, k / k.sum())
    img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.5, 0.9))
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    img *= (1 - rng.uniform(0.15, 0.45) * r2 - rng.uniform(0, 0.15) * r2**2)[..., None]
    sens = np.array([0.85, 1.0, 0.7]) * (1 + rng.normal(0, 0.04, 3))
    img = img * sens
    ch = np.zeros((h, w), np.int64)  # RGGB
    ch[0::2, 1::2] = 1
    ch[1::2, 0::2] = 1
    ch[1::2, 1::2] = 2
    raw = np.take_along_axis(img, ch[..., None], 2)[..., 0]
    e_mid = math.exp(rng.uniform(math.log(15), math.log(150)))  # photons are scarce at dawn
    green = raw[ch == 1]
    gain = e_mid / max(float(np.median(green)), 1e-6)
    el = rng.poisson(np.maximum(raw * gain, 0)).astype(np.float64)
    el += rng.normal(0, rng.uniform(1.5, 4.0), el.shape) + rng.normal(0, 0.6, (h, 1))
    dn = el / e_mid * 0.13 * 2 ** rng.normal(0, 0.5)
    illum = sens * (sc.e_sun * sc.sun_rgb * 0.4 + sc.sky_rgb)
    gains = (illum[1] / illum) ** rng.uniform(0.2, 0.85) * (1 + rng.normal(0, 0.06, 3))
    dn *= (gains / gains[1])[ch]
    mosaic = (np.clip(dn, 0, 1) * 65535).astype(np.uint16)
    rgb = cv2.cvtColor(mosaic, cv2.COLOR_BayerBG2RGB).astype(np.float64) / 65535
    y = rgb ** (1 / 2.2)
    y = np.clip(0.5 + (y - 0.5) * rng.uniform(1.0, 1.15), 0, 1)
    out: NDArray[np.uint8] = np.round(y * 255).astype(np.uint8)
    return out


def depth_sensor(
    rng: np.random.Generator, sc: Scene, cam: CameraModel, s: Surface
) -> NDArray[np.uint16]:
    """Xtion-like structured-light depth (uint16 mm, 0 = no reading)."""
    h, w = s.Z.shape
    Z: NDArray[Any] = (s.Z + s.disp).astype(np.float32)
    # lateral jitter of the 9x9 correlation window and a small misregistration
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    jit = []
    for glob in (rng.uniform(-1, 1), rng.uniform(-0.6, 0.6)):
        f = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 1.5)
        jit.append(f / f.std() * 0.35 + glob)
    Z = cv2.remap(Z, xx + jit[0], yy + jit[1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
    fb_mm = cam.fx * BASELINE_M * 1000.0
    finite = np.isfinite(Z)
    Zmm = np.where(finite, Z * 1000.0, 1e9).astype(np.float64)
    # IR projector shadow: projector column u - f b / Z must increase along each row
    upj = xx - fb_mm / Zmm
    runmin = np.minimum.accumulate(upj[:, ::-1], axis=1)[:, ::-1]
    right = np.concatenate([runmin[:, 1:], np.full((h, 1), np.inf)], axis=1)
    shadow = upj > right + 0.3
    # axial noise (partly correlated) and disparity quantisation
    wn = rng.standard_normal((h, w)).astype(np.float32)
    cn = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 1.2)
    noise = 0.6 * wn + 0.8 * cn / cn.std()
    noise /= noise.std()
    sigma = rng.uniform(0.6, 1.0) * 1.425e-6 * Zmm**2
    Zn = np.maximum(Zmm + sigma * noise, 100.0)
    disp_px = np.round(fb_mm / Zn / DISPARITY_STEP_PX) * DISPARITY_STEP_PX
    with np.errstate(divide="ignore"):
        Zq = np.where(disp_px > 0, fb_mm / disp_px, np.inf)
    zmax_mm = sc.zmax * 1000.0
    drop = ~finite | shadow | (Zq > zmax_mm) | (Zq < 500)
    # probabilistic dropouts
    p_graz = np.clip((0.25 - s.cos_inc) / 0.17, 0, 1) * 0.9
    p_dark = np.clip((0.14 - s.ir) / 0.1, 0, 1) * 0.8
    zf = np.where(finite, Z, 50.0)
    jump = np.zeros((h, w), bool)
    jump[:, 1:] |= np.abs(np.diff(zf, axis=1)) > 0.04 * zf[:, 1:]
    jump[1:] |= np.abs(np.diff(zf, axis=0)) > 0.04 * zf[1:]
    jump = cv2.dilate(jump.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    p_edge = jump * rng.uniform(0.2, 0.5)
    p_far = np.clip((Zq - (zmax_mm - 300)) / 300, 0, 1) * 0.3
    p_speck = rng.uniform(0.0005, 0.004)
    keep = (1 - p_graz) * (1 - p_dark) * (1 - p_edge) * (1 - p_far) * (1 - p_speck)
    drop |= rng.uniform(size=(h, w)) > keep
    blob = cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0), 6)
    frac = rng.uniform(0, 0.02)
    if frac > 0.001:
        drop |= blob > np.quantile(blob, 1 - frac)
    drop[:, : int(rng.integers(0, 9))] = True
    out = np.where(drop, 0, np.clip(np.round(Zq), 0, 65535))
    return out.astype(np.uint16)


#: A dry stain is soot or char (absorbing) with this probability; wet ones always absorb.
ABSORBING_DRY_STAIN_P = 0.6
#: Fraction of the pattern an absorbing stain swallows (real soot, char, wet patches).
ABSORBING_UNREAD = (0.55, 0.76)


def absorbing_stains(
    rng: np.random.Generator, sc: Scene, s: Surface
) -> tuple[NDArray[np.float32], dict[int, float]]:
    """Per pixel, the fraction of the pattern lost on absorbing surfaces, and the absorbing
    stains in view (stain id of ``s.stain`` -> that fraction).

    Dark or wet surfaces (IR reflectance under 0.14) lose up to 76 % in proportion; every
    wet stain and ``ABSORBING_DRY_STAIN_P`` of the dry ones (soot, char) lose a fraction
    drawn in ``ABSORBING_UNREAD`` over their whole core, as on real frames.
    """
    h, w = s.Z.shape
    unread = (np.clip((0.14 - s.ir) / 0.1, 0, 1) * 0.76).reshape(h, w).astype(np.float32)
    out: dict[int, float] = {}
    for k, st in enumerate(sc.stains):  # a draw per stain in the scene, in view or not
        absorbs = st.wet or rng.random() < ABSORBING_DRY_STAIN_P
        frac = float(rng.uniform(*ABSORBING_UNREAD))
        sel = s.stain == k + 1
        if absorbs and sel.any():
            unread[sel] = np.maximum(unread[sel], np.float32(frac))
            out[k + 1] = round(frac, 3)
    return unread, out


def structured_light_sensor(
    rng: np.random.Generator,
    sc: Scene,
    cam: CameraModel,
    s: Surface,
    rgb: NDArray[np.uint8],
    bands: Any = None,
) -> tuple[NDArray[np.uint16], NDArray[np.uint8], dict[str, Any]]:
    """The project's measured structured-light model (``holescan.sim.structured_light``,
    ``docs/sensor-model.md``) on this scene's true depth and infrared reflectance (absorbing
    surfaces: :func:`absorbing_stains`); ``bands``: the recording's border bands
    (``holescan.sim.registration_bands.Bands``; drawn for this frame alone when None)."""
    from holescan.sim.structured_light import (
        SensorCamera,
        StructuredLight,
        random_motion,
        structured_light_frame,
    )
    from holescan.sim.structured_light import Surface as IrSurface

    h, w = s.Z.shape
    Z = np.asarray(s.Z + s.disp, np.float64)
    finite = np.isfinite(Z)
    unread, absorbing = absorbing_stains(rng, sc, s)
    centre = float(np.median(Z[finite])) if finite.any() else 2.5
    motion = random_motion(rng, cam.fx, centre)
    params = StructuredLight(max_range_m=sc.zmax, fade_range_m=sc.zmax - 0.3)
    fr = structured_light_frame(
        np.where(finite, Z, 0.0),
        rgb,
        SensorCamera(cam.fx, cam.cx, cam.cy),
        seed=rng,
        surface=IrSurface(unread, s.cos_inc.reshape(h, w).astype(np.float32)),
        motion=motion,
        params=params,
        bands=bands,
    )
    d = fr.draws
    assert fr.rgb is not None
    return (
        fr.depth_mm,
        fr.rgb,
        {
            "bands_ltrb_px": [d.band_left, d.band_top, d.band_right, d.band_bottom],
            "band_profile": d.band_profile,
            "misregistration_px": list(d.shift_px),
            "time_offset_s": d.time_offset_s,
            "velocity_px_s": list(motion.velocity_px_s),
            "absorbing_stains": absorbing,
        },
    )
