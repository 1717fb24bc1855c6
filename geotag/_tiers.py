"""Which holes go to the ground crew, and how: announced, for review, or kept as candidates.

See :class:`AnnounceGate`: its :meth:`~AnnounceGate.tier` is the vehicle's decision.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal, get_args

from holescan.detect import p_hole_of_score
from holescan.errors import InputError
from holescan.geotag._local import LocalFrame
from holescan.geotag._merge import Hole

__all__ = [
    "FOUND_TIERS",
    "HOLE_TIERS",
    "TIERS",
    "VEHICLE_TIERS",
    "AnnounceGate",
    "HoleTier",
    "Tier",
    "VehicleTier",
    "holes_found",
]

_P_HOLE_MAX = 0.99  # p_hole is kept within [0.01, 0.99]

Tier = Literal["announced", "review", "candidate"]
"""What the vehicle makes of a hole (:meth:`AnnounceGate.tier`)."""
TIERS: tuple[Tier, ...] = get_args(Tier)
VehicleTier = Literal["announced", "review"]
"""The tiers that reach the ground (a candidate stays on board)."""
VEHICLE_TIERS: tuple[VehicleTier, ...] = get_args(VehicleTier)
HoleTier = Literal["announced", "review", "confirmed", "rejected"]
"""What a hole is for the crews: the vehicle's tier, or the operator's confirmation or
rejection (hole files, the ground station, TAK)."""
HOLE_TIERS: tuple[HoleTier, ...] = get_args(HoleTier)

FOUND_TIERS: tuple[HoleTier, ...] = ("announced", "review", "confirmed")
"""What "holes found" counts, everywhere (console, report, ``demo.json``, reprocessing's
summaries): the holes that reach a person: *announced*, *for review*, and those an operator
*confirmed* (or visited). Candidates (logged only) and holes an operator *rejected* are not
found holes."""


def holes_found(tiers: Iterable[str]) -> int:
    """How many of ``tiers`` (one per hole) are found holes (:data:`FOUND_TIERS`).

    >>> holes_found(["announced", "review", "candidate", "rejected", "confirmed"])
    3
    """
    return sum(t in FOUND_TIERS for t in tiers)


@dataclass(frozen=True)
class AnnounceGate:
    """Which tier a hole is in: *announced*, *for review*, or a *candidate*.

    * **announced** (high confidence) goes to the crew as before: STATUSTEXT ``HOLE ...``,
      a waypoint of the hole mission (component 191), its picture, TAK. A hole is
      announced when ``p_hole >= min_p_hole``, it was seen ``min_sightings`` times over
      ``min_span_s`` seconds (a one-view artefact does not repeat as the vehicle moves);
    * **review** (plausible, not sure) reaches the ground station too, with its picture
      (a card marked ``"tier": "review"``, STATUSTEXT ``REVIEW ...``), for an operator to
      confirm or reject; it is not in the mission and not sent to TAK until confirmed. A
      hole not announced is for review when ``p_hole >= review_min_p_hole``;
    * **candidate**: everything else; logged and in the flight's report, not in the crew's
      files.

    **The absorbing-surface vote** (:meth:`surface_held`): a hole that at least
    ``surface_min_views`` viewpoints measured against its rim's plane, of which at least
    ``surface_min_share`` read its inside *on* the plane, and at most
    ``surface_max_behind_ratio`` times as many *behind* it, is a surface that returns no
    infrared (soot, char, a wet black patch) more likely than a void, whose walls views
    show behind the plane and never on it. It is never announced, whatever its
    ``p_hole``: it is for review if it would otherwise have been announced or reaches
    ``review_min_p_hole`` (recall first: the vote never drops a hole below review, it only
    keeps it from being announced). Its second arm weighs the clear readings alone: a hole
    that at least ``surface_tie_views`` viewpoints read *on* its plane, and no more
    viewpoints *behind* it, is held too (views reading both, or nothing, count neither way;
    0 turns the arm off; at 1, its default, it holds every hole the first arm holds, which
    then matters only with the arm off or set higher). A void's views read its walls
    behind the plane; a view on the plane that no more views contradict is not a void's
    to announce unseen (measured on 18 simulated worlds: 3 stain holes announced without
    it, none with it; 2 of 144 access holes reviewed instead of announced by their own
    pass; survey flights unchanged).

    **Seen only at the image's edge** (:meth:`edge_held`): a hole without readings inside
    (its views measured against the rim plane) that no view saw whole (every sighting's
    box cut by the image border, or whole only with p_hole < 0.5) is never announced,
    unless at least ``edge_behind_views`` viewpoints read its inside behind the rim plane
    (a void's walls). Cut by the border, an unread patch's rim is unknown on that side and
    its inside is read too little for the vote: an absorbing stain glimpsed at the edge
    of the frame scores like a void there. It is for review until a view sees it whole
    (``edge_behind_views`` 0: never held).

    ``p_hole`` is the hole-level confidence of all its sightings (:attr:`Hole.p_hole`,
    :class:`geotag.ConfidenceModel`); holes read from logs that predate it use the best
    frame's (:func:`detect.p_hole_of_score` of the best score). It never leaves
    [0.01, 0.99], so thresholds lie in [0, 0.99].

    min_separation_m, separation_fraction : a passing hole this close to one already kept
        is the same opening seen twice (see :meth:`select`; the tracker fuses overlapping
        openings, this is a last guard).

    The defaults were chosen from measured curves (``benchmarks/bench_tiers.py``, flights
    over worlds and seeds not used to fit the confidence; docs/tiers.md): announced
    precision >= 0.9 and announced + review recall >= 0.99 of the holes in view.

    Examples
    --------
    >>> gate = AnnounceGate(min_p_hole=0.5, min_sightings=2, min_span_s=0.3)
    >>> gate.min_p_hole
    0.5
    >>> from holescan.detect import p_hole_of_score  # p_hole 0.5 is a best score of 0.368
    >>> p_hole_of_score(0.37) >= gate.min_p_hole > p_hole_of_score(0.36)
    True
    """

    min_p_hole: float = 0.9
    min_sightings: int = 2
    min_span_s: float = 0.3
    review_min_p_hole: float = 0.1
    min_separation_m: float = 0.5
    separation_fraction: float = 0.5
    surface_min_views: int = 3
    surface_min_share: float = 0.5
    surface_max_behind_ratio: float = 0.5
    edge_behind_views: int = 2
    surface_tie_views: int = 1

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_p_hole <= _P_HOLE_MAX:
            raise InputError(
                f"announce min_p_hole must be in [0, {_P_HOLE_MAX}] (p_hole never exceeds "
                f"{_P_HOLE_MAX}), got {self.min_p_hole}"
            )
        if self.min_sightings < 1 or not self.min_span_s >= 0.0:
            raise InputError("announce min_sightings must be >= 1 and min_span_s >= 0")
        if not 0.0 <= self.review_min_p_hole <= _P_HOLE_MAX:
            raise InputError(
                f"review min_p_hole must be in [0, {_P_HOLE_MAX}], got {self.review_min_p_hole}"
            )
        if self.surface_min_views < 1 or not (
            0.0 <= self.surface_min_share <= 1.0 and self.surface_max_behind_ratio >= 0.0
        ):
            raise InputError(
                "surface vote: min_views must be >= 1, min_share in [0, 1], max_behind_ratio >= 0"
            )
        if self.edge_behind_views < 0:
            raise InputError("edge_behind_views must be >= 0")
        if self.surface_tie_views < 0:
            raise InputError("surface_tie_views must be >= 0")

    def summary(self) -> str:
        """The thresholds in one line: ``announced p_hole >= 0.9, >= 2 sightings over
        >= 0.3 s; review p_hole >= 0.1``."""
        return (
            f"announced p_hole >= {self.min_p_hole:g}, >= {self.min_sightings} sightings "
            f"over >= {self.min_span_s:g} s; review p_hole >= {self.review_min_p_hole:g}"
        )

    def p_hole(self, hole: Hole) -> float:
        """``p_hole`` of ``hole``: its hole-level confidence (logs from before: its best
        frame's)."""
        return hole.p_hole if math.isfinite(hole.p_hole) else p_hole_of_score(hole.score)

    def tier(self, hole: Hole) -> Tier:
        """``announced``, ``review`` or ``candidate`` (see the class docstring)."""
        if self.passes(hole):
            return "announced"
        if self.p_hole(hole) >= self.review_min_p_hole or self._strong(hole):
            return "review"
        return "candidate"

    def surface_held(self, hole: Hole) -> bool:
        """True when the absorbing-surface vote holds ``hole`` back from announcement: at
        least ``surface_min_views`` viewpoints measured its inside against the rim plane,
        at least ``surface_min_share`` of them read it on the plane, at most
        ``surface_max_behind_ratio`` times as many behind it; or at least
        ``surface_tie_views`` read it on the plane and no more behind it (holes from older
        logs: never).

        >>> from holescan.geotag import Hole
        >>> h = Hole(1, 0, 0, 0, 1, 0.9, 9, 0, 10**9, 3, (0, 0, 9, 9), 0.7, 0.5, 0.99, 6)
        >>> gate = AnnounceGate()
        >>> gate.tier(h)
        'announced'
        >>> from dataclasses import replace
        >>> stain = replace(h, plane_views=4, surface_views=2, behind_views=0)
        >>> gate.surface_held(stain), gate.tier(stain)
        (True, 'review')
        >>> tie = replace(stain, behind_views=2)  # as many views saw behind the plane
        >>> gate.surface_held(tie), gate.tier(tie)
        (True, 'review')
        >>> void = replace(stain, behind_views=3)  # more views saw behind the plane
        >>> gate.surface_held(void), gate.tier(void)
        (False, 'announced')
        """
        n = hole.plane_views
        tie = (
            self.surface_tie_views > 0
            and hole.surface_views >= self.surface_tie_views
            and hole.behind_views <= hole.surface_views
        )
        return tie or (
            n >= self.surface_min_views
            and hole.surface_views >= self.surface_min_share * n
            and hole.behind_views <= self.surface_max_behind_ratio * hole.surface_views
        )

    def edge_held(self, hole: Hole) -> bool:
        """True when ``hole`` is held back from announcement for being seen only at the
        image's edge: unread inside (measured against its rim plane from some viewpoint),
        never seen whole with p_hole >= 0.5, and read behind its rim plane from fewer than
        ``edge_behind_views`` viewpoints (see the class docstring).

        >>> from dataclasses import replace
        >>> from holescan.geotag import Hole
        >>> h = Hole(1, 0, 0, 0, 1, 0.9, 9, 0, 10**9, 3, (0, 0, 9, 9), 0.7, 0.5, 0.99, 6)
        >>> edge = replace(h, plane_views=3, seen_whole=False)
        >>> gate = AnnounceGate()
        >>> gate.edge_held(edge), gate.tier(edge)
        (True, 'review')
        >>> walls = replace(edge, behind_views=2)  # two viewpoints read walls behind the rim
        >>> gate.edge_held(walls), gate.tier(walls)
        (False, 'announced')
        >>> gate.tier(replace(edge, seen_whole=True)), AnnounceGate(edge_behind_views=0).tier(edge)
        ('announced', 'announced')
        """
        return (
            self.edge_behind_views > 0
            and not hole.seen_whole
            and hole.plane_views >= 1
            and hole.behind_views < self.edge_behind_views
        )

    def tiers(self, holes: Sequence[Hole], announced: Iterable[int] = ()) -> dict[int, Tier]:
        """Every hole's tier, as the vehicle gives it: :meth:`select` (announced, less
        duplicates), :meth:`review` (for review, not at an announced hole's place), the
        rest candidates (a hole that passes but duplicates a kept one is a candidate).
        ``announced`` : ids the ground already has as announced (they stay announced while
        they pass). The one rule for tiers: in flight, in the demo, in reprocessing and
        campaigns.
        """
        announced = tuple(announced)
        out: dict[int, Tier] = {h.id: "candidate" for h in holes}
        out.update({h.id: "review" for h in self.review(holes, announced)})
        out.update({h.id: "announced" for h in self.select(holes, announced)})
        return out

    def review(self, holes: Sequence[Hole], announced: Iterable[int] = ()) -> list[Hole]:
        """The holes for review: in the review tier, not at the place of an announced one
        (:meth:`select`'s duplicate rule). Sorted by id."""
        kept = self.select(holes, announced)
        out = []
        for h in sorted(holes, key=lambda h: h.id):
            if self.tier(h) == "review" and not any(_duplicate(h, k, self) for k in kept):
                out.append(h)
        return out

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
        """True when ``hole`` is strong enough to be announced and neither the
        absorbing-surface vote (:meth:`surface_held`) nor having been seen only at the
        image's edge (:meth:`edge_held`) holds it back."""
        return self._strong(hole) and not self.surface_held(hole) and not self.edge_held(hole)

    def _strong(self, hole: Hole) -> bool:
        """Confident enough, seen often and long enough to be announced."""
        span_s = (hole.t_last_boot_ns - hole.t_first_boot_ns) * 1e-9
        return (
            self.p_hole(hole) >= self.min_p_hole
            and hole.sightings >= self.min_sightings
            and span_s >= self.min_span_s
        )


def _duplicate(a: Hole, b: Hole, gate: AnnounceGate) -> bool:
    radius = max(gate.min_separation_m, gate.separation_fraction * max(a.major_m, b.major_m))
    e, n = LocalFrame(b.lat_deg, b.lon_deg, b.alt_m).to_en(a.lat_deg, a.lon_deg)
    return bool(math.hypot(float(n), float(e)) < radius)
