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

This module runs the steps in order; the candidates are found by :mod:`detect._regions`,
measured and scored by :mod:`detect._measure`, suppressed by :mod:`detect._suppress`, and
their boxes refined at the frame's resolution by :mod:`detect._boxes`.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._boxes import pixel_box
from holescan.detect._calibration import p_hole_of_score
from holescan.detect._geometry import (
    disk,
    measure_opening,
    opening_axes,
    rays_of,
    rim_circle_centre,
    terrain_plane,
)
from holescan.detect._measure import (
    DARK_CUT,
    RING_PX,
    TERRAIN_PX,
    FrameData,
    Measured,
    measure,
    xyz,
)
from holescan.detect._photometry import relative_luminance
from holescan.detect._regions import (
    BAND_MAX_PX,
    SHALLOW_M,
    Candidate,
    basin_depth,
    basin_depths,
    basin_regions,
    block_depth,
    no_reading_regions,
    trim_spurs,
    unread_bands,
)
from holescan.detect._suppress import box_iou, nms
from holescan.detect._types import CameraIntrinsics, Detection, DetectParams
from holescan.detect._validate import check_frame

__all__ = [
    "basin_depth",
    "basin_labels",
    "block_depth",
    "box_iou",
    "detect_default",
    "opening_axes",
]

# The dark part of spilled no-reading blobs (options.dark_split, DARK_CUT) is taken on
# the relative luminance box-averaged over this many work pixels, against shot noise in
# dark frames.
DARK_SMOOTH_PX = 5
# Unread border bands (options.bands: registered structured-light depth, at most
# BAND_MAX_PX wide) are cut off the frame.
_TERRAIN_KERNEL = disk(RING_PX + TERRAIN_PX)


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


def _place(m: Measured, cam: CameraIntrinsics) -> Detection:
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
    return replace(m.det, opening_m=xyz(centre), rim_normal=xyz(placed.normal))


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

    frame = FrameData(z, invalid, y_img, rel, cam, z_far, range_m, factor, bands, rel_smooth)
    found = [m for r in regions if (m := measure(r, frame, params)) is not None]
    found += [m for r in dark if (m := measure(r, frame, params, dark_cut=True)) is not None]
    found += [m for r in bridged if (m := measure(r, frame, params, bridged=True)) is not None]
    near_cut = RING_PX + o.grow_px if o.seen_rim_first else None
    kept = nms(found, params.nms_iou, o.contained, near_cut)
    if o.pixel_boxes:
        kept = [m._replace(det=pixel_box(m, frame, depth, camera, o.dark_box)) for m in kept]
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
