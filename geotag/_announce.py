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
    """What the ground was last told of one hole in one tier: the hole as it was then
    (its position, sigma, scores, sightings and size went down with it)."""

    hole: Hole


@dataclass(frozen=True)
class HoleNews:
    """A hole to tell the ground now, in the tier it reaches it with."""

    hole: Hole
    tier: VehicleTier


class AnnouncePolicy:
    """The vehicle's memory of what it told the ground, and the rule for telling again.

    A hole in the *announced* or *review* tier (``gate``) is news when the ground was not
    told of it in that tier yet, or, since it was last told in that tier, when

    - it moved more than ``min_move_m`` metres, or
    - its best score rose by more than ``min_score_rise``, or its hole-level p_hole
      changed by more than ``min_p_change`` (the number the STATUSTEXT carries), or
    - its sigma changed noticeably: by more than ``min_sigma_change_m`` *and* by more than
      ``min_sigma_change_frac`` of the sigma told (a fused position's sigma shrinks with
      every view: 1.20 m -> 1.05 m is told, 1.20 m -> 1.16 m waits for the end).

    A hole for review that becomes announced is told again; a *candidate* never is. When
    the flight ends, :meth:`final` tells every hole whose facts changed at all since they
    were last told (new sightings, a sigma a few centimetres smaller), so the ground ends
    with the vehicle's last numbers. Not thread-safe: one caller (the daemon's results,
    under its lock).

    Parameters
    ----------
    gate : the tier gate (:class:`AnnounceGate`).
    min_move_m : horizontal move, metres, that makes a told hole news again.
    min_score_rise : best-score rise that makes a told hole news again.
    min_p_change : p_hole change (either way) that makes a told hole news again.
    min_sigma_change_m, min_sigma_change_frac : sigma change (either way; metres, and
        fraction of the sigma told) that makes a told hole news again, both exceeded.

    Examples
    --------
    >>> from dataclasses import replace
    >>> from holescan.geotag import Hole
    >>> hole = Hole(1, 47.0, 8.0, 500.0, 1.2, 0.9, 3, 0, 10**9, 0, (0, 0, 9, 9), 1.0, 0.8,
    ...             p_hole=0.95)
    >>> policy = AnnouncePolicy(AnnounceGate())
    >>> served, tiers = policy.tiers([hole])
    >>> tiers
    {1: 'announced'}
    >>> [(n.hole.id, n.tier) for n in policy.tell([hole], tiers)]
    [(1, 'announced')]
    >>> policy.tell([hole], tiers)  # told already, not moved: no news
    []
    >>> len(policy.tell([replace(hole, sigma_h_m=1.05)], tiers))  # sigma 1.2 -> 1.05 m
    1
    >>> later = replace(hole, sigma_h_m=1.02, sightings=9)
    >>> policy.tell([later], tiers)  # 3 cm smaller: not noticeable in flight
    []
    >>> [(n.hole.sigma_h_m, n.tier) for n in policy.final([later], tiers)]  # but at the end
    [(1.02, 'announced')]
    >>> policy.final([later], tiers)  # told: nothing left
    []
    """

    def __init__(
        self,
        gate: AnnounceGate,
        *,
        min_move_m: float = 0.5,
        min_score_rise: float = 0.05,
        min_p_change: float = 0.05,
        min_sigma_change_m: float = 0.1,
        min_sigma_change_frac: float = 0.1,
    ) -> None:
        self.gate = gate
        self.min_move_m = min_move_m
        self.min_score_rise = min_score_rise
        self.min_p_change = min_p_change
        self.min_sigma_change_m = min_sigma_change_m
        self.min_sigma_change_frac = min_sigma_change_frac
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
        was = last.hole
        east, north = local_en_m(hole.lat_deg, hole.lon_deg, was.lat_deg, was.lon_deg)
        return bool(
            math.hypot(east, north) > self.min_move_m
            or hole.score > was.score + self.min_score_rise
            or _changed_by(hole.p_hole, was.p_hole, self.min_p_change)
            or self._sigma_news(hole.sigma_h_m, was.sigma_h_m)
        )

    def _sigma_news(self, now: float, was: float) -> bool:
        if not (math.isfinite(now) and math.isfinite(was)):
            return math.isfinite(now) != math.isfinite(was)
        change = abs(now - was)
        return change > self.min_sigma_change_m and change > self.min_sigma_change_frac * was

    def tell(self, changed: Iterable[Hole], tiers: Mapping[int, Tier]) -> list[HoleNews]:
        """The holes of ``changed`` worth telling now in their tier (``tiers``, from
        :meth:`tiers`), in order; each is remembered as told."""
        return self._remember(
            HoleNews(h, tier)
            for h in changed
            if (tier := tiers[h.id]) != "candidate" and self.worth_telling(h, tier)
        )

    def final(self, holes: Iterable[Hole], tiers: Mapping[int, Tier]) -> list[HoleNews]:
        """At the flight's end: every hole of ``holes`` in the announced or review tier
        whose facts differ in any way from what the ground was last told of it in that
        tier (or that it was never told of), in order; each is remembered as told."""
        return self._remember(
            HoleNews(h, tier)
            for h in holes
            if (tier := tiers[h.id]) != "candidate"
            and ((last := self._told[tier].get(h.id)) is None or last.hole != h)
        )

    def _remember(self, news: Iterable[HoleNews]) -> list[HoleNews]:
        out = list(news)
        for n in out:
            self._told[n.tier][n.hole.id] = Told(n.hole)
        return out


def _changed_by(now: float, was: float, step: float) -> bool:
    """``now`` differs from ``was`` by more than ``step`` (NaN: unknown; known vs unknown
    is a change)."""
    if math.isnan(now) or math.isnan(was):
        return math.isnan(now) != math.isnan(was)
    return abs(now - was) > step
