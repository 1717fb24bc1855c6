"""Measuring one candidate region of the default detector (:mod:`detect._default`).

A region found on the work grid is grown by its walls, ringed by its rim (the valid
readings around it, minus nearer edges standing in front), and measured in metres on the
plane fitted to that rim: the opening's axes, area, passable width and centre, how much of
its outline the sensor saw, the paper's five attribute scores and their combination, and
for an unread region the photometric void evidence and the rim-plane test. What it keeps
is what NMS (:mod:`detect._suppress`), the box refinement (:mod:`detect._boxes`) and the
placement of an opening the border cuts need afterwards. Pure: arrays in, records out.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import NamedTuple, TypeVar, cast

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._geometry import (
    Opening,
    grow_walls,
    measure_opening,
    occluders,
    rays_of,
)
from holescan.detect._order_stats import median, percentile
from holescan.detect._photometry import void_evidence
from holescan.detect._regions import Candidate
from holescan.detect._scores import (
    combined_score,
    contrast_score,
    darkness_score,
    ramp,
    width_score,
)
from holescan.detect._surface import MIN_INNER_PX, plane_evidence, surface_factor
from holescan.detect._types import CameraIntrinsics, Detection, DetectParams, FeatureScores

__all__ = [
    "DARK_CUT",
    "RING_PX",
    "SURFACE_GATE",
    "TERRAIN_PX",
    "Cut",
    "FrameData",
    "Measured",
    "ReadBox",
    "Shape",
    "measure",
    "xyz",
]

# A candidate needs this fraction of its rim to be valid readings (not border, not no-reading).
MIN_RIM_VALID = 0.6
# The design choices the ablation study switches off are fields of DetectParams.options
# (detect._options.DefaultOptions), passed down the call.
# Openings larger than this (major axis, m) are broad terrain, not holes: width score fades.
OVERSIZE_START_M = 3.5
OVERSIZE_END_M = 6.0
RING_PX = 2
# An opening cut by the image border is placed at the centre of the circle through its seen
# rim (options.cut_circle; benchmarks/bench_geotag.py) on the plane of the terrain read this
# many work pixels beyond its ring (the ring alone runs along the near rim and the top of
# the far wall: two lines, and a plane leaning into the hole through both).
TERRAIN_PX = 6
# The dark part of spilled no-reading blobs (options.dark_split): relative luminance
# (box-averaged over work pixels against shot noise in dark frames) below DARK_CUT. Unread
# rim pixels this lit count as seen rim of a region cut from them by colour.
DARK_CUT = 0.75
# A basin cut by the frame border (or a band) is also looked at closed there
# (options.closed_border), and, with a read floor, counts when clearly deep (depth score
# from 0 at the first to 1 at the second; Sd 0.2 = 0.55 m below the bridged rim for a human
# searcher) or dark inside as a hole is (darkness score, likewise): a shallow lit dip
# running into the border closes that way too.
BRIDGED_SD = (0.2, 0.35)
BRIDGED_DARK = (0.1, 0.25)
# The rim-plane test (options.surface_plane) only for unread candidates scoring at least
# this (p_hole ~0.1): below, it could only lower what is not shown anyway. A candidate it
# lowers keeps at least SURFACE_GATE x SURFACE_FLOOR = 0.08, above the default min_score:
# it stays a detection, and a sighting whose reading the hole-level vote counts.
SURFACE_GATE = 0.2

_T = TypeVar("_T")


@dataclass(frozen=True)
class FrameData:
    """One frame as the measuring sees it, on the read area's work grid: depth (m, NaN
    unread), the no-reading mask, luminance and its relative luminance, the work camera,
    the farthest reading and the range, the block factor, the bands cut off, and a memo of
    what measuring a region found (:meth:`once`)."""

    z: npt.NDArray[np.float32]
    invalid: npt.NDArray[np.bool_]
    y_img: npt.NDArray[np.float64]
    rel: npt.NDArray[np.float64]
    cam: CameraIntrinsics
    z_far: float
    range_m: float
    factor: int
    #: The read area's place in the work grid: unread bands (left, top, right, bottom).
    bands: tuple[int, int, int, int] = (0, 0, 0, 0)
    rel_smooth: npt.NDArray[np.float32] | None = None
    #: What measuring a region found that the way it was found does not change (:meth:`once`).
    memo: dict[Hashable, object] = field(default_factory=dict, compare=False)

    def once(self, key: Hashable, compute: Callable[[], _T]) -> _T:
        """``compute()``, or what it gave for ``key`` before in this frame: a region found
        twice (a no-reading blob that is also a basin closed at the border, a blob that is
        all dark) has its walls, rim plane, opening and widest disk measured once."""
        if key not in self.memo:
            self.memo[key] = compute()
        return cast(_T, self.memo[key])


_RING_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * RING_PX + 1, 2 * RING_PX + 1))


def measure(
    region: Candidate,
    f: FrameData,
    params: DetectParams,
    dark_cut: bool = False,
    bridged: bool = False,
) -> Measured | None:
    """Measure one candidate region and score it; None when it cannot be a hole.

    A no-reading blob (not enclosed) must show enough valid rim (not border, not more
    no-reading) around it. A ``bridged`` basin (closed only by bridging its cut at the
    border) with a read floor must be clearly deep or dark inside: its depth is measured
    against a rim partly assumed, and a shallow lit dip running into the border is closed
    that way too.
    """
    mask, enclosed = region.mask, region.enclosed
    x, y, w, h = region.box
    hh, ww = f.z.shape
    o = params.options
    pad = RING_PX + o.grow_px + 4 + TERRAIN_PX
    x0, y0 = max(0, x - pad), max(0, y - pad)
    x1, y1 = min(ww, x + w + pad), min(hh, y + h + pad)
    zc, inv_c = f.z[y0:y1, x0:x1], f.invalid[y0:y1, x0:x1]
    inside = np.zeros((y1 - y0, x1 - x0), bool)
    inside[y - y0 : y - y0 + h, x - x0 : x - x0 + w] = mask
    key = (region.box, mask.tobytes())  # what follows depends on the region, not its flags
    inside = f.once(
        (key, "walls"),
        lambda: grow_walls(inside, zc, ~inv_c, (x0, y0), f.cam, RING_PX, o.grow_px),
    )
    big = inside.astype(np.uint8)
    vs, us = np.nonzero(inside)
    bx0, by0, bx1, by1 = int(us.min()), int(vs.min()), int(us.max()) + 1, int(vs.max()) + 1
    ring_all = cv2.dilate(big, _RING_KERNEL).astype(bool) & ~inside
    ring = ring_all & ~inv_c
    # The image border counts as rim we could not see.
    gx0, gy0, gx1, gy1 = bx0 + x0, by0 + y0, bx1 + x0, by1 + y0
    open_px = np.count_nonzero(inside[:, 0]) if gx0 == 0 else 0
    open_px += np.count_nonzero(inside[:, -1]) if gx1 == ww else 0
    open_px += np.count_nonzero(inside[0, :]) if gy0 == 0 else 0
    open_px += np.count_nonzero(inside[-1, :]) if gy1 == hh else 0
    n_ring = np.count_nonzero(ring)
    if n_ring < 3:
        return None
    n_rim = n_ring
    if dark_cut:  # cut from bright unread pixels by colour: those are seen rim too
        n_rim += np.count_nonzero(ring_all & inv_c & (f.rel[y0:y1, x0:x1] >= DARK_CUT))
    if not enclosed and n_rim < MIN_RIM_VALID * (np.count_nonzero(ring_all) + RING_PX * open_px):
        return None
    rv, ru = np.nonzero(ring)
    rim_u, rim_v = ru.astype(np.float64) + x0, rv.astype(np.float64) + y0
    rim_zs = zc[ring].astype(np.float64)
    # Passable width: diameter of the largest disk inside the region (metres at the rim).
    # Where an unread band cuts it, the opening runs on under the band: the disk may too
    # (the region's cut edge extruded across the band), and the ellipse's minor axis,
    # measured on the visible part only, is no bound.
    cut_sides = (
        f.bands[0] if gx0 == 0 else 0,
        f.bands[1] if gy0 == 0 else 0,
        f.bands[2] if gx1 == ww else 0,
        f.bands[3] if gy1 == hh else 0,
    )
    widest = f.once(
        (key, "disk"),
        lambda: float(
            cv2.distanceTransform(np.pad(_extrude(big, cut_sides), 1), cv2.DIST_L2, 5).max()
        ),
    )
    s = params.searcher
    if (
        o.passable_width
        and params.min_score > 0.0
        and 2.0 * widest * float(rim_zs.max()) / f.cam.fx < s.min_fraction * s.minor_m
    ):
        # Too narrow to enter, whatever the rim's plane: the minor axis is at most the
        # widest disk at the rim's median depth, and that lies within the rim's depths.
        return None
    occ, rim_plane = f.once(
        (key, "occluders"), lambda: occluders(rim_u, rim_v, rim_zs, f.cam, o.occluder_step_m)
    )
    if occ.any() and np.count_nonzero(~occ) >= 3:
        rim_u, rim_v, rim_zs = rim_u[~occ], rim_v[~occ], rim_zs[~occ]
    # How much of the opening's outline is bordered by rim we saw: not the image border,
    # not unread pixels, not a nearer edge standing in front.
    outline = np.count_nonzero(ring_all) + RING_PX * open_px
    rim_seen = min(1.0, (n_rim - np.count_nonzero(occ)) / outline)
    region_uv = (us.astype(np.float64) + x0, vs.astype(np.float64) + y0)
    # The rim's plane: the one the occluder test fitted to these very points, if it did.
    opening = f.once(
        (key, "opening"),
        lambda: measure_opening(region_uv, (rim_u, rim_v, rim_zs), f.cam, plane=rim_plane),
    )
    major, minor_pca, area, rim_z = (
        opening.major_m,
        opening.minor_m,
        opening.area_m2,
        opening.rim_depth_m,
    )
    inscribed = 2.0 * widest * rim_z / f.cam.fx
    if not o.passable_width:
        minor = minor_pca
    elif any(cut_sides):
        minor = inscribed
    else:
        minor = min(minor_pca, inscribed)
    sw = width_score(major, minor, s.major_m, s.minor_m, s.min_fraction)
    sw *= 1.0 - ramp(major, OVERSIZE_START_M, OVERSIZE_END_M)
    if sw == 0.0 and params.min_score > 0.0:
        return None  # too narrow (or too broad) to enter: scores 0 whatever the rest is
    floor_valid = inside & ~inv_c
    no_read = float(np.count_nonzero(inside & inv_c)) / float(np.count_nonzero(inside))
    seen = float(percentile(zc[floor_valid], 90) - rim_z) if floor_valid.any() else 0.0
    yc = f.y_img[y0:y1, x0:x1]
    y_in, y_ring = float(yc[inside].mean()), float(yc[ring].mean())
    sb = darkness_score(y_in, params.dark_threshold)
    sc = contrast_score(y_in, y_ring, params.contrast_threshold)
    beyond = no_read > 0.3
    rel_in = float(median(f.rel[y0:y1, x0:x1][inside & inv_c])) if beyond else 0.0
    if beyond:
        # The floor gave no reading. It lies at least as far as the sensor's range; and the
        # nearer the rim is than the farthest reading of the frame, the surer it is that a
        # floor near the rim would have been read. At the range limit itself, only the
        # light can tell a hole (dark inside) from terrain fading out of range.
        depth_rel = max(seen, f.range_m - rim_z)
        within = ramp(f.z_far - rim_z, 0.1, 0.6)
        light = max(sb, sc) if o.range_limit_light else 0.0
        sd = max(ramp(depth_rel, s.depth_low_m, s.depth_high_m), 0.6 * within + 0.4 * light)
    else:
        depth_rel = seen
        sd = ramp(depth_rel, s.depth_low_m, s.depth_high_m)
    fill = area / (major * minor_pca) if major * minor_pca > 0 else 0.0
    sr = ramp(fill, 0.3, 0.7)
    score = combined_score(sd, sw, sr, sb, sc, o.depth_exponent)
    plane_read: tuple[float, float] | None = None
    if beyond:
        # No reading: a void only if it looks like one (dark against the rubble around it),
        # and not a surface that returns no infrared (read islands on its rim plane).
        score *= 0.2 + 0.8 * (void_evidence(rel_in) if o.photometric_evidence else 1.0)
        if o.surface_plane and score >= SURFACE_GATE:
            rim_pts = rays_of(rim_u, rim_v, f.cam) * rim_zs[:, None]
            ev = plane_evidence(
                inside, zc, ~inv_c, (x0, y0), f.cam, (opening.normal, opening.centre), rim_pts
            )
            score *= surface_factor(ev)
            if ev.inner_px >= MIN_INNER_PX:
                plane_read = (round(ev.on_plane, 4), round(ev.behind, 4))
    elif bridged:
        score *= max(ramp(sd, *BRIDGED_SD), ramp(sb, *BRIDGED_DARK))
    if score < params.min_score:
        return None
    box = _frame_box((gx0, gy0, gx1, gy1), (ww, hh), f)
    det = Detection(
        box=box,
        score=float(score),
        features=FeatureScores(sd, sw, sr, sb, sc),
        depth_rel_m=float(depth_rel),
        major_m=major,
        minor_m=minor,
        rim_depth_m=rim_z,
        beyond_range=beyond,
        relative_brightness=round(rel_in, 3) if beyond else None,
        opening_m=xyz(opening.centre),
        rim_normal=xyz(opening.normal),
        rim_seen=round(max(rim_seen, 0.0), 3),
        border_cut=bool(open_px),
        inside_on_plane=plane_read[0] if plane_read else None,
        inside_behind=plane_read[1] if plane_read else None,
    )
    # Sizes (and so the score) come from the rim's plane; where the opening is, from the
    # terrain's when the border cuts it: placed once the detection has outlived NMS.
    read = ReadBox((gx0, gy0, gx1, gy1), (ww, hh), bridged, enclosed)
    shape = Shape(inside[by0:by1, bx0:bx1], (gx0, gy0), (opening.normal, opening.centre))
    if not (open_px and o.cut_circle):
        return Measured(det, None, read, shape)
    return Measured(
        det,
        Cut(opening, region_uv, (rim_u, rim_v, rim_zs), inside, inv_c, zc, (x0, y0)),
        read,
        shape,
    )


class Cut(NamedTuple):
    """What placing an opening the border cuts needs (:func:`_place`)."""

    opening: Opening
    region_uv: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]
    rim_uvz: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]
    inside: npt.NDArray[np.bool_]
    invalid: npt.NDArray[np.bool_]
    zc: npt.NDArray[np.float32]
    origin: tuple[int, int]


class ReadBox(NamedTuple):
    """Where a measured region lies on the read area (work pixels), for NMS."""

    box: tuple[int, int, int, int]  # x0, y0, x1, y1
    size: tuple[int, int]  # the read area's width, height
    bridged: bool  # a basin closed by bridging its cut at the border
    enclosed: bool  # a pit of the basin analysis (its rim holds all round)


class Shape(NamedTuple):
    """A measured region as :func:`pixel_box` refines its box."""

    mask: npt.NDArray[np.bool_]  # the region (walls included) inside its box
    origin: tuple[int, int]  # its box's top-left, read-area work pixels
    plane: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]  # the rim's (normal, point)


class Measured(NamedTuple):
    """A measured candidate: its detection (box on the work grid), what placing it needs
    when the border cuts it, where it lies on the read area (NMS), and its shape (the box
    refinement)."""

    det: Detection
    cut: Cut | None
    read: ReadBox | None = None
    shape: Shape | None = None


def _extrude(
    mask: npt.NDArray[np.uint8], sides: tuple[int, int, int, int]
) -> npt.NDArray[np.uint8]:
    """``mask`` with its edge rows/columns repeated outward (left, top, right, bottom)."""
    left, top, right, bottom = sides
    if not any(sides):
        return mask
    out = np.concatenate(
        [np.repeat(mask[:, :1], left, 1), mask, np.repeat(mask[:, -1:], right, 1)], 1
    )
    return np.concatenate([np.repeat(out[:1], top, 0), out, np.repeat(out[-1:], bottom, 0)], 0)


def _frame_box(
    read_box: tuple[int, int, int, int], read_size: tuple[int, int], f: FrameData
) -> tuple[int, int, int, int]:
    """(x, y, w, h) in frame pixels of a box ``(x0, y0, x1, y1)`` on the read area.

    Where the box reaches an unread band, the opening runs on under it (its rim there is
    unknown): the box extends across the band to the frame's edge.
    """
    x0, y0, x1, y1 = read_box
    left, top, right, bottom = f.bands
    ww, hh = read_size
    x0, x1 = (0 if x0 == 0 else x0 + left), (x1 + left + right if x1 == ww else x1 + left)
    y0, y1 = (0 if y0 == 0 else y0 + top), (y1 + top + bottom if y1 == hh else y1 + top)
    k = f.factor
    return (x0 * k, y0 * k, (x1 - x0) * k, (y1 - y0) * k)


def xyz(v: npt.NDArray[np.float64]) -> tuple[float, float, float]:
    return (round(float(v[0]), 4), round(float(v[1]), 4), round(float(v[2]), 4))
