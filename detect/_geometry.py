"""Metric geometry of an opening: rays, the rim plane, axes, and the hole's walls."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._options import DefaultOptions
from holescan.detect._order_stats import median
from holescan.detect._types import CameraIntrinsics

# Walls: regions grow (DefaultOptions.grow_px) into readings this far below the opening plane.
WALL_MARGIN_M = 0.06
# A reading lies on a plane when within the structured-light depth noise of it, which grows
# with the square of range: PLANE_TOL_M + PLANE_TOL_PER_M2 * z**2 (4.5 cm at 2.7 m).
PLANE_TOL_M = 0.02
PLANE_TOL_PER_M2 = 3e-3
# The terrain around an opening is its rim's surface only if this share of the rim lies on it.
TERRAIN_RIM_SHARE = 0.3
# RANSAC scores its candidate planes on at most this many points.
RANSAC_SCORED = 400
_K3 = np.ones((3, 3), np.uint8)


def rays_of(
    us: npt.NDArray[np.float64], vs: npt.NDArray[np.float64], cam: CameraIntrinsics
) -> npt.NDArray[np.float64]:
    return np.stack([(us - cam.cx) / cam.fx, (vs - cam.cy) / cam.fy, np.ones_like(us)], axis=1)


def _along(
    normal: npt.NDArray[np.float64], x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """``rays @ normal`` for the rays ``(x, y, 1)``, from their components (no (N, 3) array)."""
    return np.asarray(x * float(normal[0]) + y * float(normal[1]) + float(normal[2]))


def _plane_basis(
    normal: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Two unit vectors spanning the plane of unit ``normal``: ``normal x (0, 1, 0)``
    (``normal x (1, 0, 0)`` when that is degenerate) and ``normal x`` the first."""
    n0, n1, n2 = (float(c) for c in normal)
    e1 = np.array([-n2, 0.0, n0])
    if np.linalg.norm(e1) < 1e-6:
        e1 = np.array([0.0, n2, -n1])
    e1 /= np.linalg.norm(e1)
    a0, a1, a2 = (float(c) for c in e1)
    e2 = np.array([n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0])
    return e1, e2


