"""holescan's default detector: depth basins below their spill level, scored like the paper.

The paper over-segments depth into K superpixels and asks which superpixel is deeper than
its neighbours. That fails in the ways ALGORITHM.md lists (one K for every hole size,
no-reading pixels treated as noise, sizes in pixels of a fixed K). Here the candidates are
the *basins* of the depth image instead, found at every scale at once:

1. Depth is block-averaged to ``work_scale`` (valid readings only) and turned into a height
   ``H = -Z`` (camera axial depth ``Z``, metres). Pixels with no reading get a height below
   every reading: enclosed by valid rubble, no reading means *deeper than the sensor's range*.
2. Grey-level reconstruction by erosion (the values of ``skimage.morphology.reconstruction``,
   computed as iterated OpenCV erosions: :func:`detect._regions.basin_depth`) fills every
   basin of ``H`` up to its spill level; ``pit = filled - H`` is how far each pixel lies below
   the lowest point of the rim around it. A tilted plane has no basin; a basin open to the
   image border spills there, so holes cut by the border are not reported (the dataset marks
   those ``iscrowd``).
3. Candidates are connected components of ``pit > deep_m``, each with the connected part of
   its basin deeper than a cut suited to the core (:func:`detect._regions.basin_regions`);
   when that basin is much larger than its no-reading part (a hole in a broad depression),
   each no-reading blob is a candidate too. No-reading blobs that spill (they touch the
   border or the unread band at the range limit) are cut at their necks
   (:func:`detect._regions.no_reading_regions`) and, second, along their *dark* part: a
   hole's unread interior is dark against the rubble, the terrain beyond range it runs into
   is lit (:mod:`detect._photometry`, relative luminance, so dawn exposure and tint do not
   matter).
4. Each region is measured in metres: the rim is the ring of valid pixels around it, minus
   readings standing well in front of the rest (a nearer slab edge hiding part of the
   opening is not rim); a plane fitted to the rim's 3-D points is the opening, and the
   region's pixel rays meet it in points whose principal axes give the opening's major/minor
   axes (``4 sqrt(lambda)``, the ellipse of equal second moments, as the paper's ellipse
   fit); the passable width is the largest inscribed disk. Their area-weighted mean is the
   opening's centre on the rim plane (``Detection.opening_m``, where geotagging puts the
   hole: seen obliquely, the box spans the near rim and the visible far wall and its centre
   lies toward the camera); for an opening the image border cuts, the centre of the circle
   through the rim it shows, on the plane of the terrain around it (RANSAC over a band
   beyond the rim: the ring alone is the near rim plus the top of the far wall, and a plane
   through those two lines leans into the hole). ``rim_seen`` is the fraction of its
   outline bordered by rim the sensor saw (not the border, no unread pixels, no nearer
   edge).
5. The five attribute scores of the paper are kept (so a rescuer sees *why*), but combined so
   that geometry is necessary (:func:`detect._scores.combined_score`: ``sqrt(Sd) * Sw *
   (0.35 + 0.65 Sr) * (0.85 + 0.15 max(Sb, Sc))``), times ``0.2 + 0.8 V`` for a region
   without floor readings, V the photometric void evidence (1 when its unread pixels are
   much darker than the rubble around them, 0 when as bright or brighter: sheet metal, a
   puddle, a tarp). A dark stain or
   a shadow has no depth and never becomes a candidate; a shallow dip scores low on Sd, a
   crack or a small hole low on Sw. Overlapping boxes, and boxes holding a better one, are
   suppressed (NMS). ``p_hole`` maps the score to a probability (:mod:`detect._calibration`).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field, replace
from typing import NamedTuple, TypeVar, cast

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._boxes import refine_box
from holescan.detect._calibration import p_hole_of_score
from holescan.detect._evaluate import overlap
from holescan.detect._geometry import (
    Opening,
    disk,
    grow_walls,
    measure_opening,
    occluders,
    opening_axes,
    rays_of,
    rim_circle_centre,
    terrain_plane,
)
from holescan.detect._order_stats import median, percentile
from holescan.detect._photometry import relative_luminance, void_evidence
from holescan.detect._regions import (
    BAND_MAX_PX,
    SHALLOW_M,
    Candidate,
    basin_depth,
    basin_depths,
    basin_regions,
    block_depth,
    components,
    no_reading_regions,
    trim_spurs,
    unread_bands,
)
from holescan.detect._scores import (
    combined_score,
    contrast_score,
    darkness_score,
    ramp,
    width_score,
)
from holescan.detect._surface import MIN_INNER_PX, plane_evidence, surface_factor
from holescan.detect._types import CameraIntrinsics, Detection, DetectParams, FeatureScores
from holescan.detect._validate import check_frame

__all__ = [
    "basin_depth",
    "basin_labels",
    "block_depth",
    "box_iou",
    "detect_default",
    "opening_axes",
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
# (box-averaged over DARK_SMOOTH_PX work pixels against shot noise in dark frames) below
# DARK_CUT.
DARK_CUT = 0.75
DARK_SMOOTH_PX = 5
# Unread border bands (options.bands: registered structured-light depth, at most
# BAND_MAX_PX wide) are cut off the frame.
# A basin cut by the frame border (or a band) is also looked at closed there
# (options.closed_border), and, with a read floor, counts when clearly deep (depth score
# from 0 at the first to 1 at the second; Sd 0.2 = 0.55 m below the bridged rim for a human
# searcher) or dark inside as a hole is (darkness score, likewise): a shallow lit dip
# running into the border closes that way too.
BRIDGED_SD = (0.2, 0.35)
# The rim-plane test (options.surface_plane) only for unread candidates scoring at least
# this (p_hole ~0.1): below, it could only lower what is not shown anyway. A candidate it
# lowers keeps at least SURFACE_GATE x SURFACE_FLOOR = 0.08, above the default min_score:
# it stays a detection, and a sighting whose reading the hole-level vote counts.
SURFACE_GATE = 0.2
BRIDGED_DARK = (0.1, 0.25)
# NMS between a bridged basin and a basin inside it with its rim seen all round
# (_priorities): the inner one counts when it scores at least this fraction of the bridged
# one (a much weaker dip is a dip in the hole's floor), and it runs on to the cut when it
# comes within its ring and walls of it (RING_PX + options.grow_px work pixels).
INNER_SCORE_RATIO = 0.5
# Pixel-resolution boxes (options.pixel_boxes): a side moves at most this many work pixels
# from the region's blocks to the opening's edge in the frame's depth.
PIXEL_REACH = 2
# The box of an unread region (options.dark_box) is its dark part's when that part is
# at least this fraction of the region.
DARK_BOX_KEEP = 0.5
_K3 = np.ones((3, 3), np.uint8)


def _nms(
    found: list[_Measured], iou_max: float, contained: float, near_px: int | None
) -> list[_Measured]:
    """Suppress overlaps (IoU > ``iou_max``) and containers of a better detection.

    A region that holds a higher-scoring one (most of it inside) is a depression or a
    no-reading area around that hole, not a second hole. "Better" is the score, except
    between a bridged basin and a basin inside it (:func:`_priorities`; ``near_px`` None:
    the score alone, ``options.seen_rim_first`` off).
    """
    keep: list[_Measured] = []
    rank = [m.det.score for m in found]
    if near_px is not None:
        rank = _priorities(found, contained, near_px)
    for _, m in sorted(zip(rank, found, strict=True), key=lambda p: -p[0]):
        d = m.det
        if all(box_iou(d.box, k.det.box) <= iou_max for k in keep) and not any(
            _inside(k.det.box, d.box) > contained for k in keep
        ):
            keep.append(m)
    return keep


def _priorities(found: list[_Measured], contained: float, near_px: int) -> list[float]:
    """The order of NMS: each candidate's score, but a bridged basin (closed by a rim
    assumed across the border cut) and a basin inside it whose rim was seen all round (an
    enclosed pit, not bridged, not cut) that scores at least :data:`INNER_SCORE_RATIO` of
    it:

    * when the inner basin comes within ``near_px`` of a side the bridged one is cut by,
      it is the deep part of a hole that runs on to the cut: the bridged basin goes first
      (its box is the hole's);
    * otherwise seen rim lies between the inner basin and the cut: the bridged basin is
      the depression around that hole, its depth measured against a rim partly assumed;
      the inner basin goes first (and the bridged one, holding it, is dropped).
    """
    rank = [m.det.score for m in found]
    for i, b in enumerate(found):
        if b.read is None or not b.read.bridged:
            continue
        for j, e in enumerate(found):
            if (
                e.read is None
                or e.read.bridged
                or not e.read.enclosed
                or e.det.border_cut
                or e.det.score < INNER_SCORE_RATIO * b.det.score
                or _inside(e.det.box, b.det.box) <= contained
            ):
                continue
            first, then = (i, j) if _near_cut(e.read, b.read, near_px) else (j, i)
            if rank[first] <= rank[then]:
                rank[first] = np.nextafter(rank[then], np.inf)
    return rank


def _near_cut(inner: _ReadBox, outer: _ReadBox, near: int) -> bool:
    """Whether ``inner`` comes within ``near`` work pixels of a side of the read area
    that ``outer`` reaches."""
    (ix0, iy0, ix1, iy1), (ox0, oy0, ox1, oy1), (ww, hh) = inner.box, outer.box, outer.size
    return (
        (ox0 == 0 and ix0 <= near)
        or (oy0 == 0 and iy0 <= near)
        or (ox1 == ww and ww - ix1 <= near)
        or (oy1 == hh and hh - iy1 <= near)
    )


def _inside(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> float:
    """Fraction of box ``a`` that lies inside box ``b``."""
    ix = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    return ix * iy / max(a[2] * a[3], 1)


def _as_is(region: Candidate) -> Candidate:
    return region


def _unique(regions: list[Candidate]) -> list[Candidate]:
    """Candidates without repeats (neck cuts at several radii often yield the same blob)."""
    seen: set[tuple[tuple[int, int, int, int], int, bool]] = set()
    out: list[Candidate] = []
    for r in regions:
        key = (r.box, int(r.mask.sum()), r.enclosed)
        if key not in seen:
            seen.add(key)
            out.append(r)
    return out


def _touches_border(region: Candidate, shape: tuple[int, ...]) -> bool:
    x, y, w, h = region.box
    return x == 0 or y == 0 or x + w == shape[1] or y + h == shape[0]


def box_iou(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> float:
    """Intersection over union of two (x, y, w, h) boxes."""
    return overlap(a, b, "iou")


_T = TypeVar("_T")


@dataclass(frozen=True)
class _FrameData:
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
_TERRAIN_KERNEL = disk(RING_PX + TERRAIN_PX)


def _measure(
    region: Candidate,
    f: _FrameData,
    params: DetectParams,
    dark_cut: bool = False,
    bridged: bool = False,
) -> _Measured | None:
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
    inscribed = 2.0 * widest * rim_z / f.cam.fx
    if not o.passable_width:
        minor = minor_pca
    elif any(cut_sides):
        minor = inscribed
    else:
        minor = min(minor_pca, inscribed)
    s = params.searcher
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
        opening_m=_xyz(opening.centre),
        rim_normal=_xyz(opening.normal),
        rim_seen=round(max(rim_seen, 0.0), 3),
        border_cut=bool(open_px),
        inside_on_plane=plane_read[0] if plane_read else None,
        inside_behind=plane_read[1] if plane_read else None,
    )
    # Sizes (and so the score) come from the rim's plane; where the opening is, from the
    # terrain's when the border cuts it: placed once the detection has outlived NMS.
    read = _ReadBox((gx0, gy0, gx1, gy1), (ww, hh), bridged, enclosed)
    shape = _Shape(inside[by0:by1, bx0:bx1], (gx0, gy0), (opening.normal, opening.centre))
    if not (open_px and o.cut_circle):
        return _Measured(det, None, read, shape)
    return _Measured(
        det,
        _Cut(opening, region_uv, (rim_u, rim_v, rim_zs), inside, inv_c, zc, (x0, y0)),
        read,
        shape,
    )


class _Cut(NamedTuple):
    """What placing an opening the border cuts needs (:func:`_place`)."""

    opening: Opening
    region_uv: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]
    rim_uvz: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]
    inside: npt.NDArray[np.bool_]
    invalid: npt.NDArray[np.bool_]
    zc: npt.NDArray[np.float32]
    origin: tuple[int, int]


class _ReadBox(NamedTuple):
    """Where a measured region lies on the read area (work pixels), for NMS."""

    box: tuple[int, int, int, int]  # x0, y0, x1, y1
    size: tuple[int, int]  # the read area's width, height
    bridged: bool  # a basin closed by bridging its cut at the border
    enclosed: bool  # a pit of the basin analysis (its rim holds all round)


class _Shape(NamedTuple):
    """A measured region as :func:`_pixel_box` refines its box."""

    mask: npt.NDArray[np.bool_]  # the region (walls included) inside its box
    origin: tuple[int, int]  # its box's top-left, read-area work pixels
    plane: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]  # the rim's (normal, point)


class _Measured(NamedTuple):
    det: Detection
    cut: _Cut | None
    read: _ReadBox | None = None
    shape: _Shape | None = None


def _pixel_box(
    m: _Measured,
    f: _FrameData,
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    dark_box: bool,
) -> Detection:
    """The detection with its box refined at the frame's own resolution
    (``options.pixel_boxes``, :func:`detect._boxes.refine_box`): each side the read
    area does not cut moves to the opening's edge in the depth, within
    :data:`PIXEL_REACH` work pixels of the region's blocks; with ``dark_box``, the
    region's lit unread part left out first (:func:`_dark_part`). Scores, sizes and NMS
    are the work grid's: only the box changes."""
    if m.shape is None or m.read is None:
        return m.det
    k = f.factor
    left, top, _, _ = f.bands
    mask, (ux, uy), plane = m.shape
    hh, ww = f.z.shape
    (gx0, gy0, gx1, gy1), (rw, rh) = m.read.box, m.read.size
    if dark_box:
        mask, (ux, uy) = _dark_part(mask, (ux, uy), f)
        gx0, gy0, gx1, gy1 = ux, uy, ux + mask.shape[1], uy + mask.shape[0]
    region = np.repeat(np.repeat(mask, k, axis=0), k, axis=1)
    read_area = (left * k, top * k, (left + ww) * k, (top + hh) * k)
    origin = ((ux + left) * k, (uy + top) * k)
    barrier = None
    if dark_box and f.rel_smooth is not None:
        lit = f.once("lit unread", lambda: _lit_unread(f))

        def barrier(win: tuple[int, int, int, int]) -> npt.NDArray[np.bool_]:
            return _upsampled(lit, win, (left * k, top * k), k)

    refined = refine_box(region, origin, depth, camera, plane, PIXEL_REACH * k, read_area, barrier)
    if refined is None:
        return m.det
    rx0, ry0, rx1, ry1 = refined
    x, y, w, h = m.det.box
    # Where the read area cuts the region, its box runs on across the band (_frame_box).
    bx0, by0 = x if gx0 == 0 else rx0, y if gy0 == 0 else ry0
    bx1, by1 = x + w if gx1 == rw else rx1, y + h if gy1 == rh else ry1
    return replace(m.det, box=(bx0, by0, bx1 - bx0, by1 - by0))


def _lit_unread(f: _FrameData) -> npt.NDArray[np.bool_]:
    """The read area's unread work pixels as lit as the rubble around them."""
    assert f.rel_smooth is not None
    return np.asarray(f.invalid & (f.rel_smooth >= DARK_CUT), bool)


def _upsampled(
    mask: npt.NDArray[np.bool_], win: tuple[int, int, int, int], at: tuple[int, int], k: int
) -> npt.NDArray[np.bool_]:
    """The window ``(x0, y0, x1, y1)`` (frame pixels, inside the mask's extent) of ``mask``
    (work pixels, its top-left at frame pixel ``at``, ``k`` frame pixels a side),
    nearest-neighbour.

    >>> m = np.array([[True, False]]); _upsampled(m, (1, 0, 4, 2), (0, 0), 2).astype(int)
    array([[1, 0, 0],
           [1, 0, 0]])
    """
    x0, y0, x1, y1 = win[0] - at[0], win[1] - at[1], win[2] - at[0], win[3] - at[1]
    wx0, wy0 = x0 // k, y0 // k
    crop = mask[wy0 : (y1 - 1) // k + 1, wx0 : (x1 - 1) // k + 1]
    up = np.repeat(np.repeat(crop, k, axis=0), k, axis=1)
    ox, oy = x0 - wx0 * k, y0 - wy0 * k
    return np.asarray(up[oy : oy + y1 - y0, ox : ox + x1 - x0], bool)


def _dark_part(
    mask: npt.NDArray[np.bool_], origin: tuple[int, int], f: _FrameData
) -> tuple[npt.NDArray[np.bool_], tuple[int, int]]:
    """An unread region without its unread pixels that are lit (``options.dark_box``):
    ``(mask, origin)`` of its largest remaining part (opened over 3 x 3), or the region as
    it is when that part is under :data:`DARK_BOX_KEEP` of it.

    A hole's unread inside is dark against the rubble (:mod:`detect._photometry`); an
    unread area as lit as the rubble around it is terrain beyond the range, a speckled
    far field or a bright surface that returns nothing, that the region ran into. It
    stays in the region the detection was scored on; the box is the hole's.
    """
    if f.rel_smooth is None:
        return mask, origin
    ux, uy = origin
    mh, mw = mask.shape
    lit = mask & f.invalid[uy : uy + mh, ux : ux + mw]
    lit &= f.rel_smooth[uy : uy + mh, ux : ux + mw] >= DARK_CUT
    if not lit.any():
        return mask, origin
    rest = np.asarray(cv2.morphologyEx((mask & ~lit).view(np.uint8), cv2.MORPH_OPEN, _K3), np.uint8)
    n, lab, stats = components(rest)
    if n < 2:
        return mask, origin
    i = int(np.argmax(stats[1:, cv2.CC_STAT_AREA])) + 1
    if stats[i, cv2.CC_STAT_AREA] < DARK_BOX_KEEP * np.count_nonzero(mask):
        return mask, origin
    x, y = int(stats[i, cv2.CC_STAT_LEFT]), int(stats[i, cv2.CC_STAT_TOP])
    w, h = int(stats[i, cv2.CC_STAT_WIDTH]), int(stats[i, cv2.CC_STAT_HEIGHT])
    return lab[y : y + h, x : x + w] == i, (ux + x, uy + y)


def _place(m: _Measured, cam: CameraIntrinsics) -> Detection:
    """The detection with an opening the border cuts placed at the centre of the circle
    through the rim it shows, on the plane of the terrain around it (``options.cut_circle``)."""
    if m.cut is None:
        return m.det
    opening, region_uv, rim, inside, invalid, zc, (x0, y0) = m.cut
    rim_u, rim_v, rim_zs = rim
    band = (cv2.dilate(inside.astype(np.uint8), _TERRAIN_KERNEL) > 0) & ~inside & ~invalid
    bv, bu = np.nonzero(band)
    uv_band = (bu.astype(np.float64) + x0, bv.astype(np.float64) + y0)
    around = rays_of(*uv_band, cam) * zc[band].astype(np.float64)[:, None]
    plane = terrain_plane(around, rays_of(rim_u, rim_v, cam) * rim_zs[:, None])
    placed = opening
    if plane is not None:
        placed = measure_opening(region_uv, rim, cam, plane=plane)
    fitted = rim_circle_centre(rim, placed, cam)
    centre = placed.centre if fitted is None else fitted
    return replace(m.det, opening_m=_xyz(centre), rim_normal=_xyz(placed.normal))


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
    read_box: tuple[int, int, int, int], read_size: tuple[int, int], f: _FrameData
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


def _xyz(v: npt.NDArray[np.float64]) -> tuple[float, float, float]:
    return (round(float(v[0]), 4), round(float(v[1]), 4), round(float(v[2]), 4))


def detect_default(
    rgb: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    params: DetectParams,
) -> list[Detection]:
    """Detect access holes with holescan's default method (module docstring).

    Parameters
    ----------
    rgb : (H, W, 3) uint8 ndarray, RGB, registered to depth.
    depth : (H, W) uint16 ndarray, millimetres, 0 = no reading.
    camera : intrinsics of the (H, W) images.
    params : detector parameters (``searcher`` sets the sizes and depths).

    Returns
    -------
    Detections sorted by score, highest first.
    """
    check_frame(rgb, depth, camera)
    factor = max(1, round(1.0 / params.work_scale))
    o = params.options
    z_full, _ = block_depth(depth, factor, camera.depth_unit_m, o.min_valid_fraction)
    if np.isnan(z_full).all():
        return []
    # The read area: the frame without its unread border bands (a hole the band cuts is
    # cut by the read area's border, its rim there unknown).
    max_px = max(1, round(BAND_MAX_PX / factor))
    bands = unread_bands(np.isnan(z_full), max_px) if o.bands else (0, 0, 0, 0)
    left, top, right, bottom = bands
    hf, wf = z_full.shape
    z = z_full[top : hf - bottom, left : wf - right]
    if min(z.shape) < 3 or np.isnan(z).all():
        return []
    full = camera.scaled(1.0 / factor)
    cam = CameraIntrinsics(
        z.shape[1], z.shape[0], full.fx, full.fy, full.cx - left, full.cy - top, full.depth_unit_m
    )
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)  # BT.601 Y, as the paper's YUV
    small = cv2.resize(grey, (wf, hf), interpolation=cv2.INTER_AREA)
    y_img = np.asarray(small, np.float64)[top : hf - bottom, left : wf - right] / 255.0
    depths = basin_depths(z, closed_border=o.closed_border)
    pit, invalid, z_far = depths.spilled, depths.invalid, depths.z_far
    rel = relative_luminance(y_img, ~invalid)
    range_m = max(params.max_range_m, z_far)
    s = params.searcher
    # Smallest region worth measuring: a quarter of the searcher's minimum opening at the
    # farthest depth in view, in work pixels.
    min_side_px = s.min_fraction * s.minor_m * cam.fx / max(z_far, 0.5)
    min_px = max(2, int(0.25 * min_side_px**2))
    spurs = trim_spurs if o.trim_spurs else _as_is
    regions = _unique(
        [
            spurs(r)
            for r in basin_regions(pit, min_px, o.depression_ratio)
            + no_reading_regions(invalid, pit, min_px, o.neck_radii_px)
        ]
    )
    # Basins the border cuts, closed there (their rim beyond is unknown): candidates beside
    # the spilled view's (the better-scoring one of a pair wins in NMS).
    bridged: list[Candidate] = []
    if depths.closed is not None:
        bridged = [
            spurs(r)
            for r in basin_regions(depths.closed, min_px, o.depression_ratio)
            if _touches_border(r, z.shape)
        ]
    # The dark part of each spilled no-reading blob: a hole's interior cut from the bright
    # terrain beyond range (or a bright no-return surface) it runs into.
    dark: list[Candidate] = []
    rel_smooth = np.asarray(
        cv2.blur(rel.astype(np.float32), (DARK_SMOOTH_PX, DARK_SMOOTH_PX)), np.float32
    )
    if o.dark_split:
        dark_blobs = invalid & (rel_smooth < DARK_CUT)
        dark = _unique(
            [spurs(r) for r in no_reading_regions(dark_blobs, pit, min_px, o.neck_radii_px)]
        )

    frame = _FrameData(z, invalid, y_img, rel, cam, z_far, range_m, factor, bands, rel_smooth)
    found = [m for r in regions if (m := _measure(r, frame, params)) is not None]
    found += [m for r in dark if (m := _measure(r, frame, params, dark_cut=True)) is not None]
    found += [m for r in bridged if (m := _measure(r, frame, params, bridged=True)) is not None]
    near_cut = RING_PX + o.grow_px if o.seen_rim_first else None
    kept = _nms(found, params.nms_iou, o.contained, near_cut)
    if o.pixel_boxes:
        kept = [m._replace(det=_pixel_box(m, frame, depth, camera, o.dark_box)) for m in kept]
    return [replace(d, p_hole=p_hole_of_score(d.score)) for d in (_place(m, cam) for m in kept)]


def basin_labels(
    depth: npt.NDArray[np.uint16], camera: CameraIntrinsics, params: DetectParams
) -> npt.NDArray[np.int32]:
    """(H, W) int32 labels of the depth basins the default detector considers (0 = none).

    For display: nearest-neighbour upsampling of the work-resolution basin components.
    """
    factor = max(1, round(1.0 / params.work_scale))
    z, _ = block_depth(depth, factor, camera.depth_unit_m, params.options.min_valid_fraction)
    if np.isnan(z).all():
        return np.zeros(depth.shape, np.int32)
    pit, _, _ = basin_depth(z)
    _, lab = cv2.connectedComponents((pit > SHALLOW_M).astype(np.uint8), connectivity=8)
    up = cv2.resize(
        lab.astype(np.int32), (depth.shape[1], depth.shape[0]), interpolation=cv2.INTER_NEAREST
    )
    return up.astype(np.int32)
