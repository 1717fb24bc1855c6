"""Alien scenes: constants, the camera model, geometry helpers, textures."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import NDArray

_LOG = logging.getLogger("alien_scenes")

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

WIDTH = 640
HEIGHT = 480
BASELINE_M = 0.075  # IR projector to IR camera, projector on the camera's +x side
DISPARITY_STEP_PX = 0.125
GROUND_ID = 0
F_PAD = 14  # plane slots per polyhedron
_EPS = 1e-5


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics shared by the registered RGB and depth images (pixels)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @staticmethod
    def sample(rng: np.random.Generator) -> CameraModel:
        """Draw an Xtion-like camera: fx = fy in 560-580 px, centre within 4 px."""
        f = float(rng.uniform(560.0, 580.0))
        return CameraModel(
            WIDTH,
            HEIGHT,
            f,
            f,
            319.5 + float(rng.uniform(-4, 4)),
            239.5 + float(rng.uniform(-4, 4)),
        )

    def to_json(self) -> dict[str, float | int]:
        """The ``camera.json`` record (depth PNG unit: 1 mm)."""
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "depth_unit_m": 0.001,
        }


# --------------------------------------------------------------------------- geometry


def mm(a: NDArray[Any], b: NDArray[Any] | list[float]) -> NDArray[Any]:
    """``a @ b`` for many small vectors without BLAS (its threads stall on a busy machine)."""
    b = np.asarray(b, dtype=a.dtype if a.dtype == np.float32 else np.float64)
    if b.ndim == 1:
        return cast(NDArray[Any], np.einsum("...j,j->...", a, b))
    return cast(NDArray[Any], np.einsum("...j,jk->...k", a, b))


def rot(axis: F64 | tuple[float, float, float], angle: float) -> F64:
    """Rotation matrix about ``axis`` by ``angle`` radians (Rodrigues)."""
    x, y, z = (float(v) for v in axis)
    n = math.sqrt(x * x + y * y + z * z)
    x, y, z = x / n, y / n, z / n
    c, s = math.cos(angle), math.sin(angle)
    C = 1 - c
    return np.array(
        [
            [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
        ]
    )


def pick(rng: np.random.Generator, items: list[str], p: list[float] | None = None) -> str:
    """One of ``items`` (probabilities ``p``, default uniform); faster than Generator.choice."""
    if p is None:
        return items[int(rng.integers(len(items)))]
    u = rng.random() * sum(p)
    for item, w in zip(items, p, strict=True):
        u -= w
        if u < 0:
            return item
    return items[-1]


def rz(angle: float) -> F64:
    return rot(np.array([0.0, 0.0, 1.0]), angle)


def resting_rotation(rng: np.random.Generator, max_tilt_deg: float) -> F64:
    """Random yaw, then a tilt about a random horizontal axis."""
    az = rng.uniform(0, 2 * math.pi)
    tilt = math.radians(rng.uniform(0, max_tilt_deg))
    axis = np.array([math.cos(az), math.sin(az), 0.0])
    return rot(axis, tilt) @ rz(rng.uniform(0, 2 * math.pi))


def perp_basis(a: F64) -> tuple[F64, F64]:
    ref = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(a, ref)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def powerlaw(rng: np.random.Generator, lo: float, hi: float, alpha: float) -> float:
    """Sample p(s) ~ s^-alpha on [lo, hi]."""
    e = 1.0 - alpha
    u = rng.uniform()
    return float((lo**e + u * (hi**e - lo**e)) ** (1.0 / e))


# --------------------------------------------------------------------------- textures


@dataclass(frozen=True)
class Textures:
    """Periodic zero-mean unit-variance noise images (float32, S x S)."""

    smooth: F32
    grain: F32


def _fft_noise(rng: np.random.Generator, size: int, beta: float) -> F32:
    white = rng.standard_normal((size, size))
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    f = np.hypot(fx, fy)
    f[0, 0] = 1.0
    amp = f ** (-beta / 2.0)
    amp[0, 0] = 0.0
    tex = np.fft.irfft2(np.fft.rfft2(white) * amp, s=(size, size))
    tex = (tex - tex.mean()) / tex.std()
    out: F32 = tex.astype(np.float32)
    return out


def make_textures(rng: np.random.Generator) -> Textures:
    return Textures(_fft_noise(rng, 512, 2.6), _fft_noise(rng, 512, 1.1))


def triplanar(tex: F32, P: F32, w3: F32, inv_texel: F32, off: F32) -> F32:
    """Sample a periodic texture on surfaces by world position (triplanar blend).

    P, w3, off: (H, W, 3); inv_texel: (H, W) texels per metre. Returns (H, W).
    """
    size = tex.shape[0]
    q = np.mod(P * inv_texel[..., None] + off, size).astype(np.float32)
    out = np.zeros(P.shape[:2], np.float32)
    for k, (i, j) in enumerate(((1, 2), (0, 2), (0, 1))):
        s = cv2.remap(tex, q[..., i], q[..., j], cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        out += w3[..., k] * s
    return out
