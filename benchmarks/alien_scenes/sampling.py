"""Alien scenes: camera placement helpers."""

from __future__ import annotations

import cv2
import numpy as np

from alien_scenes.common import F64, CameraModel, _perp_basis, _rot

# --------------------------------------------------------------------------- scene sampling

_LIB_BOX, _LIB_PRISM, _LIB_CUT0, _LIB_HULL0 = 0, 1, 2, 34


def _camera_rotation(up: F64, tilt: float, yaw: float, roll: float) -> F64:
    """World-from-camera rotation: tilt from nadir, yaw about gravity, roll about the axis."""
    x, _ = _perp_basis(up)
    x = _rot(up, yaw) @ x
    z = -up
    y = np.cross(z, x)
    rt = _rot(x, tilt)
    z2, y2 = rt @ z, rt @ y
    rr = _rot(z2, roll)
    return np.column_stack([rr @ x, rr @ y2, z2])


def _ground_point(cam: CameraModel, C: F64, R: F64, u: float, v: float) -> F64 | None:
    d = R @ np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
    if d[2] > -0.05:
        return None
    p: F64 = C + (-C[2] / d[2]) * d
    return p


def _footprint(cam: CameraModel, C: F64, R: F64) -> F64:
    """Ground-plane polygon (M, 2) seen through the image border."""
    w, h = cam.width - 1, cam.height - 1
    border = (
        [(u, 0) for u in range(0, w, 16)]
        + [(w, v) for v in range(0, h, 16)]
        + [(u, h) for u in range(w, 0, -16)]
        + [(0, v) for v in range(h, 0, -16)]
    )
    pts = []
    for u, v in border:
        p = _ground_point(cam, C, R, u, v)
        if p is None:  # ray towards the horizon: stop it 12 m away
            d = R @ np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
            d[2] = 0
            p = C + 12 * d / np.linalg.norm(d)
        pts.append(p[:2])
    return np.array(pts)


def _poly_dims(poly: F64, axis: F64) -> tuple[float, float, float]:
    """Long and short side of the min-area rectangle and inscribed-circle diameter (m) of
    an opening ``poly`` in z = 0, measured across the shaft ``axis``."""
    u, v = _perp_basis(axis)
    p3 = np.column_stack([poly, np.zeros(len(poly))])
    q = np.column_stack([p3 @ u, p3 @ v])
    (_, _), (w, h), _ = cv2.minAreaRect(q.astype(np.float32))
    res = 0.01
    q0 = q.min(0) - 0.05
    size = np.ceil((q.max(0) - q0 + 0.05) / res).astype(int) + 1
    m = np.zeros((size[1], size[0]), np.uint8)
    cv2.fillPoly(m, [np.round((q - q0) / res * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    dist = cv2.distanceTransform(m, cv2.DIST_L2, 5)
    return float(max(w, h)), float(min(w, h)), float(2 * dist.max() * res)


def _polygon_area(p: F64) -> float:
    x, y = p[:, 0], p[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
