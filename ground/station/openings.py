"""Several vehicles, one picture: the station's holes, one per opening.

Each hole report names its vehicle (its MAVLink system id). A vehicle's hole is one of the
station's holes when it lies at the same opening as a hole another vehicle reported: the
rule of ``holescan campaign`` (:func:`geotag.carry_ids`: nearest first, each hole used
once, within the tracker's gate of position, uncertainties and size), never with another
hole of the same vehicle (its own tracker already told them apart). The station's ids:

* the first vehicle that reports a hole (``primary_sysid``, kept in the state file)
  keeps its own ids: with one drone the station's ids are the vehicle's;
* a hole first reported by vehicle ``N`` (not the first) is
  ``N * VEHICLE_ID_BLOCK + its own id`` (vehicle 2's hole 3 is hole 2000003);
* a hole another vehicle reports later keeps its id; ``vehicles`` lists each
  vehicle's own id of it, and when each first and last reported it;
* a hole first known by its STATUSTEXT alone (no size, no uncertainty: the gate is
  the tracker's 0.5 m) that its card then places at another vehicle's hole is folded
  into the earlier of the two (its id leaves every output; the operator's mark of it
  is kept by the other).

A hole's facts: position, altitude and uncertainty of the vehicle whose estimate is
the most certain (smallest sigma; ties: the latest); the highest score and p_hole;
``announced`` when any vehicle announced it; sightings summed over the vehicles.
"""

from __future__ import annotations

import logging

from holescan.geotag import carry_ids
from holescan.ground.station.records import GroundHole, HoleSource
from holescan.link import LinkValueError

__all__ = ["MAX_HOLES", "VEHICLE_ID_BLOCK", "Openings"]

_log = logging.getLogger(__name__)

MAX_HOLES = 10_000
"""Holes one station keeps (a flight finds tens; a flood of forged ids stops here)."""
VEHICLE_ID_BLOCK = 1_000_000
"""A hole first reported by a vehicle other than the station's first is numbered
``sysid * VEHICLE_ID_BLOCK + its own id``."""


