"""Holes merged across the flights of an operation: one id per hole, sightings per flight.

Every frame merged in a flight (:class:`ground.reprocessing.merge.FlightMerger`) also hands its
sightings, geotagged by that flight's :class:`geotag.HolePipeline`, to one campaign-wide
:class:`geotag.HoleTracker`: the same gate as in flight (position, each sighting's
uncertainty, the GPS error that drifts between sorties), so a hole seen on two sorties or
by two vehicles is one hole. Sightings are put on the Unix clock first (each vehicle's
autopilot boot clock is its own), and flights are merged in the order they started.

Ids: the campaign's holes take the ids of the first flight's (its reprocessed holes carry
the vehicle's ids; :func:`geotag.carry_ids`), and holes it did not see ids above every id
that flight used; each hole also lists the id each flight knows it by (``flights``).

Operators' marks (``--station``): each flight's marks by its own ids
(:meth:`ground.reprocessing.ReprocessOptions.marks_for`) reach the campaign's hole through
the id that flight knows it by (:func:`campaign_marks`); marks of several flights that
disagree give the most affirmative (:func:`ground.station.marks.strongest_mark`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from holescan.geotag import (
    FrameHoles,
    Hole,
    HoleTracker,
    IdMap,
    LocalFrame,
    VehiclePose,
    carry_ids,
)
from holescan.ground.reprocessing.merge import box_of, read_views
from holescan.ground.reprocessing.plan import PartitionTask
from holescan.ground.reprocessing.task import Box, FrameResult, View
from holescan.ground.station.marks import strongest_mark

__all__ = [
    "CampaignHole",
    "CampaignMerge",
    "FlightSightings",
    "campaign_marks",
    "campaign_summary",
    "track_coverage",
]


@dataclasses.dataclass(frozen=True)
class FlightSightings:
    """One flight's part in a campaign hole: frames it was seen in, first and last seen
    (Unix ns)."""

    flight: str
    sightings: int
    first_seen_unix_ns: int
    last_seen_unix_ns: int
    hole_id: int | None = None
    mark: str | None = None


@dataclasses.dataclass(frozen=True)
class CampaignHole:
    """A hole of the campaign. ``hole`` is the fused hole (its ``t_first_boot_ns`` and
    ``t_last_boot_ns`` are Unix ns here); ``flights`` in the order they first saw it;
    ``mark``: the operators' (None: none; each flight's in ``flights``)."""

    hole: Hole
    flights: tuple[FlightSightings, ...]
    tier: str = "announced"
    mark: str | None = None

    @property
    def id(self) -> int:
        return self.hole.id

    def summary(self) -> dict[str, Any]:
        h = self.hole
        return {
            "id": h.id,
            "tier": self.tier,
            "mark": self.mark,
            "p_hole": h.p_hole if math.isfinite(h.p_hole) else None,
            "lat_deg": h.lat_deg,
            "lon_deg": h.lon_deg,
            "alt_m": h.alt_m,
            "sigma_h_m": h.sigma_h_m,
            "score": h.score,
            "frames": h.sightings,
            "views": h.views,
            "major_m": h.major_m,
            "minor_m": h.minor_m,
            "first_seen_unix_ns": h.t_first_boot_ns,
            "last_seen_unix_ns": h.t_last_boot_ns,
            "flights": [dataclasses.asdict(f) for f in self.flights],
        }


class CampaignMerge:
    """Feed :meth:`on_frame` every merged frame of every flight (flights in start order)."""

    def __init__(self) -> None:
        self.tracker = HoleTracker()
        self.best: dict[int, tuple[PartitionTask, int, Box]] = {}
        self._seen: dict[int, dict[str, list[int]]] = {}  # id -> flight -> [n, first, last]
        self.id_map: IdMap | None = None
        self._flight_ids: dict[str, dict[int, int]] = {}  # flight -> own id -> its id

    def on_frame(self, flight: str, fr: FrameResult, step: FrameHoles, task: PartitionTask) -> None:
        if not step.sightings:
            return
        t = fr.t_unix_ns
        sightings = [dataclasses.replace(s, t_boot_ns=t) for s in step.sightings]
        # one sighting per hole and frame at most; each flight's GPS error is its own
        for h in self.tracker.update(sightings, source=flight):
            stats = self._seen.setdefault(h.id, {}).setdefault(flight, [0, t, t])
            stats[0] += 1
            stats[1], stats[2] = min(stats[1], t), max(stats[2], t)
            if h.best_frame_index == fr.index:
                self.best[h.id] = (task, fr.index, box_of(h.best_box))

    def views(self, ids: set[int]) -> dict[int, View]:
        """The best views of holes ``ids`` (carried ids), read again from the logs."""
        back = {v: k for k, v in self.id_map.ids.items()} if self.id_map else {i: i for i in ids}
        own = {i: back[i] for i in ids if i in back and back[i] in self.best}
        got = read_views({b: self.best[b] for b in own.values()})
        return {i: got[b] for i, b in own.items() if b in got}

    def carry_ids(self, flights: Sequence[tuple[str, Sequence[Hole], int]]) -> None:
        """Give the campaign's holes the first flight's ids (see the module docstring).

        flights : (name, reprocessed holes with the vehicle's ids, highest id it used), in
        start order."""
        holes = self.tracker.holes()
        if flights:
            _, ref, top = flights[0]
            self.id_map = carry_ids(ref, holes, reference_max_id=top)
        for name, fholes, top in flights:
            m = carry_ids(fholes, holes, reference_max_id=top)
            self._flight_ids[name] = {k: v for k, v in m.ids.items() if v in m.from_reference}

    def _seen_by_hole(self) -> dict[int, dict[str, list[int]]]:
        """Each flight's sightings of each hole, with those counted under an id the tracker
        later retired (two holes found to be one opening) added to the hole it joined."""
        merged = self.tracker.merged()
        out: dict[int, dict[str, list[int]]] = {}
        for hid, per in self._seen.items():
            into = out.setdefault(merged.get(hid, hid), {})
            for name, (n, first, last) in per.items():
                cur = into.setdefault(name, [0, first, last])
                cur[0] += n
                cur[1], cur[2] = min(cur[1], first), max(cur[2], last)
        return out

    def holes(self, min_sightings: int = 1) -> list[CampaignHole]:
        """The campaign's holes seen at least ``min_sightings`` times, by (carried) id."""
        out = []
        seen = self._seen_by_hole()
        for h in self.tracker.holes():
            if h.sightings < min_sightings:
                continue
            per = seen.get(h.id, {})
            flights = sorted(
                (
                    FlightSightings(name, n, first, last, self._flight_ids.get(name, {}).get(h.id))
                    for name, (n, first, last) in per.items()
                ),
                key=lambda f: f.first_seen_unix_ns,
            )
            carried = h if self.id_map is None else dataclasses.replace(h, id=self.id_map.ids[h.id])
            out.append(CampaignHole(carried, tuple(flights)))
        return sorted(out, key=lambda c: c.id)


def campaign_marks(
    holes: Sequence[CampaignHole], flight_marks: Mapping[str, Mapping[int, str]]
) -> list[CampaignHole]:
    """``holes`` with the operators' marks: each flight's (``flight_marks``: flight name ->
    its hole id -> mark) through the id that flight knows the hole by; a hole marked in
    several flights takes :func:`~ground.station.marks.strongest_mark`.

    >>> f1 = FlightSightings("f1", 5, 0, 1, hole_id=3)
    >>> f2 = FlightSightings("f2", 4, 2, 3, hole_id=1)
    >>> h = Hole(7, 43.6, -79.4, 100.0, 0.3, 0.8, 9, 0, 3, 1, (0, 0, 9, 9), 1.0, 0.6)
    >>> (c,) = campaign_marks([CampaignHole(h, (f1, f2))], {"f1": {3: "rejected"},
    ...                                                     "f2": {1: "confirmed"}})
    >>> c.mark, [f.mark for f in c.flights]
    ('confirmed', ['rejected', 'confirmed'])
    """
    out = []
    for c in holes:
        flights = tuple(
            dataclasses.replace(
                f, mark=None if f.hole_id is None else flight_marks.get(f.flight, {}).get(f.hole_id)
            )
            for f in c.flights
        )
        mark = strongest_mark(f.mark for f in flights if f.mark is not None)
        out.append(dataclasses.replace(c, flights=flights, mark=mark))
    return out


def track_coverage(track: Sequence[VehiclePose]) -> tuple[float, float]:
    """(length_m, duration_s) of a flight's track (horizontal, poses in time order).

    Examples
    --------
    >>> track_coverage([])
    (0.0, 0.0)
    """
    pts = [p for p in track if math.isfinite(p.lat_deg) and math.isfinite(p.lon_deg)]
    if len(pts) < 2:
        return 0.0, 0.0
    frame = LocalFrame(pts[0].lat_deg, pts[0].lon_deg)
    e, n = frame.to_en([p.lat_deg for p in pts], [p.lon_deg for p in pts])
    length = float(np.sum(np.hypot(np.diff(e), np.diff(n))))
    return length, (pts[-1].t_boot_ns - pts[0].t_boot_ns) * 1e-9


def campaign_summary(
    holes: Sequence[CampaignHole], flights: Mapping[str, Sequence[VehiclePose]]
) -> dict[str, Any]:
    """The ``holes`` part of a campaign's ``summary.json``, and per flight its coverage
    (track length and duration), how many holes it saw and how many of those another flight
    saw too."""
    per_flight = {}
    for name, track in flights.items():
        length, duration = track_coverage(track)
        per_flight[name] = {
            "track_length_m": round(length, 1),
            "track_duration_s": round(duration, 1),
            "holes_seen": sum(any(f.flight == name for f in h.flights) for h in holes),
            "also_seen_by_another_flight": sum(
                any(f.flight == name for f in h.flights) and len(h.flights) > 1 for h in holes
            ),
        }
    return {
        "holes": [h.summary() for h in holes],
        "holes_seen_by_several_flights": sum(len(h.flights) > 1 for h in holes),
        "per_flight": per_flight,
    }
