"""The simulated camera: its pose in the world, the viewing conditions and projection.

World frame (see :mod:`sim._world`): metres, x east, y north, z up. Camera optical
frame: x right, y down, z forward (along the optical axis), as in
:class:`detect.CameraIntrinsics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError

__all__ = [
    "XTION_BASELINE_M",
    "XTION_DISPARITY_STEP_PX",
    "XTION_NOISE_COEFF_PER_MM",
    "CameraPose",
    "Conditions",
    "axial_noise_mm",
    "project_points",
    "random_conditions",
]

#: Axial depth noise of the Xtion/Kinect v1: sigma = coeff * Z_mm**2 (Khoshelham & Elberink 2012).
XTION_NOISE_COEFF_PER_MM = 1.425e-6
#: Distance between the IR projector and the IR camera (the projector sits at +x of the camera).
XTION_BASELINE_M = 0.075
#: The sensor reports disparity in steps of 1/8 pixel.
XTION_DISPARITY_STEP_PX = 0.125

FloatArray = npt.NDArray[np.float64]


def _rotation_about(axis: FloatArray, angle: float) -> FloatArray:
    """(3, 3) rotation by ``angle`` rad about ``axis`` (any length; scipy's rotation vector)."""
    k = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    return np.asarray(Rotation.from_rotvec(angle * k).as_matrix(), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class CameraPose:
    """Where the camera is and where it looks.

    position : (3,) float64 ndarray, metres, optical centre in the world frame.
    rotation : (3, 3) float64 ndarray, world <- camera (its columns are the camera's x right,
        y down and z forward axes written in the world frame).
    """

    position: FloatArray
    rotation: FloatArray

    def __post_init__(self) -> None:
        p = np.array(self.position, dtype=np.float64).reshape(-1)
        r = np.array(self.rotation, dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError(f"camera position must be 3 finite numbers, got {self.position!r}")
        if r.shape != (3, 3) or not np.allclose(r.T @ r, np.eye(3), atol=1e-6):
            raise InputError("camera rotation must be a 3x3 orthonormal matrix (world <- camera)")
        if np.linalg.det(r) < 0:
            raise InputError("camera rotation must be a proper rotation (det = +1), not a mirror")
        p.flags.writeable = False
        r.flags.writeable = False
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "rotation", r)

    @classmethod
    def looking_down(
        cls,
        x: float,
        y: float,
        z: float,
        yaw: float = 0.0,
        tilt: float = 0.0,
        tilt_heading: float = 0.0,
    ) -> CameraPose:
        """A camera at ``(x, y, z)`` world metres looking (nearly) straight down.

        yaw : heading of the image's "up" direction, rad clockwise from north (0: north up,
            east right, like a map).
        tilt : angle between the optical axis and the vertical, rad (0 = nadir).
        tilt_heading : heading towards which the optical axis leans, rad clockwise from north.
        """
        c, s = math.cos(yaw), math.sin(yaw)
        x_c = np.array([c, -s, 0.0])
        y_c = np.array([-s, -c, 0.0])
        z_c = np.array([0.0, 0.0, -1.0])
        r0 = np.column_stack([x_c, y_c, z_c])
        if tilt != 0.0:
            axis = np.array([math.cos(tilt_heading), -math.sin(tilt_heading), 0.0])
            r0 = _rotation_about(axis, tilt) @ r0
        return cls(np.array([x, y, z], dtype=np.float64), r0)

    def to_camera(self, points_w: npt.ArrayLike) -> FloatArray:
        """(N, 3) world points, metres -> (N, 3) points in the camera's optical frame."""
        pts = np.asarray(points_w, dtype=np.float64).reshape(-1, 3)
        return (pts - self.position) @ self.rotation

    def to_world(self, points_c: npt.ArrayLike) -> FloatArray:
        """(N, 3) points in the optical frame -> (N, 3) world points, metres."""
        pts = np.asarray(points_c, dtype=np.float64).reshape(-1, 3)
        return pts @ self.rotation.T + self.position


def project_points(
    camera: CameraIntrinsics, pose: CameraPose, points_w: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Project world points into the image.

    Returns
    -------
    uv : (N, 2) float64 ndarray, pixels (pixel centres at integers, as ``cx``/``cy``); NaN
        for points not in front of the camera.
    z : (N,) float64 ndarray, metres along the optical axis (axial depth).
    """
    pc = pose.to_camera(points_w)
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.fx * pc[:, 0] / z + camera.cx
        v = camera.fy * pc[:, 1] / z + camera.cy
    uv = np.column_stack([u, v])
    uv[z <= 0] = np.nan
    return uv, z


def axial_noise_mm(z_mm: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The Xtion's axial depth noise (1 sigma, mm) at depth ``z_mm``: 1.425e-6 Z^2."""
    z = np.asarray(z_mm, dtype=np.float64)
    return np.asarray(XTION_NOISE_COEFF_PER_MM * z * z)


@dataclass(frozen=True)
class Conditions:
    """Viewing conditions and sensor artefacts of one frame.

    Colour: linear scene radiance x ``exposure`` x ``white_balance``, vignetting
    ``1 - vignetting * r^2`` (r = 1 at the image corner), sensor noise with standard deviation
    ``sqrt(read_noise^2 + shot_noise^2 * signal)`` (linear units, 1 = full scale), then a
    1/2.2 gamma and 8-bit rounding.

    Depth: ``depth_noise`` x the Xtion's axial noise (noise and disparity quantisation
    together have the standard deviation 1.425e-6 Z^2 when ``depth_noise`` is 1), disparity
    quantised in steps of ``disparity_step_px``, no reading outside
    [``min_range_m``, ``max_range_m``] (readings fade out increasingly from ``fade_range_m``),
    projector shadows (projector ``baseline_m`` to the camera's right), and a fraction
    ``dropout_fraction`` of random missing pixels. With ``structured_light`` (the default)
    the depth goes through :mod:`sim.structured_light` instead (the ranges above still
    apply; noise, shadows, bands and dropouts are that model's); ``False`` keeps this basic
    model, for comparison.
    """

    exposure: float = 0.35
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    vignetting: float = 0.25
    read_noise: float = 0.004
    shot_noise: float = 0.03
    depth_noise: float = 1.0
    min_range_m: float = 0.5
    fade_range_m: float = 3.5
    max_range_m: float = 4.0
    baseline_m: float = XTION_BASELINE_M
    disparity_step_px: float = XTION_DISPARITY_STEP_PX
    dropout_fraction: float = 0.002
    structured_light: bool = True

    def __post_init__(self) -> None:
        if self.exposure <= 0:
            raise InputError(f"exposure must be positive, got {self.exposure}")
        if not 0 <= self.min_range_m < self.max_range_m:
            raise InputError("need 0 <= min_range_m < max_range_m")
        if not 0 <= self.dropout_fraction < 1:
            raise InputError("dropout_fraction must be in [0, 1)")

    @classmethod
    def ideal(cls) -> Conditions:
        """No noise, no quantisation, no dropouts or projector shadows (exact rendering)."""
        return cls(
            vignetting=0.0,
            read_noise=0.0,
            shot_noise=0.0,
            depth_noise=0.0,
            fade_range_m=1e9,
            max_range_m=1e9,
            min_range_m=0.0,
            baseline_m=0.0,
            disparity_step_px=0.0,
            dropout_fraction=0.0,
            structured_light=False,
        )


def random_conditions(rng: np.random.Generator, base: Conditions | None = None) -> Conditions:
    """Per-frame variation of ``base``: exposure (log-normal, +-30 %), white balance, ranges."""
    b = base if base is not None else Conditions()
    wb = rng.normal(1.0, 0.04, size=3)
    return Conditions(
        exposure=b.exposure * float(np.exp(rng.normal(0.0, 0.3))),
        white_balance=(float(wb[0]), float(wb[1]), float(wb[2])),
        vignetting=b.vignetting * float(rng.uniform(0.6, 1.4)),
        read_noise=b.read_noise * float(rng.uniform(0.7, 1.5)),
        shot_noise=b.shot_noise * float(rng.uniform(0.7, 1.5)),
        depth_noise=b.depth_noise,
        min_range_m=b.min_range_m,
        fade_range_m=b.fade_range_m - float(rng.uniform(0.0, 0.3)),
        max_range_m=b.max_range_m - float(rng.uniform(0.0, 0.3)),
        baseline_m=b.baseline_m,
        disparity_step_px=b.disparity_step_px,
        dropout_fraction=b.dropout_fraction * float(rng.uniform(0.5, 2.0)),
        structured_light=b.structured_light,
    )
