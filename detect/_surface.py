"""Is an unread region a void or a surface that returns no infrared? The plane test.

Soot, char, wet or black material swallows most of a structured-light sensor's pattern:
55-76 % of such a patch is unread, in clumps, and it is dark in colour (0.3-0.55 of the
rubble's brightness). To depth alone and to the light it is a deep void. What differs is
the geometry of what *is* read: an absorbing patch is a surface, so its rim is coplanar
with the terrain and the islands of readings left inside its outline lie **on** the rim's
plane; a void's readings inside (walls, ledges, the floor) lie **behind** it.

:func:`plane_evidence` looks only at read pixels well inside the outline (the outline's
own pixels are the hole's upper walls, fattened rim and flying pixels), measures their
distance from the rim plane against the rim's own roughness, and returns the fractions of
the interior that are read on the plane and read behind it. :func:`surface_factor` turns
that into the factor the candidate's score is multiplied by: 1 (no change) unless the
interior is clearly read on the plane and nothing of it behind; a hole whose inside is
unread throughout, or read behind the plane, is never touched (recall first).

One view is weak evidence (a few islands, a grazing view); many views are strong: a void
shows its walls behind the plane from somewhere, a black patch is read on its plane again
and again. The detection keeps the two fractions (:attr:`Detection.inside_on_plane`,
:attr:`Detection.inside_behind`) and :func:`plane_verdict` says what one view read; the
tracker counts the verdicts over a hole's viewpoints and the announce gate holds a hole
that most views read on its plane for review (:mod:`geotag`).

Pure and cheap: run only for candidates with no floor readings, on their crop.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple, get_args

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._order_stats import median
from holescan.detect._scores import ramp
from holescan.detect._types import CameraIntrinsics

__all__ = [
    "PLANE_VERDICTS",
    "PlaneEvidence",
    "PlaneVerdict",
    "plane_evidence",
    "plane_verdict",
    "surface_factor",
]

# "Well inside": read pixels at least this fraction of the outline's inscribed radius from
# its edge, and at least INNER_MIN_PX work pixels.
INNER_FRACTION = 0.35
INNER_MIN_PX = 1.5
# On the plane: within PLANE_TOL_M + PLANE_TOL_PER_M2 Z^2 (block-averaged noise and 1/8 px
# quantisation at Z), or ROUGHNESS_K x the rim's own scatter about its plane when rougher.
PLANE_TOL_M = 0.03
PLANE_TOL_PER_M2 = 0.004
ROUGHNESS_K = 2.5
# Gaps in the outline closed up to this radius (work pixels).
CLOSE_PX = 3
_CLOSE = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * CLOSE_PX + 1, 2 * CLOSE_PX + 1))
# Too few interior pixels to say anything: no evidence.
MIN_INNER_PX = 6


class PlaneEvidence(NamedTuple):
    """What the readings inside an unread region's outline say about it.

    inner_px : pixels well inside the outline (the region with its read islands filled in).
    on_plane : fraction of them read on the rim's plane (a surface's islands).
    behind : fraction of them read behind the plane (a void's walls and floor).
    tol_m : the tolerance used for "on the plane".
    """

    inner_px: int
    on_plane: float
    behind: float
    tol_m: float


NO_EVIDENCE = PlaneEvidence(0, 0.0, 0.0, 0.0)


def plane_evidence(
    inside: npt.NDArray[np.bool_],
    z: npt.NDArray[np.float32],
    read: npt.NDArray[np.bool_],
    origin: tuple[int, int],
    cam: CameraIntrinsics,
    plane: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
    rim: npt.NDArray[np.float64],
) -> PlaneEvidence:
    """Readings well inside a region's outline against its rim plane.

    inside : (h, w) the region (crop of the work grid at ``origin`` = (x0, y0));
    z : (h, w) depth, metres (NaN or anything where not ``read``); read : (h, w) readings;
    plane : ``(normal, point)`` of the rim plane, normal toward the camera; rim : (N, 3)
    the rim's points (its scatter about the plane sets the tolerance).

    Examples
    --------
    A flat floor 2 m away with an unread ring whose inside is read on the floor (a black
    ring of soot), then the same ring around a pit 1 m deeper:

    >>> cam = CameraIntrinsics(40, 40, 50.0, 50.0, 19.5, 19.5, 0.001)
    >>> z = np.full((40, 40), 2.0, np.float32)
    >>> yy, xx = np.mgrid[:40, :40]
    >>> inside = np.hypot(xx - 19.5, yy - 19.5) < 12
    >>> read = ~inside | (np.hypot(xx - 19.5, yy - 19.5) < 7)
    >>> rim = np.array([[x, y, 2.0] for x in (-0.3, 0.0, 0.3) for y in (-0.3, 0.3)])
    >>> plane = (np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 2.0]))
    >>> ev = plane_evidence(inside & ~read, z, read, (0, 0), cam, plane, rim)
    >>> ev.on_plane > 0.5, ev.behind
    (True, 0.0)
    >>> z[np.hypot(xx - 19.5, yy - 19.5) < 7] = 3.0
    >>> ev = plane_evidence(inside & ~read, z, read, (0, 0), cam, plane, rim)
    >>> ev.on_plane, ev.behind > 0.5
    (0.0, True)
    """
    # The outline: the region closed over gaps up to CLOSE_PX (islands of readings that
    # reach its edge between unread clumps) with its enclosed islands filled in.
    pad = CLOSE_PX + 1
    closed = cv2.morphologyEx(np.pad(inside, pad).astype(np.uint8), cv2.MORPH_CLOSE, _CLOSE)
    # Enclosed gaps filled: whatever the background flooded from the corner does not reach.
    outside = closed.copy()
    cv2.floodFill(outside, None, (0, 0), 1)
    filled = ((closed > 0) | (outside == 0))[pad:-pad, pad:-pad]
    if int(filled.sum()) < MIN_INNER_PX:
        return NO_EVIDENCE
    dist = cv2.distanceTransform(np.pad(filled, 1).astype(np.uint8), cv2.DIST_L2, 3)[1:-1, 1:-1]
    cut = max(INNER_MIN_PX, INNER_FRACTION * float(dist.max()))
    inner = dist >= cut
    n_inner = int(inner.sum())
    if n_inner < MIN_INNER_PX:
        return NO_EVIDENCE
    normal, point = plane
    resid = (rim - point) @ normal
    rough = float(median(np.abs(resid - median(resid)))) * 1.4826 if len(rim) else 0.0
    pick = inner & read
    if not pick.any():
        return PlaneEvidence(n_inner, 0.0, 0.0, 0.0)
    vs, us = np.nonzero(pick)
    zs = z[pick].astype(np.float64)
    x0, y0 = origin
    pts = np.stack([(us + x0 - cam.cx) / cam.fx * zs, (vs + y0 - cam.cy) / cam.fy * zs, zs], axis=1)
    d = (pts - point) @ normal  # > 0 toward the camera, < 0 behind the plane
    tol = np.maximum(PLANE_TOL_M + PLANE_TOL_PER_M2 * zs**2, ROUGHNESS_K * rough)
    on = int((np.abs(d) <= tol).sum())
    behind = int((d < -tol).sum())
    return PlaneEvidence(n_inner, on / n_inner, behind / n_inner, float(median(tol)))


# A surface when at least ON_PLANE[1] of the interior is read on the plane (ramp from
# ON_PLANE[0]) and at most BEHIND[0] of the interior's readings lie behind it (ramp to
# BEHIND[1]: rubble under a stain is rough, a void's readings are mostly behind); the score
# then falls to SURFACE_FLOOR of its value at full evidence. Measured over many stains and
# holes (docs/detector.md): access holes read at most ~6 % of their interior on the plane.
ON_PLANE = (0.2, 0.35)
BEHIND = (0.3, 0.5)
SURFACE_FLOOR = 0.4


def surface_factor(ev: PlaneEvidence) -> float:
    """Factor on the score of an unread candidate: 1 for a void (or no evidence), down to
    :data:`SURFACE_FLOOR` for a surface whose interior is read on its rim plane.

    >>> surface_factor(PlaneEvidence(40, 0.4, 0.0, 0.05))
    0.4
    >>> surface_factor(PlaneEvidence(40, 0.3, 0.4, 0.05)), surface_factor(NO_EVIDENCE)
    (1.0, 1.0)
    """
    if ev.inner_px < MIN_INNER_PX or ev.on_plane <= 0.0:
        return 1.0
    behind_share = ev.behind / (ev.on_plane + ev.behind)
    e = ramp(ev.on_plane, *ON_PLANE) * (1.0 - ramp(behind_share, *BEHIND))
    return round(1.0 - (1.0 - SURFACE_FLOOR) * e, 6)


PlaneVerdict = Literal["surface", "behind", "unread", "mixed"]
"""What one view read inside an unread region: ``surface`` (read on the rim's plane,
nothing behind it), ``behind`` (read behind the plane: walls, a floor), ``unread``
(nothing read well inside) or ``mixed`` (some of both, or too little of either)."""
PLANE_VERDICTS: tuple[PlaneVerdict, ...] = get_args(PlaneVerdict)

# One view reads a surface when at least VERDICT_ON_PLANE of the interior is read on the
# plane and no more of it behind (share of the readings behind <= VERDICT_BEHIND_SHARE); it
# reads behind when at least VERDICT_BEHIND of the interior lies behind the plane and more
# of it than on. Set on the tuning worlds of benchmarks/absorbing_eval.py (1,110 views of
# access holes, 199 of absorbing stains): a hole's interior is read on its plane in at most
# 6 % of it in 95 % of views (17 % in 99 %), a stain's in 32 % in the median; readings
# behind the plane come with both (a stain over rough rubble, a rim fitted across a slope),
# so a view reads "behind" only when they outweigh those on the plane.
VERDICT_ON_PLANE = 0.15
VERDICT_BEHIND_SHARE = 0.5
VERDICT_BEHIND = 0.05


def plane_verdict(on_plane: float | None, behind: float | None) -> PlaneVerdict | None:
    """One view's verdict from its interior fractions (:attr:`Detection.inside_on_plane`,
    :attr:`Detection.inside_behind`); None when not measured (or not numbers in [0, 1]).

    >>> plane_verdict(0.4, 0.0), plane_verdict(0.05, 0.5), plane_verdict(0.0, 0.0)
    ('surface', 'behind', 'unread')
    >>> plane_verdict(0.1, 0.02), plane_verdict(None, None), plane_verdict(float("nan"), 0.0)
    ('mixed', None, None)
    """
    if on_plane is None or behind is None:
        return None
    if not (math.isfinite(on_plane) and math.isfinite(behind)):
        return None
    if not (0.0 <= on_plane <= 1.0 and 0.0 <= behind <= 1.0):
        return None
    if on_plane <= 0.0 and behind <= 0.0:
        return "unread"
    share = behind / (on_plane + behind)
    if on_plane >= VERDICT_ON_PLANE and share <= VERDICT_BEHIND_SHARE:
        return "surface"
    if behind >= VERDICT_BEHIND and behind > on_plane:
        return "behind"
    return "mixed"