def fit_plane(
    points: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Least-squares plane ``(unit normal, centroid)`` of (N, 3) camera-frame points.

    Falls back to a fronto-parallel plane when the points are too few, collinear, or the
    plane would be seen edge-on (normal more than ~72 deg from the optical axis).
    """
    centre = np.ones(len(points)) @ points / len(points)  # the mean (a BLAS product)
    normal = np.array([0.0, 0.0, 1.0])
    if len(points) >= 6:
        # The right singular vectors of the centred points are the eigenvectors of their
        # 3 x 3 scatter matrix, the squared singular values its eigenvalues (ascending):
        # the same plane as an SVD of the (N, 3) points, for much less.
        d = points - centre
        eig, vec = np.linalg.eigh(d.T @ d)
        if eig[1] > 1e-12 and abs(vec[2, 0]) > 0.3:
            normal = vec[:, 0] / np.linalg.norm(vec[:, 0])
    return normal, centre


def _depth_tol(points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return np.asarray(PLANE_TOL_M + PLANE_TOL_PER_M2 * points[:, 2] ** 2)


def on_plane(
    points: npt.NDArray[np.float64], plane: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]
) -> npt.NDArray[np.bool_]:
    """Which (N, 3) camera-frame points lie on ``(normal, centre)`` within the depth noise."""
    normal, centre = plane
    return np.asarray(np.abs((points - centre) @ normal) < _depth_tol(points))


def fit_plane_ransac(
    points: npt.NDArray[np.float64], tries: int = 200
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The plane most of (N, 3) points lie on (:func:`on_plane`), refitted to them.

    MSAC (RANSAC scored by truncated squared residuals) over planes through three of the
    points; planes seen edge-on (normal more than ~72 deg from the optical axis) are not
    candidates. The samples are drawn from a generator seeded by the number of points, so
    the same frame always gives the same plane. Falls back to :func:`fit_plane` of all
    points when fewer than 12 or no candidate is found.
    """
    n = len(points)
    if n < 12:
        return fit_plane(points)
    idx = np.random.default_rng(n).integers(0, n, size=(tries, 3))
    a, b, c = points[idx[:, 0]], points[idx[:, 1]], points[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    ok = length > 1e-9
    normals, a = normals[ok] / length[ok, None], a[ok]
    facing = np.abs(normals[:, 2]) > 0.3
    normals, a = normals[facing], a[facing]
    if not len(normals):
        return fit_plane(points)
    # Candidates are scored on at most RANSAC_SCORED points spread evenly over the set
    # (the plane most points lie on is the same; the cost no longer grows with the band).
    scored = points[:: max(1, n // RANSAC_SCORED)]
    tol = _depth_tol(scored)
    # (In place: one (planes, points) array instead of five.)
    cost = normals @ scored.T
    np.subtract(cost, np.einsum("kj,kj->k", normals, a)[:, None], out=cost)
    np.abs(cost, out=cost)  # the distances
    # MSAC: outliers cost a constant, inliers their squared residual, so of two planes
    # that hold the same points the closer one wins (not one tilted to reach a few more).
    np.divide(cost, tol, out=cost)
    np.minimum(cost, 1.0, out=cost)
    np.square(cost, out=cost)
    best = int(np.argmin(cost.sum(axis=1)))
    inliers = on_plane(points, (normals[best], a[best]))
    if inliers.sum() < 3:
        return fit_plane(points)
    plane = fit_plane(points[inliers])
    refit = on_plane(points, plane)  # once more, with the refitted plane's own inliers
    return fit_plane(points[refit]) if refit.sum() >= 6 else plane


def terrain_plane(
    around: npt.NDArray[np.float64], rim: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
    """The surface an opening is cut in, from the readings around it (camera frame, m).

    around : (N, 3) readings in a wide band around the opening (its rim ring included);
    rim : (M, 3) the rim ring's. Where the image border cuts an opening, the ring around
    its visible part is two lines: the near rim, and the top of the far wall it sees into.
    A plane through both leans toward the wall (40-50 deg on level ground seen straight
    down), and so does the centre placed on it. The terrain beyond the rim is a surface,
    not a line: the plane most of the band lies on is the terrain's. It is the rim's only
    when ``TERRAIN_RIM_SHARE`` of the rim lies on it too (rough rubble may offer a plane
    that misses the rim); otherwise None.
    """
    plane = fit_plane_ransac(around)
    if len(rim) == 0 or float(on_plane(rim, plane).mean()) < TERRAIN_RIM_SHARE:
        return None
    return plane


@dataclass(frozen=True)
class Opening:
    """An opening measured on its rim plane (camera optical frame, metres).

    major_m, minor_m : axes of the ellipse with the opening's second moments on the plane.
    area_m2 : its area on the plane.
    rim_depth_m : median axial depth of the rim.
    centre : (3,) the opening's centroid on the rim plane (area-weighted: each pixel's ray
        meets the plane in a patch whose size grows with range and obliqueness).
    normal : (3,) unit normal of the rim plane, pointing toward the camera.
    """

    major_m: float
    minor_m: float
    area_m2: float
    rim_depth_m: float
    centre: npt.NDArray[np.float64]
    normal: npt.NDArray[np.float64]


def measure_opening(
    region_uv: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
    rim_uvz: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]],
    cam: CameraIntrinsics,
    plane: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None,
) -> Opening:
    """Metric size and centre of an opening on the plane of its rim.

    region_uv : pixel coordinates of the region; rim_uvz : pixel coordinates and depth (m)
    of the valid ring around it; plane : ``(normal, point)`` of the opening's plane when
    known (:func:`terrain_plane`). Otherwise the rim's 3-D points define it (least
    squares). The region's pixel rays meet that plane in points whose area-weighted mean is
    the opening's centre and whose second moments (plus each pixel's own footprint) give the
    axes of the ellipse with the same moments.

    The centre is the opening's own, whatever the view: seen obliquely, the box of the
    region spans the visible far wall and the near rim, and the ray through the box centre
    meets the ground off the opening's centre (toward the camera).
    """
    ru, rv, rz = rim_uvz
    normal, centre = fit_plane(rays_of(ru, rv, cam) * rz[:, None]) if plane is None else plane
    if normal @ centre > 0:
        normal = -normal
    # Each pixel's ray (x, y, 1) meets the plane at t (its axial depth) in the point t * ray;
    # computed per component (regions run to thousands of pixels).
    x = (region_uv[0] - cam.cx) / cam.fx
    y = (region_uv[1] - cam.cy) / cam.fy
    along = _along(normal, x, y)
    t = float(centre @ normal) / along
    cos_incidence = np.abs(along) / np.sqrt(x * x + y * y + 1.0)
    pix_area = (t**2) / (cam.fx * cam.fy) / np.maximum(cos_incidence, 0.2)
    area = float(pix_area.sum())
    wt = pix_area * t
    mid = np.array([float(wt @ x), float(wt @ y), float(wt.sum())]) / area
    e1, e2 = _plane_basis(normal)
    # In-plane coordinates of the points, about their mean, and their covariance.
    px, py, pz = x * t - mid[0], y * t - mid[1], t - mid[2]
    a = px * e1[0] + py * e1[1] + pz * e1[2]
    b = px * e2[0] + py * e2[1] + pz * e2[2]
    saa = sab = sbb = 0.0
    if len(a) > 1:
        a -= a.mean()
        b -= b.mean()
        saa, sab, sbb = (float(u @ v) / (len(a) - 1) for u, v in ((a, a), (a, b), (b, b)))
    # Plus each pixel's own footprint (a square's variance), then the eigenvalues.
    foot = float(np.mean(pix_area)) / 12.0
    saa, sbb = saa + foot, sbb + foot
    half, spread = 0.5 * (saa + sbb), math.hypot(0.5 * (saa - sbb), sab)
    major, minor = (
        4.0 * math.sqrt(max(half + spread, 0.0)),
        4.0 * math.sqrt(max(half - spread, 0.0)),
    )
    return Opening(major, minor, area, float(median(rz)), mid, normal)


def rim_circle_centre(
    rim_uvz: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]],
    opening: Opening,
    cam: CameraIntrinsics,
) -> npt.NDArray[np.float64] | None:
    """Centre of the circle through the seen rim, on the rim plane (optical frame, m).

    For an opening the image border cuts: the centroid of its visible part lies toward the
    image, the circle through the rim it shows does not. Least squares (Kasa) on the rim's
    points in the plane. None when the fit is not a plausible opening: radius outside
    0.15-1.0 m, or a centre farther than that radius from the visible part's centroid.
    """
    ru, rv, rz = rim_uvz
    if len(rz) < 8:
        return None
    pts = rays_of(ru, rv, cam) * rz[:, None]
    e1, e2 = _plane_basis(opening.normal)
    rel = pts - opening.centre
    x, y = rel @ e1, rel @ e2
    a = np.column_stack([2.0 * x, 2.0 * y, np.ones_like(x)])
    sol, *_ = np.linalg.lstsq(a, x * x + y * y, rcond=None)
    cx, cy, c = (float(v) for v in sol)
    r2 = c + cx * cx + cy * cy
    if not r2 > 0.0:
        return None
    r = math.sqrt(r2)
    if not 0.15 <= r <= 1.0 or math.hypot(cx, cy) > r:
        return None
    out: npt.NDArray[np.float64] = opening.centre + cx * e1 + cy * e2
    return out


def opening_axes(
    region_uv: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
    rim_uvz: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]],
    cam: CameraIntrinsics,
) -> tuple[float, float, float, float]:
    """``(major_m, minor_m, area_m2, rim_depth_m)`` of :func:`measure_opening`."""
    o = measure_opening(region_uv, rim_uvz, cam)
    return o.major_m, o.minor_m, o.area_m2, o.rim_depth_m


