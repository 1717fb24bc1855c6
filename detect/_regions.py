"""Candidate regions of the default detector: depth basins and no-reading blobs.

See :mod:`detect._default` for the method. Pure: arrays in, masks and boxes out.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from skimage.morphology import reconstruction

from holescan.detect._options import DefaultOptions
from holescan.detect._order_stats import percentile

# Region thresholds (metres below the spill level). SHALLOW is a few block-averaged noise
# sigmas at 4 m (Xtion: 1.425e-6 Z^2 mm per pixel -> 23 mm, /4 after 4x4 averaging).
SHALLOW_M = 0.05
DEEP_M = 0.25
# A border column (row) this unread belongs to an unread band of the registered frame;
# wider than BAND_MAX_PX (frame pixels at 640 wide) an unread border area is the scene's.
BAND_UNREAD = 0.95
BAND_MAX_PX = 64
# Dips along a border line up to this fraction of its length are bridged (basin_depth).
BORDER_BRIDGE = 0.5
# ... and at least this many pixels long.
BRIDGE_MIN_PX = 3
# A bridge takes in the dip's shoulders (shallower than DEEP_M) up to this fraction of its
# deep part's length on each side (_bridged).
SHOULDER_REACH = 0.5
# Dips running into a corner up to this fraction of the line are bridged at the rim on
# their one side, when that side rises as a wall's (by DEEP_M within CORNER_STEP_PX).
CORNER_BRIDGE = 0.25
CORNER_STEP_PX = 2
# _fill checks for stability after this many geodesic erosions (a work-grid frame needs
# 50-130).
_FILL_CHECK_STEPS = 8
_K3 = np.ones((3, 3), np.uint8)


def block_depth(
    depth: npt.NDArray[np.uint16],
    factor: int,
    unit_m: float,
    min_valid_fraction: float = DefaultOptions.min_valid_fraction,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Mean of the valid readings in each ``factor`` x ``factor`` block.

    Returns ``(z, valid_fraction)``: z (h, w) float32 metres, NaN where fewer than
    ``min_valid_fraction`` of the block's pixels had a reading.
    """
    size = (depth.shape[1] // factor, depth.shape[0] // factor)
    total = cv2.resize(depth.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    frac = np.asarray(
        cv2.resize((depth > 0).astype(np.float32), size, interpolation=cv2.INTER_AREA), np.float32
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.asarray(total / frac * np.float32(unit_m), np.float32)
    z[frac < min_valid_fraction] = np.nan
    return z, frac


def unread_bands(unread: npt.NDArray[np.bool_], max_px: int) -> tuple[int, int, int, int]:
    """Widths ``(left, top, right, bottom)`` of the unread bands at the frame border.

    A registered structured-light frame has no reading in bands along its border (right
    24-43 px, top 8-14, bottom 6-12, left 0-11 at 640x480): a band is the run of border
    columns (rows) of ``unread`` (True = no reading) at least :data:`BAND_UNREAD` unread,
    at most ``max_px`` wide (wider unread areas are the scene's, e.g. terrain beyond range).

    >>> unread = np.zeros((20, 30), bool); unread[:, 26:] = True; unread[:2] = True
    >>> unread_bands(unread, 8)
    (0, 2, 4, 0)
    """
    cols, rows = unread.mean(axis=0), unread.mean(axis=1)

    def run(frac: npt.NDArray[np.float64]) -> int:
        n = 0
        while n < min(max_px, frac.size - 1) and frac[n] >= BAND_UNREAD:
            n += 1
        return n

    return run(cols), run(rows), run(cols[::-1]), run(rows[::-1])


def _closed_profile(
    profile: npt.NDArray[np.float64], length: int, end: int = 0
) -> npt.NDArray[np.float64]:
    """Dips along a border line shorter than ``length`` bridged: each point raised to the
    lower of the highest points within ``length`` on its two sides (itself included).

    With ``end``, a dip running into an end of the line (a corner of the frame) within
    ``end`` of it is bridged at the rim on its one side when it is a wall's step, not a
    slope (:func:`_end_rim`).

    >>> _closed_profile(np.array([3.0, 1.0, 0.0, 2.0, 1.0, 0.5]), 3).tolist()
    [3.0, 2.0, 2.0, 2.0, 1.0, 0.5]
    >>> _closed_profile(np.array([0.0, 0.0, 2.0, 2.0, 2.0, 2.0]), 3, end=3).tolist()
    [2.0, 2.0, 2.0, 2.0, 2.0, 2.0]
    """
    n = max(1, length)
    lo = _end_rim(profile, end) if end else float(profile[0])
    hi = _end_rim(profile[::-1], end) if end else float(profile[-1])
    line = np.ascontiguousarray(profile, np.float64)[None, :]
    kernel = np.ones((1, n + 1), np.uint8)
    # Running maxima over [i - n, i] and [i, i + n] (a dilation: exact, no window copies),
    # the line continued by ``lo`` before its start and ``hi`` after its end.
    const = cv2.BORDER_CONSTANT
    left = cv2.dilate(line, kernel, anchor=(n, 0), borderType=const, borderValue=lo)
    right = cv2.dilate(line, kernel, anchor=(0, 0), borderType=const, borderValue=hi)
    return np.asarray(np.minimum(left, right)[0], np.float64)


def _end_rim(profile: npt.NDArray[np.float64], end: int) -> float:
    """The height beyond ``profile[0]`` (the line's end): the rim of a dip that runs into
    the end, when the dip lies within ``end`` of it and its side rises by :data:`DEEP_M`
    within :data:`CORNER_STEP_PX` (a wall: terrain sloping toward the corner is no dip);
    else ``profile[0]`` itself (the end drains).

    >>> _end_rim(np.array([-3.0, -3.0, -3.0, -2.0, -2.0, -2.0]), 4)  # a hole's wall
    -2.0
    >>> _end_rim(-3.0 + 0.05 * np.arange(12), 8)  # a slope
    -3.0
    """
    rim = float(profile[: end + 1].max())
    edge = int(np.argmax(profile >= rim - DEEP_M))  # the dip: profile[:edge]
    if edge == 0 or float(profile[edge : edge + CORNER_STEP_PX + 1].max()) < rim - 0.2 * DEEP_M:
        return float(profile[0])
    return rim


def _bridged(
    profile: npt.NDArray[np.float64], length: int, end: int = 0
) -> npt.NDArray[np.float64]:
    """The border line with its deep dips bridged: where the closed profile stands more
    than :data:`DEEP_M` above it (a hole or its unread floor crossing the border), not at
    shallow undulations of the terrain (those drain there as before).

    Each bridge also takes in the dip's shoulders, where the closed profile stands more
    than :data:`SHALLOW_M` above the line, up to :data:`SHOULDER_REACH` of the deep part's
    length on each side: a hole's walls slope up to its rim, and a bridge over the deep
    part alone leaves the basin to drain at a shoulder up to :data:`DEEP_M` below the rim,
    shallower than it is by as much (an oblique 0.5 m hole cut by the border then has no
    core at all). The reach is bounded, scaling with the dip: a long shallow stretch of
    terrain beside a dip is no wall, and bridged would close a basin across the frame.

    >>> p = -np.array([2.5, 2.5, 2.6, 2.8, 3.0, 3.0, 3.0, 3.0, 2.8, 2.6, 2.5, 2.5])
    >>> (-_bridged(p, 9)).round(2).tolist()  # the deep part and its shoulders
    [2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5]
    >>> (-_bridged(-np.array([2.5, 2.6, 2.6, 2.6, 2.5]), 4)).round(2).tolist()  # shallow
    [2.5, 2.6, 2.6, 2.6, 2.5]
    """
    closed = _closed_profile(profile, length, end)
    dip = closed - profile
    deep = (dip > DEEP_M).astype(np.uint8)[None, :]
    # Runs shorter than BRIDGE_MIN_PX (stray unread pixels at the border) are left alone.
    k = np.ones((1, BRIDGE_MIN_PX), np.uint8)
    deep = np.asarray(cv2.morphologyEx(deep, cv2.MORPH_OPEN, k), np.uint8)[0].astype(bool)
    if not deep.any():
        return profile
    wet = dip > SHALLOW_M
    bridge = deep.copy()
    edges = np.diff(np.concatenate(([0], deep.view(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()
    for a, b in zip(starts, stops, strict=True):  # each deep run is [a, b)
        reach = max(1, round(SHOULDER_REACH * (b - a)))
        lo, hi = max(0, a - reach), min(int(wet.size), b + reach)
        dry_before, dry_after = np.flatnonzero(~wet[lo:a]), np.flatnonzero(~wet[b:hi])
        lo = lo + int(dry_before[-1]) + 1 if dry_before.size else lo
        hi = b + int(dry_after[0]) if dry_after.size else hi
        bridge[lo:hi] = True
    return np.where(bridge, closed, profile)


def _heights(z: npt.NDArray[np.float32]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """``(height, invalid)``: ``-z``, no reading set below every reading."""
    invalid = np.isnan(z)
    height = -z.astype(np.float64)
    # A float32 value, as every other height is (what _fill's exactness rests on).
    height[invalid] = -float(np.fmax.reduce(z, axis=None) + np.float32(1.0))  # fmax: NaN-blind
    return height, invalid


def _border_seed(height: npt.NDArray[np.float64], closed_border: bool) -> npt.NDArray[np.float64]:
    """The reconstruction's seed: the border's heights (deep dips bridged with
    ``closed_border``), above every height inside."""
    seed = height.copy()
    seed[1:-1, 1:-1] = height.max()
    if closed_border and min(height.shape) >= 3:
        hh, ww = height.shape
        lw, lh = round(BORDER_BRIDGE * ww), round(BORDER_BRIDGE * hh)
        ew, eh = round(CORNER_BRIDGE * ww), round(CORNER_BRIDGE * hh)
        seed[0, :] = _bridged(height[0, :], lw, ew)
        seed[-1, :] = _bridged(height[-1, :], lw, ew)
        seed[:, 0] = np.maximum(seed[:, 0], _bridged(height[:, 0], lh, eh))
        seed[:, -1] = np.maximum(seed[:, -1], _bridged(height[:, -1], lh, eh))
    return seed


def _fill(
    seed: npt.NDArray[np.float64], height: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """Grey-level reconstruction by erosion of ``height`` from ``seed`` (``seed >= height``):
    every basin filled to its spill level.

    Equal to ``skimage.morphology.reconstruction(seed, height, method="erosion")`` (8-
    neighbourhood), computed as its definition: the geodesic erosion (a 3x3 erosion, then
    no lower than ``height``) repeated until nothing changes. A reconstruction only
    compares and copies values, so on float32 copies it gives the same values whenever
    every value is a float32 one, as the heights of block-averaged float32 depth are; on a
    work grid (160 x 120) OpenCV's float32 erosion makes that ~3x cheaper than skimage,
    which sorts the whole image twice. Other values go to skimage.

    The erosions start from a tighter marker than ``seed``: each pixel lowered to the
    least, over the four straight paths from it along its row and column to the border, of
    the path's highest height (or its seed where it leaves, if higher). Water can drain
    along each of those paths, so the marker stays between the result and ``seed``, and
    the erosions from it reach the same result (reconstruction is monotone in the
    marker), in about half as many steps.

    >>> h = np.array([[3, 3, 3, 3], [3, 1, 0, 3], [3, 2, 3, 3], [3, 3, 3, 3]], np.float64)
    >>> h[0, 1] = 2.0  # the rim's lowest point: the basin spills there
    >>> seed = h.copy(); seed[1:-1, 1:-1] = h.max()
    >>> _fill(seed, h)[1:3, 1:3].tolist()
    [[2.0, 2.0], [2.0, 3.0]]
    """
    s32, h32 = seed.astype(np.float32), height.astype(np.float32)
    if not (np.array_equal(s32, seed) and np.array_equal(h32, height)):
        return np.asarray(reconstruction(seed, height, method="erosion"), np.float64)  # type: ignore[no-untyped-call]
    top = np.maximum.accumulate
    cur = np.minimum(s32, np.maximum(top(h32, axis=1), s32[:, :1]))
    np.minimum(cur, np.maximum(top(h32[:, ::-1], axis=1)[:, ::-1], s32[:, -1:]), out=cur)
    np.minimum(cur, np.maximum(top(h32, axis=0), s32[:1, :]), out=cur)
    np.minimum(cur, np.maximum(top(h32[::-1], axis=0)[::-1], s32[-1:, :]), out=cur)
    eroded, before = np.empty_like(s32), np.empty_like(s32)
    while True:
        before[...] = cur
        for _ in range(_FILL_CHECK_STEPS):
            cv2.erode(cur, _K3, dst=eroded)  # outside the image counts as +inf
            np.maximum(eroded, h32, out=cur)
        if np.array_equal(cur, before):
            return cur.astype(np.float64)


def _pit(
    filled: npt.NDArray[np.float64], height: npt.NDArray[np.float64], invalid: npt.NDArray[np.bool_]
) -> npt.NDArray[np.float64]:
    pit = filled - height
    pit[invalid & (pit > 0)] = np.inf
    return pit


def basin_depth(
    z: npt.NDArray[np.float32], closed_border: bool = False
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_], float]:
    """Depth of every pixel below the spill level of its basin (metres; inf for no reading).

    The frame's border is where basins drain. With ``closed_border`` a basin the border
    cuts does not drain through the cut: the rim beyond the border is unknown, not absent,
    so along each border line, dips shorter than :data:`BORDER_BRIDGE` of its length and
    deeper than :data:`DEEP_M` (a hole or its unread floor crossing the border) are bridged
    at the height of the rim on their two sides. Without it (the default) such a basin
    spills there and is no pit.

    Returns ``(pit, invalid, z_far)`` where ``z_far`` is the farthest reading in the image.
    """
    height, invalid = _heights(z)
    z_far = float(np.nanpercentile(z, 99.5))  # robust to a few outliers
    return _pit(_fill(_border_seed(height, closed_border), height), height, invalid), invalid, z_far


class BasinDepths(NamedTuple):
    """Both views of :func:`basin_depth` of one depth image.

    spilled : the pit with basins draining at the border (``closed_border=False``).
    closed : the pit with deep border dips bridged (``closed_border=True``); None when no
        deep dip crosses the border (it would equal ``spilled``).
    invalid : (h, w) bool, no reading.
    z_far : the farthest reading in the image (99.5th percentile).
    """

    spilled: npt.NDArray[np.float64]
    closed: npt.NDArray[np.float64] | None
    invalid: npt.NDArray[np.bool_]
    z_far: float


def basin_depths(z: npt.NDArray[np.float32], closed_border: bool = True) -> BasinDepths:
    """:func:`basin_depth` spilled and (with ``closed_border``) closed, for about the cost
    of one reconstruction, equal to the two computed apart.

    The closed view fills more: it differs from the spilled one only in the lakes it
    holds against a bridged border dip (the spilled view's lakes never reach the border,
    where the seed is the height itself). So the full reconstruction is the closed one,
    and the spilled view is reconstructed again from it with the border unbridged. That
    start lies between the spilled view and its seed (the closed fill is above the spilled
    one; the border is at its own height in both), and a reconstruction by erosion from any
    marker between the two comes down to the same result: the spilled view exactly, in the
    few steps that drain the lakes at the border.
    """
    height, invalid = _heights(z)
    z_far = float(percentile(z[~invalid], 99.5))  # robust to a few outliers
    spilled_seed = _border_seed(height, False)
    closed_seed = _border_seed(height, closed_border)
    if not closed_border or np.array_equal(closed_seed, spilled_seed):
        return BasinDepths(_pit(_fill(spilled_seed, height), height, invalid), None, invalid, z_far)
    closed = _fill(closed_seed, height)
    # The border drains again: its pixels at their own height, the rest from the closed fill.
    start = closed.copy()
    start[[0, -1], :] = height[[0, -1], :]
    start[:, [0, -1]] = height[:, [0, -1]]
    spilled = closed if np.array_equal(start, closed) else _fill(start, height)
    return BasinDepths(
        _pit(spilled, height, invalid), _pit(closed, height, invalid), invalid, z_far
    )


Region = tuple[npt.NDArray[np.bool_], tuple[int, int, int, int]]


class Candidate(NamedTuple):
    """A candidate region of the work grid.

    mask : (h, w) bool, the region inside its box.
    box : (x, y, w, h) work pixels.
    enclosed : a pit of the basin analysis (its rim holds all round); False for a
        no-reading blob that spills (its rim is checked when it is measured).
    """

    mask: npt.NDArray[np.bool_]
    box: tuple[int, int, int, int]
    enclosed: bool


def components(
    mask: npt.NDArray[np.bool_] | npt.NDArray[np.uint8],
) -> tuple[int, npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """8-connected components of ``mask``: ``(count incl. background, labels, stats)``.

    OpenCV's BBDT labelling: the labels and stats of its default (Spaghetti, the same 2 x 2
    blocks in the same order; ``tests/detect/test_default.py`` compares them), for a third
    of the time (single-threaded, its default computes the stats slowly: ~160 against
    ~60 us on a work grid, and the detector labels some 16 grids a frame).
    """
    n, lab, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(
        mask.astype(np.uint8), 8, cv2.CV_32S, cv2.CCL_BBDT
    )
    return int(n), np.asarray(lab, np.int32), np.asarray(stats, np.int32)


def _crop(lab: npt.NDArray[np.int32], stats: npt.NDArray[np.int32], i: int) -> Region:
    x, y = int(stats[i, cv2.CC_STAT_LEFT]), int(stats[i, cv2.CC_STAT_TOP])
    w, h = int(stats[i, cv2.CC_STAT_WIDTH]), int(stats[i, cv2.CC_STAT_HEIGHT])
    return lab[y : y + h, x : x + w] == i, (x, y, w, h)


def basin_regions(
    pit: npt.NDArray[np.float64],
    min_px: int,
    depression_ratio: float = DefaultOptions.depression_ratio,
) -> list[Candidate]:
    """Regions around each deep core, cut from its basin at a depth that suits the core.

    A core is a component of ``pit > DEEP_M``. Its region is the connected part of its basin
    lying more than ``tau = clip(0.25 * D, SHALLOW_M, DEEP_M)`` below the spill level, D
    being the core's depth (1 m for a core without readings). The shallow skirt of a broad
    depression holding a hole is left out; the walls of a clean hole stay in.
    """
    n_b, lab_b, stats_b = components(pit > DEEP_M)
    regions: list[Candidate] = []
    seen: set[tuple[int, int, int, int]] = set()
    levels: dict[float, tuple[int, npt.NDArray[np.int32], npt.NDArray[np.int32]]] = {}
    for b in range(1, n_b):
        if stats_b[b, cv2.CC_STAT_AREA] < min_px:
            continue
        core, (x, y, w, h) = _crop(lab_b, stats_b, b)
        depths = pit[y : y + h, x : x + w][core]
        finite = depths[np.isfinite(depths)]
        d = float(percentile(finite, 90)) if finite.size > 0.5 * depths.size else 1.0
        tau = min(DEEP_M, max(SHALLOW_M, 0.25 * d))
        if tau not in levels:
            levels[tau] = components(pit > tau)
        _, lab, stats = levels[tau]
        labels = lab[y : y + h, x : x + w][core]
        i = int(np.bincount(labels[labels > 0]).argmax())  # core pixels are all > tau
        mask, box = _crop(lab, stats, i)
        if box not in seen:
            seen.add(box)
            regions.append(Candidate(mask, box, True))
            regions += _voids_in_depression(mask, box, pit, min_px, depression_ratio)
    return regions


def _voids_in_depression(
    mask: npt.NDArray[np.bool_],
    box: tuple[int, int, int, int],
    pit: npt.NDArray[np.float64],
    min_px: int,
    ratio: float,
) -> list[Candidate]:
    """The no-reading blobs of a basin much larger than them: holes in a broad depression.

    Each blob is a candidate of its own (its walls are added when it is measured); the
    basin stays a candidate too, and the better-scoring one wins (NMS by containment).
    """
    x, y, w, h = box
    void = mask & np.isinf(pit[y : y + h, x : x + w])
    n_void = int(void.sum())
    if n_void < min_px or mask.sum() <= ratio * n_void:
        return []
    n, lab, stats = components(void)
    out: list[Candidate] = []
    for i in range(1, n):
        if stats[i, cv2.CC_STAT_AREA] >= min_px:
            m, (bx, by, bw, bh) = _crop(lab, stats, i)
            out.append(Candidate(m, (bx + x, by + y, bw, bh), True))
    return out


def no_reading_regions(
    invalid: npt.NDArray[np.bool_],
    pit: npt.NDArray[np.float64],
    min_px: int,
    neck_radii_px: tuple[int, ...] = DefaultOptions.neck_radii_px,
) -> list[Candidate]:
    """Blobs of no reading that the basin analysis cannot see as pits.

    A hole whose floor gives no reading can touch another no-reading area (ground beyond
    the sensor's range, a neighbouring hole) or the image border; then it spills and is no
    pit. Opening the no-reading mask with disks of growing radius cuts such necks; each
    blob that appears (grown back inside the mask) is a candidate. Whether it is a hole is
    decided later from its rim (enough valid readings around it, well inside the range).

    ``invalid`` may also be a part of the no-reading mask (its dark pixels).
    """
    regions: list[Candidate] = []
    spilled = invalid & ~np.isinf(pit)
    if spilled.sum() < min_px:
        return regions
    inv_u8 = invalid.astype(np.uint8)
    for r in neck_radii_px:
        if r:
            k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
            opened = np.asarray(cv2.morphologyEx(inv_u8, cv2.MORPH_OPEN, k), np.uint8)
        else:
            opened = inv_u8
        n, lab, stats = components(opened)
        hh, ww = invalid.shape
        for i in range(1, n):
            if stats[i, cv2.CC_STAT_AREA] < min_px:
                continue
            # The blob grown back by r stays within its box widened by r.
            x, y = int(stats[i, cv2.CC_STAT_LEFT]), int(stats[i, cv2.CC_STAT_TOP])
            w, h = int(stats[i, cv2.CC_STAT_WIDTH]), int(stats[i, cv2.CC_STAT_HEIGHT])
            x0, y0 = max(0, x - r), max(0, y - r)
            win = (slice(y0, min(hh, y + h + r)), slice(x0, min(ww, x + w + r)))
            blob = (lab[win] == i).astype(np.uint8)
            if r:
                blob = np.asarray(cv2.dilate(blob, k), np.uint8) & inv_u8[win]
            if not (blob.astype(bool) & spilled[win]).any():
                continue  # an enclosed pit: basin_regions has it
            _, lab2, stats2 = components(blob)
            j = int(np.argmax(stats2[1:, cv2.CC_STAT_AREA])) + 1
            mask, (bx, by, bw, bh) = _crop(lab2, stats2, j)
            regions.append(Candidate(mask, (bx + x0, by + y0, bw, bh), False))
    return regions


# Spurs (trim_spurs): parts of a region no wider than this many work pixels, ...
SPUR_PX = 2
# ... trimmed when that takes this fraction of its box's area or more off the box.
SPUR_BOX_CUT = 0.25
_SPUR_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (SPUR_PX + 1, SPUR_PX + 1))


def trim_spurs(region: Candidate) -> Candidate:
    """``region`` without the thin spurs that stretch its box.

    On a structured-light frame a line of unread pixels a block or two wide runs along
    every nearer edge (the projector's shadow, the edge's dropouts); where it meets a hole
    it joins the hole's region and can double its box. No person passes through a line
    :data:`SPUR_PX` work pixels wide: the region is opened with a disk that wide and, when
    that takes at least :data:`SPUR_BOX_CUT` of the box's area off the box, its largest
    part kept (else the region is returned as it is: its edge is not stretched).

    >>> m = np.zeros((12, 30), bool); m[2:10, 2:10] = True; m[5, 10:30] = True
    >>> trim_spurs(Candidate(m, (0, 0, 30, 12), True)).box
    (2, 2, 9, 8)
    """
    x, y, w, h = region.box
    opened = np.asarray(
        cv2.morphologyEx(region.mask.astype(np.uint8), cv2.MORPH_OPEN, _SPUR_KERNEL), np.uint8
    )
    _, _, ow, oh = cv2.boundingRect(opened)  # the largest part's box lies inside it
    if ow * oh > (1.0 - SPUR_BOX_CUT) * w * h:
        return region
    n, lab, stats = components(opened)
    if n < 2:
        return region
    i = int(np.argmax(stats[1:, cv2.CC_STAT_AREA])) + 1
    mask, (bx, by, bw, bh) = _crop(lab, stats, i)
    if bw * bh > (1.0 - SPUR_BOX_CUT) * w * h:
        return region
    return Candidate(mask, (bx + x, by + y, bw, bh), region.enclosed)