class Openings:
    """The station's holes by id, and which station hole each vehicle's own id is.

    Not thread-safe: the station calls it under its lock. ``max_holes`` bounds the holes
    kept (a flood of forged ids cannot exhaust memory or bury a genuine hole).
    """

    def __init__(self, max_holes: int = MAX_HOLES) -> None:
        self.holes: dict[int, GroundHole] = {}
        self.primary_sysid: int | None = None
        self.max_holes = max_holes
        self._ids: dict[tuple[int, int], int] = {}
        # station ids of the holes with a vehicle's part, and of each vehicle's holes: the
        # candidates of :meth:`same_opening` by set difference (a flood of one vehicle's
        # holes must not cost a Python loop over every hole kept per packet)
        self._parted: set[int] = set()
        self._of: dict[int, set[int]] = {}

    def _part(self, sysid: int, own: int, hid: int) -> None:
        """Vehicle ``sysid``'s hole ``own`` is station hole ``hid``."""
        self._ids[(sysid, own)] = hid
        self._parted.add(hid)
        self._of.setdefault(sysid, set()).add(hid)

    def keep(self, h: GroundHole) -> None:
        """Keep a hole as it is (one of the state file, checked), with its vehicles' ids."""
        self.holes[h.id] = h
        for v in h.vehicles:
            self._part(v.sysid, v.hole_id, h.id)

    def sysid(self, sysid: int | None) -> int:
        """The vehicle a report names (None: the station's first); the first vehicle that
        reports becomes the station's first."""
        if sysid is None:
            sysid = self.primary_sysid if self.primary_sysid is not None else 1
        if self.primary_sysid is None:
            self.primary_sysid = sysid
        return sysid

    def station_id(self, sysid: int, own: int) -> int:
        """The station id a new hole of vehicle ``sysid`` (its id ``own``) takes (raises
        :class:`link.LinkValueError` when a second vehicle's id is too large to number).

        >>> o = Openings()
        >>> o.primary_sysid = 1
        >>> o.station_id(1, 7), o.station_id(2, 3)
        (7, 2000003)
        """
        if sysid == self.primary_sysid:
            return own
        if own >= VEHICLE_ID_BLOCK:
            raise LinkValueError(
                f"vehicle {sysid}'s hole id {own}: a second vehicle's ids must be below "
                f"{VEHICLE_ID_BLOCK}"
            )
        return sysid * VEHICLE_ID_BLOCK + own

    def same_opening(self, src: HoleSource, exclude: int | None) -> int | None:
        """The station hole (not ``exclude``, none with a part of ``src``'s vehicle) at
        ``src``'s opening by the campaign's rule, or None."""
        ids = self._parted - self._of.get(src.sysid, set()) - {exclude}
        others = [h for hid, h in self.holes.items() if hid in ids] if ids else []
        if not others:
            return None
        # each station hole by its most certain vehicle's estimate (the one it shows)
        ref = [_best(h.vehicles).as_hole(h.id) for h in others]
        m = carry_ids(ref, [src.as_hole(0)])
        hid = m.ids.get(0)
        return hid if hid is not None and hid in m.from_reference else None

    def source(
        self, sysid: int | None, own: int, lat: float, lon: float, now: int
    ) -> tuple[GroundHole, HoleSource, bool]:
        """The station hole and vehicle part for vehicle ``sysid``'s hole ``own`` (made
        when new: matched to another vehicle's hole or a new station hole), and whether
        the part is new. Raises :class:`link.LinkValueError`: no room, or an id that
        cannot be given."""
        sysid = self.sysid(sysid)
        hid = self._ids.get((sysid, own))
        if hid is not None and hid in self.holes:
            h = self.holes[hid]
            src = next(v for v in h.vehicles if v.sysid == sysid)
            src.t_last_unix_ns = now
            return h, src, False
        src = HoleSource(sysid, own, lat, lon, t_first_unix_ns=now, t_last_unix_ns=now)
        match = self.same_opening(src, None)
        if match is not None:
            h = self.holes[match]
            h.vehicles.append(src)
            self._part(sysid, own, h.id)
            return h, src, True
        hid = self.station_id(sysid, own)
        h_old = self.holes.get(hid)
        if h_old is not None and h_old.vehicles:  # another vehicle's hole has that id
            raise LinkValueError(f"vehicle {sysid}'s hole {own}: id {hid} is taken")
        if h_old is None and len(self.holes) >= self.max_holes:
            raise LinkValueError(f"hole {hid}: {self.max_holes} holes kept already")
        if h_old is None:  # a hole known before vehicles were told apart keeps its facts
            h_old = GroundHole(hid, lat, lon, t_first_unix_ns=now)
            self.holes[hid] = h_old
        else:  # a hole of a state file older than this: its facts are this vehicle's
            src = HoleSource(
                sysid, own, h_old.lat_deg, h_old.lon_deg, h_old.score, h_old.alt_m,
                h_old.sigma_h_m, h_old.major_m, h_old.minor_m, h_old.p_hole,
                h_old.sightings, h_old.vehicle_tier, h_old.card_rev, h_old.seq,
                h_old.t_first_unix_ns or now, now,
            )  # fmt: skip
        h_old.vehicles.append(src)
        self._part(sysid, own, hid)
        return h_old, src, True

    def fold(
        self, h: GroundHole, moved: HoleSource, now: int
    ) -> tuple[GroundHole, GroundHole | None]:
        """Set ``h``'s facts from its vehicles' (see the module docstring), after ``moved``
        told new ones; fold it into another vehicle's hole at the same opening when it has
        only this one vehicle. Returns the hole that remains and the one folded into it
        (None: none; its picture, if any, is the caller's to move)."""
        gone = None
        if len(h.vehicles) == 1 and h.mark == "new":
            other = self.same_opening(moved, h.id)
            if other is not None:
                a, b = sorted((h, self.holes[other]), key=lambda x: (x.t_first_unix_ns, x.id))
                self._absorb(a, b)
                h, gone = a, b
        best = _best(h.vehicles)
        h.lat_deg, h.lon_deg, h.alt_m, h.sigma_h_m = (
            best.lat_deg, best.lon_deg, best.alt_m, best.sigma_h_m,
        )  # fmt: skip
        sized = [v for v in h.vehicles if v.major_m is not None]
        if sized:
            s = _best(sized)
            h.major_m, h.minor_m = s.major_m, s.minor_m
        scores = [v.score for v in h.vehicles if v.score is not None]
        h.score = max(scores) if scores else None
        known = [v.p_hole for v in h.vehicles if v.p_hole is not None]
        h.p_hole = max(known) if known else None
        h.vehicle_tier = "announced" if any(v.tier == "announced" for v in h.vehicles) else "review"
        h.sightings = sum(v.sightings for v in h.vehicles)
        h.card_rev = sum(v.card_rev for v in h.vehicles)
        h.t_updated_unix_ns = now
        return h, gone

    def _absorb(self, keep: GroundHole, gone: GroundHole) -> None:
        """Fold hole ``gone`` into ``keep``: its vehicles and its mark."""
        _log.info("hole %d is at hole %d's opening (another vehicle's): one hole", gone.id,
                  keep.id)  # fmt: skip
        keep.vehicles += gone.vehicles
        keep.vehicles.sort(key=lambda v: v.t_first_unix_ns)
        for v in gone.vehicles:
            self._of[v.sysid].discard(gone.id)
            self._part(v.sysid, v.hole_id, keep.id)
        self._parted.discard(gone.id)
        if keep.mark == "new":
            keep.mark = gone.mark
        keep.t_first_unix_ns = min(keep.t_first_unix_ns, gone.t_first_unix_ns)
        del self.holes[gone.id]


def _best(sources: list[HoleSource]) -> HoleSource:
    """The vehicle part with the most certain position (smallest sigma; ties: latest)."""
    return min(
        sources,
        key=lambda v: (
            v.sigma_h_m if v.sigma_h_m is not None else float("inf"),
            -v.t_last_unix_ns,
        ),
    )
