"""Scoring holes against the simulator's truth: found, missed, not in view, false.

The truth comes from the simulated world (:class:`sim.RubbleWorld`), which the code under
test never sees: each true access hole the camera saw whole in enough frames must be found
by a reported hole (within ``match_m`` of its centre or inside its opening); reported holes
matching no true hole are false, and the nearest feature of the world is named.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Iterable, Sequence
from typing import Any

from holescan.geotag import Hole, LocalFrame, nearest_pairs
from holescan.sim import GtBox, RubbleWorld, TrueHole

__all__ = ["FalseHole", "TruthRow", "count_in_view", "frames_in_view", "score_holes"]


@dataclasses.dataclass(frozen=True)
class TruthRow:
    """One true access hole and what the flight made of it.

    status : ``found``, ``missed`` (seen whole in enough frames, not found) or
    ``not in view``. x_m, y_m : position in the field (east, north of its south-west corner).
    hole_id, error_m, sightings : the confirmed hole that found it, its horizontal distance
    to the truth, its sightings.
    """

    truth: TrueHole
    frames_in_view: int
    status: str
    hole_id: int | None
    error_m: float
    sightings: int


@dataclasses.dataclass(frozen=True)
class FalseHole:
    """A confirmed hole that is no true access hole; ``nearest`` names the closest feature
    of the world (a distractor kind, or an access hole farther than the match distance)."""

    hole: Hole
    nearest: str
    distance_m: float


def count_in_view(boxes_per_frame: Iterable[Iterable[GtBox]]) -> Counter[int]:
    """World hole id -> frames that showed the whole opening (not cut by the border)."""
    seen: Counter[int] = Counter()
    for boxes in boxes_per_frame:
        for b in boxes:
            if not b.iscrowd:
                seen[b.hole_id] += 1
    return seen


def frames_in_view(sources: Iterable[Any]) -> Counter[int]:
    """:func:`count_in_view` over the truth of simulated cameras (:class:`sim.SimSource`)."""
    return count_in_view(boxes for src in sources for _, boxes in src.truth.values())


def _en(world_anchor: Any, lat: float, lon: float) -> tuple[float, float]:
    frame = LocalFrame(world_anchor.lat_deg, world_anchor.lon_deg, world_anchor.alt_m)
    x, y = frame.to_en(lat, lon)
    return float(x), float(y)


def score_holes(
    reported: Sequence[Hole],
    truth: Sequence[TrueHole],
    world: RubbleWorld,
    anchor: Any,
    in_view: Counter[int],
    *,
    match_m: float = 0.5,
    min_frames_in_view: int = 3,
) -> tuple[tuple[TruthRow, ...], tuple[FalseHole, ...]]:
    """Match reported holes to the true access holes, nearest pairs first, each used once.

    A reported hole finds a true one when it lies within ``match_m`` of its centre or
    inside its opening (a big hole seen cut by the image border is placed off its centre,
    yet a crew sent there stands at the hole). A true hole whole in view in at least
    ``min_frames_in_view`` frames and not found is ``missed``. Unmatched reported holes
    are false; the nearest feature of the world is named.
    """
    from shapely.geometry import Point, Polygon

    confirmed = reported
    xy = [_en(anchor, h.lat_deg, h.lon_deg) for h in confirmed]
    pairs = []
    for i, t in enumerate(truth):
        opening = Polygon(world.holes[t.id].opening)
        for j, (x, y) in enumerate(xy):
            d = math.hypot(x - t.x_m, y - t.y_m)
            if d <= match_m or opening.contains(Point(x, y)):
                pairs.append((d, i, j))
    matched = nearest_pairs(pairs)
    used = {j for j, _ in matched.values()}
    rows = []
    for i, t in enumerate(truth):
        frames = in_view.get(t.id, 0)
        if i in matched:
            j, d = matched[i]
            h = confirmed[j]
            rows.append(TruthRow(t, frames, "found", h.id, d, h.sightings))
        else:
            status = "missed" if frames >= min_frames_in_view else "not in view"
            rows.append(TruthRow(t, frames, status, None, math.nan, 0))
    false = []
    for j, h in enumerate(confirmed):
        if j in used:
            continue
        x, y = xy[j]
        best = ("nothing", math.inf)
        for feature in world.holes:
            d = math.hypot(feature.centre_xy[0] - x, feature.centre_xy[1] - y)
            if d < best[1]:
                kind = "access hole" if feature.is_access else feature.kind.replace("_", " ")
                best = (kind, d)
        false.append(FalseHole(h, best[0], best[1]))
    return tuple(rows), tuple(false)
