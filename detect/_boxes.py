"""Pixel-resolution boxes: a detection's box refined from the full-resolution depth.

The default detector finds and measures its regions on a reduced work grid (4 x 4 blocks
at 640 x 480), so a region's box is a multiple of the block and sits where the blocks
put it: a block counts as read when a few of its pixels are, so the region of an unread
opening stops up to a block short of the opening's edge on every side, and the readings of
the far wall just below the rim (behind the rim plane by less than the walls' margin) are
left out. The labels of a hole are its *visible opening*: the pixels whose ray crosses the
rim plane inside the outline. On the frame itself that is where the depth drops behind the
rim's plane, or gives no reading.

:func:`refine_box` takes the region at full resolution (its blocks), and lets it move by at
most ``reach`` pixels on each side to the pixels that lie behind the rim plane (or have no
reading) and connect to it: the box grows across the blocks the work grid counted as
read, and shrinks off blocks that hold no such pixel. :func:`pixel_box` applies it to a
measured region of the default detector (:mod:`detect._measure`), an unread region's lit
part left out first. Pure: arrays in, a box out.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect._measure import DARK_CUT, FrameData, Measured
from holescan.detect._regions import components
from holescan.detect._types import CameraIntrinsics, Detection

__all__ = ["BEHIND_M", "BEHIND_PER_M2", "behind_plane", "pixel_box", "refine_box"]

# A reading lies behind the rim plane (in the opening) when farther along its ray than the
# plane by the structured-light depth noise: BEHIND_M + BEHIND_PER_M2 * z**2 (4.5 cm at
# 2.7 m), the tolerance of :func:`detect._geometry.on_plane`.
BEHIND_M = 0.02
BEHIND_PER_M2 = 3e-3
# Pixel-resolution boxes (options.pixel_boxes): a side moves at most this many work pixels
# from the region's blocks to the opening's edge in the frame's depth.
PIXEL_REACH = 2
# The box of an unread region (options.dark_box) is its dark part's when that part is
# at least this fraction of the region.
DARK_BOX_KEEP = 0.5
_K3 = np.ones((3, 3), np.uint8)


def behind_plane(
    depth: npt.NDArray[np.uint16],
    origin: tuple[int, int],
    camera: CameraIntrinsics,
    plane: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
) -> npt.NDArray[np.bool_]:
    """Which pixels of ``depth`` (``camera.depth_unit_m`` units, 0 = no reading; a window
    whose top-left pixel is ``origin`` in the frame of ``camera``) read farther than the
    plane ``(normal, point)`` (camera frame, metres) along their ray, beyond the depth
    noise.

    >>> cam = CameraIntrinsics(8, 6, 100.0, 100.0, 3.5, 2.5)
    >>> z = np.full((6, 8), 2000, np.uint16); z[2:4, 3:5] = 2500
    >>> plane = (np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 2.0]))
    >>> int(behind_plane(z, (0, 0), cam, plane).sum())
    4
    """
    normal, point = plane
    hh, ww = depth.shape
    f32 = np.float32
    x = ((np.arange(ww) + origin[0] - camera.cx) / camera.fx).astype(f32)
    y = ((np.arange(hh) + origin[1] - camera.cy) / camera.fy).astype(f32)
    along = x[None, :] * f32(normal[0]) + y[:, None] * f32(normal[1])
    along += f32(normal[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        z_plane = f32(point @ normal) / along  # where each ray meets the plane (axial, m)
        limit = z_plane * z_plane
        limit *= f32(BEHIND_PER_M2)
        limit += z_plane
        limit += f32(BEHIND_M)
        limit *= f32(1.0 / camera.depth_unit_m)
        return np.asarray((z_plane > 0) & (depth > limit), bool)


def refine_box(
    region: npt.NDArray[np.bool_],
    origin: tuple[int, int],
    depth: npt.NDArray[np.uint16],
    camera: CameraIntrinsics,
    plane: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
    reach: int,
    read_area: tuple[int, int, int, int] | None = None,
    barrier: Callable[[tuple[int, int, int, int]], npt.NDArray[np.bool_]] | None = None,
) -> tuple[int, int, int, int] | None:
    """The box ``(x0, y0, x1, y1)`` (frame pixels, end exclusive) of the opening around
    ``region``, from the frame's own depth; None when no pixel of it is behind the plane
    or unread.

    region : (h, w) bool, the region at full resolution, its top-left pixel at ``origin``.
    depth : (H, W) the frame's depth (``camera.depth_unit_m`` units, 0 = no reading).
    plane : ``(normal, point)``, the rim's plane (camera frame, metres).
    reach : how far (pixels) the refined region may run beyond ``region``.
    read_area : ``(x0, y0, x1, y1)`` the part of the frame with readings (without its
        unread border bands); the refined region stays inside it.
    barrier : given a window ``(x0, y0, x1, y1)`` of the frame, its pixels (bool) that are
        no part of the opening whatever their depth.

    The opening's pixels are those behind the plane or without a reading (:func:`
    behind_plane`), cleared of lines one pixel wide (noise, a flying pixel's trail); the
    refined region is those of them within ``reach`` of ``region`` and connected to its
    own.
    """
    hh, ww = depth.shape
    ax0, ay0, ax1, ay1 = read_area if read_area is not None else (0, 0, ww, hh)
    ox, oy = origin
    rh, rw = region.shape
    x0, y0 = max(ax0, ox - reach), max(ay0, oy - reach)
    x1, y1 = min(ax1, ox + rw + reach), min(ay1, oy + rh + reach)
    if x0 >= x1 or y0 >= y1:
        return None
    seed = np.zeros((y1 - y0, x1 - x0), np.uint8)
    sy0, sx0 = max(0, y0 - oy), max(0, x0 - ox)
    sy1, sx1 = min(rh, y1 - oy), min(rw, x1 - ox)
    seed[sy0 + oy - y0 : sy1 + oy - y0, sx0 + ox - x0 : sx1 + ox - x0] = region[sy0:sy1, sx0:sx1]
    raw = depth[y0:y1, x0:x1]
    opening = (raw == 0) | behind_plane(raw, (x0, y0), camera, plane)
    if barrier is not None:
        opening &= ~barrier((x0, y0, x1, y1))
    # Lines one pixel wide (noise, flying pixels, a fattened edge's gaps) are no opening.
    opening_u8 = np.asarray(cv2.morphologyEx(opening.view(np.uint8), cv2.MORPH_OPEN, _K3), np.uint8)
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * reach + 1, 2 * reach + 1))
    allowed = opening_u8 & np.asarray(cv2.dilate(seed, k), np.uint8)
    n, lab = cv2.connectedComponents(allowed, connectivity=8)
    if n < 2:
        return None
    lut = np.zeros(n, np.uint8)
    lut[lab[(seed > 0) & (allowed > 0)]] = 1
    lut[0] = 0
    if not lut.any():
        return None
    x, y, w, h = cv2.boundingRect(lut[lab])
    return (x + x0, y + y0, x + w + x0, y + h + y0)


def pixel_box(
    m: Measured,
    f: FrameData,
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


def _lit_unread(f: FrameData) -> npt.NDArray[np.bool_]:
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
    mask: npt.NDArray[np.bool_], origin: tuple[int, int], f: FrameData
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
