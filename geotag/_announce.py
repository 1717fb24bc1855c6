"""When the vehicle tells the ground crew about a hole, and again about the same hole.

:class:`AnnounceGate` (``_tiers``) says which tier a hole is in; :class:`AnnouncePolicy`
remembers what the ground was last told of each hole in each tier and says which of the
holes that just changed are news worth a message (a STATUSTEXT, a card, a waypoint).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from holescan.geotag._local import local_en_m
from holescan.geotag._merge import Hole
from holescan.geotag._tiers import AnnounceGate, Tier, VehicleTier

__all__ = ["AnnouncePolicy", "HoleNews", "Told"]


@dataclass(frozen=True)
class Told:
    """What the ground was last told of one hole in one tier: where it was and its score.

    lat_deg, lon_deg : WGS84 position sent. score : the hole's best detector score then.
    """

    lat_deg: float
    lon_deg: float
    score: float

    @classmethod
    def of(cls, hole: Hole) -> Told:
        """The record of telling ``hole`` now."""
        return cls(hole.lat_deg, hole.lon_deg, hole.score)


@dataclass(frozen=True)
class HoleNews:
    """A hole to tell the ground now, in the tier it reaches it with."""

    hole: Hole
    tier: VehicleTier


class AnnouncePolicy:
    """The vehicle's memory of what it told the ground, and the rule for telling again.

    A hole in the *announced* or *review* tier (``gate``) is news when the ground was not
    told of it in that tier yet, when it moved more than ``min_move_m`` metres or when its
    score rose by more than ``min_score_rise`` since it was last told in that tier. A hole
    for review that becomes announced is told again; a *candidate* never is. Not
    thread-safe: one caller (the daemon's results, under its lock).

    Parameters
    ----------
    gate : the tier gate (:class:`AnnounceGate`).
    min_move_m : horizontal move, metres, that makes a told hole news again.
    min_score_rise : score rise that makes a told hole news again.

    Examples
    --------
    >>> from holescan.geotag import Hole
    >>> hole = Hole(1, 47.0, 8.0, 500.0, 0.2, 0.9, 3, 0, 10**9, 0, (0, 0, 9, 9), 1.0, 0.8,
    ...             p_hole=0.95)
    >>> policy = AnnouncePolicy(AnnounceGate())
    >>> served, tiers = policy.tiers([hole])
    >>> tiers
    {1: 'announced'}
    >>> [(n.hole.id, n.tier) for n in policy.tell([hole], tiers)]
    [(1, 'announced')]
    >>> policy.tell([hole], tiers)  # told already, not moved: no news
    []
    """

    def __init__(
        self, gate: AnnounceGate, *, min_move_m: float = 0.5, min_score_rise: float = 0.05
    ) -> None:
        self.gate = gate
        self.min_move_m = min_move_m
        self.min_score_rise = min_score_rise
        self._told: dict[VehicleTier, dict[int, Told]] = {"announced": {}, "review": {}}

    @property
    def announced(self) -> Mapping[int, Told]:
        """Hole id -> what the ground was last told of it as announced."""
        return self._told["announced"]

    @property
    def reviewed(self) -> Mapping[int, Told]:
        """Hole id -> what the ground was last told of it for review."""
        return self._told["review"]

    def tiers(self, holes: Sequence[Hole]) -> tuple[list[Hole], dict[int, Tier]]:
        """The holes to serve (the gate's :meth:`~AnnounceGate.select`: the holes already
        announced stay while they pass) and every hole's tier (:meth:`AnnounceGate.tiers`,
        given the holes announced so far)."""
        announced = tuple(self.announced)
        return self.gate.select(holes, announced), self.gate.tiers(holes, announced)

    def worth_telling(self, hole: Hole, tier: VehicleTier) -> bool:
        """True when ``hole`` is news in ``tier`` (see the class docstring)."""
        last = self._told[tier].get(hole.id)
        if last is None:
            return True
        east, north = local_en_m(hole.lat_deg, hole.lon_deg, last.lat_deg, last.lon_deg)
        return bool(
            math.hypot(east, north) > self.min_move_m
            or hole.score > last.score + self.min_score_rise
        )

    def tell(self, changed: Iterable[Hole], tiers: Mapping[int, Tier]) -> list[HoleNews]:
        """The holes of ``changed`` worth telling now in their tier (``tiers``, from
        :meth:`tiers`), in order; each is remembered as told."""
        news: list[HoleNews] = []
        for h in changed:
            tier = tiers[h.id]
            if tier != "candidate" and self.worth_telling(h, tier):
                news.append(HoleNews(h, tier))
        for n in news:
            self._told[n.tier][n.hole.id] = Told.of(n.hole)
        return news
