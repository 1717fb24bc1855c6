"""Which holes go to the ground crew, and how: announced, for review, or kept as candidates.

See :class:`AnnounceGate`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal

import pymap3d

from holescan.detect import p_hole_of_score
from holescan.errors import InputError
from holescan.geotag._merge import Hole

__all__ = ["TIERS", "AnnounceGate", "Tier"]

_P_HOLE_MAX = 0.99  # p_hole is kept within [0.01, 0.99]

Tier = Literal["announced", "review", "candidate"]
TIERS: tuple[Tier, ...] = ("announced", "review", "candidate")


@dataclass(frozen=True)
class AnnounceGate:
    """When a hole is worth a rescuer's look: announced, served as a waypoint, sent on.

    A hole passes when all three hold:

    min_p_hole : the probability that it is a true access hole, ``p_hole`` of its best
        detector score (:func:`detect.p_hole_of_score`, see :meth:`p_hole`). ``p_hole``
        never leaves [0.01, 0.99], so the threshold must lie in [0, 0.99].
    min_sightings : frames it was seen in (2: the count depends on the detector's frame
        rate, which drops to ~2.5 frames/s on a loaded computer; the time span does not).
    min_span_s : seconds between its first and last sighting. The vehicle moves over the
        hole meanwhile (0.6-1 m/s on a survey), so the views come from different
        positions: a one-view artefact (a glint, a shadow edge) does not repeat.

    min_separation_m, separation_fraction : a passing hole this close to one already
        kept is the same opening seen twice (see :meth:`select`).

    Holes that do not pass stay *candidates*: logged and written to the hole files marked
    as such, never a waypoint.

    The calibration is the **default** detector mode's (Platt scaling fitted on its
    scores). Paper mode's scores are not calibrated (its detections carry ``p_hole =
    None``); the gate still maps them through the same curve, a monotone map, so in paper
    mode ``min_p_hole`` is a raw-score threshold in disguise (0.5 is a paper score of
    0.37), not a probability. One rule for both modes keeps one config key and one meaning
    of "announced" on the ground; paper mode (2.5-3.5 s a frame) is a reference, not a
    flight mode, and falling back to the raw score would silently change what a given
    ``announce_min_p_hole`` lets through.

    The default ``min_p_hole = 0.5`` was measured with the current detector
    (``benchmarks/bench_announce.py``: 8 simulated worlds, 6,000 frames; figures in the
    README, "What is announced"): every true hole seen twice over 0.3 s had p_hole >=
    0.973, every false one (cracks, stains, small holes, a depression) <= 0.112, so any
    threshold from 0.2 to 0.95 delivers the same 23 holes, all true (precision 1.000),
    21 of the 22 true holes in view (the 22nd: one detection at score 0.09 in the whole
    lap), first sighting to delivery median 0.3 s. Through the whole demo path
    (``benchmarks/bench_delivery.py``, the same 8 worlds, 14-21 detected frames/s) 0.5
    announced 20 holes, all true, all 20 true holes in view, median 0.4 s, max 17.6 s. But
    on an idle machine (29 detected frames/s) ``holescan demo`` saw a stain 11 times at
    score 0.43 (p_hole 0.73) and announced it at 0.5: more frames give a weak false box
    more sightings. Hence 0.9: still far below every true hole seen twice (0.973), above
    that stain; on independent single detections it keeps 91 of 101 true ones (0.5: 98),
    and in flight a hole is judged on its best of many views.

    Examples
    --------
    >>> gate = AnnounceGate(min_p_hole=0.5, min_sightings=2, min_span_s=0.3)
    >>> gate.min_p_hole
    0.5
    >>> from detect import p_hole_of_score  # p_hole 0.5 is a best score of 0.368
    >>> p_hole_of_score(0.37) >= gate.min_p_hole > p_hole_of_score(0.36)
    True
    """

    min_p_hole: float = 0.9
    min_sightings: int = 2
    min_span_s: float = 0.3
    min_separation_m: float = 0.5
    separation_fraction: float = 0.5

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_p_hole <= _P_HOLE_MAX:
            raise InputError(
                f"announce min_p_hole must be in [0, {_P_HOLE_MAX}] (p_hole never exceeds "
                f"{_P_HOLE_MAX}), got {self.min_p_hole}"
            )
        if self.min_sightings < 1 or not self.min_span_s >= 0.0:
            raise InputError("announce min_sightings must be >= 1 and min_span_s >= 0")

    def p_hole(self, hole: Hole) -> float:
        """``p_hole`` of ``hole``: of its best detector score."""
        return p_hole_of_score(hole.score)

    def select(self, holes: Sequence[Hole], announced: Iterable[int] = ()) -> list[Hole]:
        """The holes to announce and serve: those that pass, less duplicates.

        A duplicate lies within ``max(min_separation_m, separation_fraction * major
        axis)`` of a hole kept before it: the tracker keeps one sighting per hole per
        frame, so a detector that boxes one opening twice in a frame makes two holes at
        the same place. Holes already ``announced`` are always kept (the ground has them);
        the others in id order. Sorted by id.
        """
        done = set(announced)
        ordered = sorted(
            (h for h in holes if self.passes(h)), key=lambda h: (h.id not in done, h.id)
        )
        kept: list[Hole] = []
        for h in ordered:
            if h.id not in done and any(_duplicate(h, k, self) for k in kept):
                continue
            kept.append(h)
        return sorted(kept, key=lambda h: h.id)

    def passes(self, hole: Hole) -> bool:
        """True when ``hole`` is strong enough to be announced."""
        span_s = (hole.t_last_boot_ns - hole.t_first_boot_ns) * 1e-9
        return (
            self.p_hole(hole) >= self.min_p_hole
            and hole.sightings >= self.min_sightings
            and span_s >= self.min_span_s
        )


def _duplicate(a: Hole, b: Hole, gate: AnnounceGate) -> bool:
    radius = max(gate.min_separation_m, gate.separation_fraction * max(a.major_m, b.major_m))
    n, e, _ = pymap3d.geodetic2ned(a.lat_deg, a.lon_deg, b.alt_m, b.lat_deg, b.lon_deg, b.alt_m)
    return bool(math.hypot(float(n), float(e)) < radius)
