"""Non-maximum suppression of the default detector's measured regions.

Overlapping boxes, and boxes holding a better detection (a depression or a no-reading area
around a hole, not a second hole), are suppressed. "Better" is the score, except between a
basin closed by bridging its cut at the border and a basin inside it whose rim was seen all
round (:func:`nms`). Pure: records in, records out.
"""

from __future__ import annotations

import numpy as np

from holescan.detect._evaluate import overlap
from holescan.detect._measure import Measured, ReadBox

__all__ = ["box_iou", "nms"]

# NMS between a bridged basin and a basin inside it with its rim seen all round
# (_priorities): the inner one counts when it scores at least this fraction of the bridged
# one (a much weaker dip is a dip in the hole's floor), and it runs on to the cut when it
# comes within its ring and walls of it (RING_PX + options.grow_px work pixels).
INNER_SCORE_RATIO = 0.5
# A bridged basin that is the hole running on to the cut reaches beyond the enclosed deep
# part inside it, on the sides away from the cut, by the hole's sloping walls: up to this
# fraction of the deep part's extent (beside the ring and walls every region is grown by).
WALLS_BEYOND = 0.25


def nms(
    found: list[Measured], iou_max: float, contained: float, near_px: int | None
) -> list[Measured]:
    """Suppress overlaps (IoU > ``iou_max``) and containers of a better detection.

    A region that holds a higher-scoring one (most of it inside) is a depression or a
    no-reading area around that hole, not a second hole. "Better" is the score, except
    between a bridged basin and a basin inside it (:func:`_priorities`; ``near_px`` None:
    the score alone, ``options.seen_rim_first`` off).
    """
    keep: list[Measured] = []
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


def _priorities(found: list[Measured], contained: float, near_px: int) -> list[float]:
    """The order of NMS: each candidate's score, but a bridged basin (closed by a rim
    assumed across the border cut) and a basin inside it whose rim was seen all round (an
    enclosed pit, not bridged, not cut) that scores at least :data:`INNER_SCORE_RATIO` of
    it:

    * when the inner basin comes within ``near_px`` of a side the bridged one is cut by,
      and the bridged one runs on beyond it only toward the cut (on every other side within
      ``near_px`` and :data:`WALLS_BEYOND` of its extent), it is the deep part of a hole
      that runs on to the cut: the bridged basin goes first (its box is the hole's);
    * otherwise seen rim lies between the inner basin and the cut (or the bridged basin
      spreads away from the cut too): the bridged basin is the depression around that
      hole, its depth measured against a rim partly assumed; the inner basin goes first
      (and the bridged one, holding it, is dropped).
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
            runs_on = near_cut(e.read, b.read, near_px) and toward_cut(e.read, b.read, near_px)
            first, then = (i, j) if runs_on else (j, i)
            if rank[first] <= rank[then]:
                rank[first] = np.nextafter(rank[then], np.inf)
    return rank


def near_cut(inner: ReadBox, outer: ReadBox, near: int) -> bool:
    """Whether ``inner`` comes within ``near`` work pixels of a side of the read area
    that ``outer`` reaches."""
    (ix0, iy0, ix1, iy1), (ox0, oy0, ox1, oy1), (ww, hh) = inner.box, outer.box, outer.size
    return (
        (ox0 == 0 and ix0 <= near)
        or (oy0 == 0 and iy0 <= near)
        or (ox1 == ww and ww - ix1 <= near)
        or (oy1 == hh and hh - iy1 <= near)
    )


def toward_cut(inner: ReadBox, outer: ReadBox, near: int) -> bool:
    """Whether ``outer`` runs on beyond ``inner`` only toward the sides of the read area it
    reaches: on every other side it ends within ``near`` work pixels (a ring and walls) and
    :data:`WALLS_BEYOND` of ``inner``'s extent of it. A bridged basin that spreads farther
    away from the cut is a depression around the hole, closed across the border, not the
    hole running on to the cut."""
    (ix0, iy0, ix1, iy1), (ox0, oy0, ox1, oy1), (ww, hh) = inner.box, outer.box, outer.size
    mx, my = near + WALLS_BEYOND * (ix1 - ix0), near + WALLS_BEYOND * (iy1 - iy0)
    return (
        (ox0 == 0 or ox0 >= ix0 - mx)
        and (oy0 == 0 or oy0 >= iy0 - my)
        and (ox1 == ww or ox1 <= ix1 + mx)
        and (oy1 == hh or oy1 <= iy1 + my)
    )


def _inside(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> float:
    """Fraction of box ``a`` that lies inside box ``b`` (a crowd overlap: over ``a``'s area)."""
    return overlap(a, b, "iou", crowd=True)


def box_iou(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> float:
    """Intersection over union of two (x, y, w, h) boxes."""
    return overlap(a, b, "iou")
