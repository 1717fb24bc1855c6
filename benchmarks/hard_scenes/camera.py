"""Xtion-like camera: intrinsics, UAV poses (nadir to 20 deg oblique), rays and projection.

World frame: x, y horizontal, z up (metres, rubble datum near z = 0). Camera frame as in
OpenCV: x right, y down, z along the optical axis. A pixel with index (i, j) looks through
(i - cx) / fx, (j - cy) / fy; in box (pixel-edge) coordinates its centre is at i + 0.5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BASELINE_M = 0.075  # IR projector to IR camera, along the camera's +x
MIN_RANGE_M = 0.5


@dataclass(frozen=True)
class Intrinsics:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def scaled(self, s: float) -> Intrinsics:
        if s == 1.0:
            return self
        w, h = round(self.width * s), round(self.height * s)
        return Intrinsics(
            w, h, self.fx * s, self.fy * s, (self.cx + 0.5) * s - 0.5, (self.cy + 0.5) * s - 0.5
        )

    def to_dict(self) -> dict[str, float | int]:
        return {
            "width": self.width,
            "height": self.height,
            "fx": round(self.fx, 4),
            "fy": round(self.fy, 4),
            "cx": round(self.cx, 4),
            "cy": round(self.cy, 4),
            "depth_unit_m": 0.001,
        }


def dataset_intrinsics(seed: int) -> Intrinsics:
    """One set of intrinsics per dataset (fx = fy in 570-576 px, centre near the middle)."""
    rng = np.random.default_rng([seed, 0x1C7])
    f = float(rng.uniform(570.0, 576.0))
    cx = 319.5 + float(rng.uniform(-2.0, 2.0))
    cy = 239.5 + float(rng.uniform(-2.0, 2.0))
    return Intrinsics(640, 480, round(f, 3), round(f, 3), round(cx, 3), round(cy, 3))


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: rotation by ``angle`` (rad) about the unit vector ``axis``."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def make_pose(
    height: float, tilt: float, tilt_dir: float, yaw: float, xy: tuple[float, float] = (0, 0)
) -> tuple[np.ndarray, np.ndarray]:
    """World-from-camera rotation R (columns: camera axes in world) and centre C.

    The optical axis leans ``tilt`` rad from nadir toward the image direction ``tilt_dir``
    (0 = image right, pi/2 = image down): that side of the image sees farthest.
    """
    nadir = np.diag([1.0, -1.0, -1.0])
    c, s = np.cos(yaw), np.sin(yaw)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    axis_cam = np.array([-np.sin(tilt_dir), np.cos(tilt_dir), 0.0])
    R = rz @ nadir @ rotation(axis_cam, tilt)
    return R, np.array([xy[0], xy[1], height], float)


def dirs_at(intr: Intrinsics, R: np.ndarray, u: np.ndarray, v: np.ndarray):
    """Unit world directions through pixel coordinates (u, v), and Z per unit length."""
    dc = np.stack(
        [
            (np.asarray(u, float) - intr.cx) / intr.fx,
            (np.asarray(v, float) - intr.cy) / intr.fy,
            np.ones(np.shape(u)),
        ],
        axis=-1,
    )
    n = np.linalg.norm(dc, axis=-1, keepdims=True)
    dc = dc / n
    return dc @ R.T, dc[..., 2]


def pixel_dirs(intr: Intrinsics, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H*W, 3) unit world ray directions in row-major pixel order, and axial factors."""
    v, u = np.mgrid[0 : intr.height, 0 : intr.width]
    d, ax = dirs_at(intr, R, u.ravel(), v.ravel())
    return np.ascontiguousarray(d), ax


def project(intr: Intrinsics, R: np.ndarray, C: np.ndarray, P: np.ndarray):
    """World points (M, 3) -> pixel coordinates u, v (index convention) and axial depth Z."""
    pc = (np.asarray(P, float) - C) @ R
    z = pc[:, 2]
    return intr.fx * pc[:, 0] / z + intr.cx, intr.fy * pc[:, 1] / z + intr.cy, z


def ground_at(intr: Intrinsics, R: np.ndarray, C: np.ndarray, u, v, z: float = 0.0):
    """Where the rays through (u, v) meet the horizontal plane at height z: (M, 3)."""
    d, _ = dirs_at(intr, R, np.atleast_1d(u), np.atleast_1d(v))
    t = (z - C[2]) / d[:, 2]
    return C + t[:, None] * d


def axial_depth(R: np.ndarray, C: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Z (along the optical axis) of world points (M, 3)."""
    return (np.atleast_2d(P) - C) @ R[:, 2]