@cache
def disk(r: int) -> npt.NDArray[np.uint8]:
    """The disk of radius ``r`` (an OpenCV ellipse kernel); shared: do not write to it."""
    return np.asarray(
        cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)), np.uint8
    )


def grow_walls(
    inside: npt.NDArray[np.bool_],
    zc: npt.NDArray[np.float32],
    valid: npt.NDArray[np.bool_],
    uv0: tuple[int, int],
    cam: CameraIntrinsics,
    ring_px: int,
    grow_px: int = DefaultOptions.grow_px,
) -> npt.NDArray[np.bool_]:
    """Add the hole's walls: readings next to the region that lie below the opening plane.

    The plane is fitted to the readings of a ring a few pixels out (the surrounding
    terrain); pixels connected to the region and deeper than the plane by ``WALL_MARGIN_M``
    are wall or floor. Up to ``grow_px`` pixels of growth, so a tilted view's visible far
    wall joins the opening (its box is the rim's).
    """
    u8 = inside.astype(np.uint8)
    # The ring between the two dilations (the smaller disk lies inside the larger).
    outer = (cv2.dilate(u8, disk(ring_px + 3)) > cv2.dilate(u8, disk(ring_px))) & valid
    if np.count_nonzero(outer) < 6:
        return inside
    ov, ou = np.nonzero(outer)
    normal, centre = fit_plane(
        rays_of(ou.astype(np.float64) + uv0[0], ov.astype(np.float64) + uv0[1], cam)
        * zc[outer].astype(np.float64)[:, None]
    )
    # The plane's depth along every pixel's ray, from a row and a column of ray components.
    x = (np.arange(zc.shape[1], dtype=np.float64) + uv0[0] - cam.cx) / cam.fx
    y = (np.arange(zc.shape[0], dtype=np.float64) + uv0[1] - cam.cy) / cam.fy
    z_plane = float(centre @ normal) / _along(normal, x[None, :], y[:, None])
    below = (valid & (zc > z_plane + WALL_MARGIN_M)).view(np.uint8)
    region = u8
    for _ in range(grow_px):
        grown = (np.asarray(cv2.dilate(region, _K3), np.uint8) & below) | region
        if np.count_nonzero(grown) == np.count_nonzero(region):  # grown holds region
            break
        region = grown
    return region.view(bool)


def occluders(
    ru: npt.NDArray[np.float64],
    rv: npt.NDArray[np.float64],
    rz: npt.NDArray[np.float64],
    cam: CameraIntrinsics,
    step_m: float = DefaultOptions.occluder_step_m,
) -> tuple[npt.NDArray[np.bool_], tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None]:
    """Rim points that stand well in front of the plane of the others: a nearer edge.

    ru, rv : pixel coordinates of the rim; rz : their depth (m). A slab lying across the
    opening hides its near part; its edge borders the visible part of the hole and is no
    rim. Points more than ``step_m`` nearer than the plane fitted to the rim
    (refitted once without them) are flagged.

    Returns ``(flagged, plane)``: plane is :func:`fit_plane` of the points not flagged
    when that is the last plane fitted (the rim's plane, not fitted twice), else None.
    """
    near = np.zeros(len(rz), bool)
    rays = rays_of(ru, rv, cam)
    for _ in range(2):
        keep = ~near
        if np.count_nonzero(keep) < 6:
            break
        normal, centre = fit_plane(rays[keep] * rz[keep, None])
        z_plane = float(centre @ normal) / _along(normal, rays[:, 0], rays[:, 1])
        now = rz < z_plane - step_m
        if not now.any() or np.array_equal(now, near):
            return now, ((normal, centre) if np.array_equal(~now, keep) else None)
        near = now
    return near, None
