"""The station's records: a hole as the ground knows it (:class:`GroundHole`), one
vehicle's part in it (:class:`HoleSource`), a vehicle at one instant (:class:`TrackPoint`),
and the hole STATUSTEXT they start from (:func:`parse_hole_statustext`).

Each record reads itself from the state file (:mod:`.statefile`) and checks every value as
one from the link would be (:mod:`link._values`: finite, in range, ids in the protocol's
range, text XML can hold). A file of an older station (``holescan-ground-1``: ``lat`` /
``lon`` / ``alt`` / ``sigma_m``, times in float seconds) is read too.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from holescan.geotag import HOLE_TIERS, VEHICLE_TIERS, Hole, HoleTier, VehicleTier
from holescan.link import (
    LinkValueError,
    check_hole_id,
    link_float,
    link_int,
    link_lat_lon,
    link_yaw,
    optional_float,
    read_hole_text,
    xml_text,
)

__all__ = [
    "ALT_M",
    "FORMAT",
    "FORMAT_1",
    "MARKS",
    "SIZE_M",
    "TIERS",
    "T_NS_MAX",
    "VEHICLE_TIERS",
    "GroundHole",
    "HoleSource",
    "Mark",
    "Tier",
    "TrackPoint",
    "VehicleTier",
    "ns_of_seconds",
    "parse_hole_statustext",
]

Mark = Literal["new", "confirmed", "rejected", "visited"]
MARKS: tuple[Mark, ...] = ("new", "confirmed", "rejected", "visited")
Tier = HoleTier
"""What a hole is for the crews (:data:`geotag.HoleTier`, defined once there)."""
TIERS = HOLE_TIERS
FORMAT = "holescan-ground-2"
"""The state file's ``format``; ``holescan-ground-1`` files (older stations) are read too."""
FORMAT_1 = "holescan-ground-1"
"""The format of an older station's file (times in float seconds, short keys)."""
ALT_M = (-1000.0, 10_000.0)
"""Altitudes and heights a record may hold, m."""
SIZE_M = (0.0, 1000.0)
"""Sizes and uncertainties a record may hold, m."""
T_NS_MAX = 2**63 - 1
"""The latest time (and largest count) a record may hold."""
# keys of a holescan-ground-1 hole -> this version's
_OLD_KEYS = {"lat": "lat_deg", "lon": "lon_deg", "alt": "alt_m", "sigma_m": "sigma_h_m"}
_OLD_SECONDS = {"first_unix": "t_first_unix_ns", "updated_unix": "t_updated_unix_ns"}


def parse_hole_statustext(text: str) -> tuple[int, float, float, float] | None:
    """``HOLE <id> p<p_hole> <lat> <lon>`` (an announced hole) or ``REVIEW <id> ...`` (a
    hole for review) -> (id, confidence, lat_deg, lon_deg); None for other texts. The
    confidence is the hole-level p_hole, or the best frame's detector score from a vehicle
    that sent the old form (``HOLE <id> <score> ...``). The link's one codec
    (:func:`link.read_hole_text`, which says which of the two it was and the tier).

    >>> parse_hole_statustext("HOLE 3 p0.97 43.6533100 -79.3831200")
    (3, 0.97, 43.65331, -79.38312)
    >>> parse_hole_statustext("REVIEW 4 0.30 43.6533100 -79.3831200")
    (4, 0.3, 43.65331, -79.38312)
    >>> parse_hole_statustext("PreArm: GPS") is None
    True
    >>> parse_hole_statustext("HOLE 1000000000 p0.88 43.6533100 -79.3831200") is None
    True
    """
    said = read_hole_text(text)
    if said is None:
        return None
    value = said.p_hole if said.p_hole is not None else said.score
    assert value is not None  # the codec sets one of the two
    return (said.hole_id, value, said.lat_deg, said.lon_deg)


@dataclass
class HoleSource:
    """One vehicle's part in a hole of the station: who, the id it gives the hole, and
    what it said of it last.

    sysid : the vehicle's MAVLink system id. hole_id : its own id of the hole. lat_deg,
    lon_deg, alt_m, sigma_h_m, major_m, minor_m, score, p_hole, sightings, tier : its
    latest facts (STATUSTEXT and card). card_rev : its newest card's revision. seq : the
    hole's waypoint number in its hole mission (None: not in it). t_first_unix_ns,
    t_last_unix_ns : when the station first and last heard of the hole from it.
    """

    sysid: int
    hole_id: int
    lat_deg: float
    lon_deg: float
    score: float | None = None
    alt_m: float | None = None
    sigma_h_m: float | None = None
    major_m: float | None = None
    minor_m: float | None = None
    p_hole: float | None = None
    sightings: int = 0
    tier: VehicleTier = "announced"
    card_rev: int = 0
    seq: int | None = None
    t_first_unix_ns: int = 0
    t_last_unix_ns: int = 0

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> HoleSource:
        """One of a state file's, every value checked as from the link (raises
        :class:`link.LinkValueError`, ``TypeError``)."""
        names = {f.name for f in dataclasses.fields(cls)}
        v = cls(**{k: d[k] for k in d if k in names})
        v.sysid = link_int(v.sysid, 1, 255, "system id")
        v.hole_id = check_hole_id(v.hole_id)
        v.lat_deg, v.lon_deg = link_lat_lon(v.lat_deg, v.lon_deg)
        v.score = optional_float(v.score, 0.0, 1.0, "score")
        v.alt_m = optional_float(v.alt_m, *ALT_M, "alt_m")
        for name in ("sigma_h_m", "major_m", "minor_m"):
            setattr(v, name, optional_float(getattr(v, name), *SIZE_M, name))
        v.p_hole = optional_float(v.p_hole, 0.0, 1.0, "p_hole")
        v.sightings = link_int(v.sightings, 0, 2**31 - 1, "sightings")
        v.card_rev = link_int(v.card_rev, 0, 2**31 - 1, "card_rev")
        v.seq = None if v.seq is None else link_int(v.seq, 0, 65535, "seq")
        v.t_first_unix_ns = link_int(v.t_first_unix_ns, 0, T_NS_MAX, "time")
        v.t_last_unix_ns = link_int(v.t_last_unix_ns, 0, T_NS_MAX, "time")
        if v.tier not in VEHICLE_TIERS:
            v.tier = "announced"
        return v

    def to_json(self) -> dict[str, Any]:
        """The part's fields (a JSON-able dict, as :meth:`from_json` reads)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def as_hole(self, station_id: int) -> Hole:
        """This vehicle's view of the hole as the tracker's record (for its gate)."""
        nan = float("nan")
        return Hole(
            station_id,
            self.lat_deg,
            self.lon_deg,
            nan if self.alt_m is None else self.alt_m,
            nan if self.sigma_h_m is None else self.sigma_h_m,
            nan if self.score is None else self.score,
            self.sightings,
            self.t_first_unix_ns,
            self.t_last_unix_ns,
            None,
            (0, 0, 0, 0),
            nan if self.major_m is None else self.major_m,
            nan if self.minor_m is None else self.minor_m,
        )


@dataclass
class GroundHole:
    """One hole as the ground knows it.

    id : the vehicle's hole id. lat_deg, lon_deg : WGS84; alt_m : m MSL (None: unknown).
    sigma_h_m : 1-sigma horizontal uncertainty, m (None until the card came).
    score : the best frame's detector score (None until a card or an old-form STATUSTEXT
    told it). sightings, major_m, minor_m : the detector's. why : its explanation.
    card_rev : revision of the newest card (0: no card yet). has_picture : a JPEG is kept.
    mark : the operator's (``new`` until set). vehicle_tier : what the vehicle said of it
    (``announced``: sure enough to send to the crews; ``review``: plausible, for an
    operator to confirm or reject; files older than the tiers read as ``announced``).
    seq : waypoint number in the downloaded
    hole mission (None: not in it). t_first_unix_ns, t_updated_unix_ns : when the ground
    first heard of it / last changed it (Unix clock, ns).
    The vehicle says the tier by STATUSTEXT ``HOLE`` / ``REVIEW`` and by its card's
    ``"tier"``. p_hole : the vehicle's hole-level confidence (its card's ``p``; None: not
    told).
    vehicles : each vehicle's part (:class:`HoleSource`), in the order they first reported
    it (empty for holes of a state file older than this: one vehicle, its ids).
    """

    id: int
    lat_deg: float
    lon_deg: float
    score: float | None = None
    alt_m: float | None = None
    sigma_h_m: float | None = None
    sightings: int = 0
    major_m: float | None = None
    minor_m: float | None = None
    why: str = ""
    card_rev: int = 0
    has_picture: bool = False
    mark: Mark = "new"
    seq: int | None = None
    t_first_unix_ns: int = 0
    t_updated_unix_ns: int = 0
    vehicle_tier: VehicleTier = "announced"
    p_hole: float | None = None
    vehicles: list[HoleSource] = field(default_factory=list)

    @property
    def tier(self) -> Tier:
        """What the hole is for the crews: the operator's mark overrides the vehicle's tier.

        ``rejected`` -> rejected (kept, shown as rejected, withdrawn from TAK);
        ``confirmed`` and ``visited`` -> confirmed (a crew that visited a hole stood at it:
        it is a real place that was checked, and it stays on every map); ``new`` -> the
        vehicle's tier (``announced`` or ``review``).
        """
        if self.mark == "rejected":  # the rule marks.tier_with_mark states for reprocessing
            return "rejected"
        if self.mark in ("confirmed", "visited"):
            return "confirmed"
        return self.vehicle_tier

    @property
    def sysids(self) -> list[int]:
        """The vehicles that reported the hole (system ids), in the order they first did
        (empty: a hole of a state file older than vehicles told apart)."""
        return [v.sysid for v in sorted(self.vehicles, key=lambda v: v.t_first_unix_ns)]

    @property
    def first_last(self) -> tuple[int, int] | None:
        """The vehicle that reported the hole first and the one that reported it last
        (None: not known).

        >>> a = HoleSource(2, 5, 43.6, -79.4, t_first_unix_ns=1, t_last_unix_ns=9)
        >>> b = HoleSource(1, 5, 43.6, -79.4, t_first_unix_ns=3, t_last_unix_ns=4)
        >>> h = GroundHole(1, 43.6, -79.4, vehicles=[a, b])
        >>> h.sysids, h.first_last
        ([2, 1], (2, 2))
        """
        if not self.vehicles:
            return None
        first = min(self.vehicles, key=lambda v: v.t_first_unix_ns)
        last = max(reversed(self.vehicles), key=lambda v: v.t_last_unix_ns)
        return first.sysid, last.sysid

    def to_json(self) -> dict[str, Any]:
        """The hole's fields and its :attr:`tier` (a JSON-able dict)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        # what dataclasses.asdict gives, a field at a time (asdict's deep copy of every
        # value costs ~1 ms a hole: the state file of a few thousand holes took seconds)
        d["vehicles"] = [v.to_json() for v in self.vehicles]
        d["tier"] = self.tier
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> GroundHole:
        """A hole of the state file; also one of a ``holescan-ground-1`` file (``lat``,
        ``lon``, ``alt``, ``sigma_m``, ``first_unix`` / ``updated_unix`` in seconds)."""
        d = dict(d)
        for old, new in _OLD_KEYS.items():
            if old in d:
                d.setdefault(new, d.pop(old))
        for old, new in _OLD_SECONDS.items():
            if old in d:
                d.setdefault(new, ns_of_seconds(d.pop(old)))
        names = {f.name for f in dataclasses.fields(cls)} - {"vehicles"}
        h = cls(**{k: v for k, v in d.items() if k in names})
        h.vehicles = list(d.get("vehicles") or [])
        h.t_first_unix_ns, h.t_updated_unix_ns = int(h.t_first_unix_ns), int(h.t_updated_unix_ns)
        if h.mark not in MARKS:
            h.mark = "new"
        if h.vehicle_tier not in VEHICLE_TIERS:
            h.vehicle_tier = "announced"
        return h

    def checked(self) -> list[str]:
        """Check every value in place as one from the link would be
        (:mod:`link._values`): raise :class:`link.LinkValueError` when the id,
        position or score is bad (the hole cannot be kept); a bad optional fact is set to
        unknown and named in the list returned."""
        self.id = check_hole_id(self.id)
        self.lat_deg, self.lon_deg = link_lat_lon(self.lat_deg, self.lon_deg)
        forgotten = []
        optional = {
            "score": (0.0, 1.0),
            "alt_m": ALT_M,
            "sigma_h_m": SIZE_M,
            "major_m": SIZE_M,
            "minor_m": SIZE_M,
            "p_hole": (0.0, 1.0),
        }
        for name, (lo, hi) in optional.items():
            try:
                setattr(self, name, optional_float(getattr(self, name), lo, hi, name))
            except LinkValueError:
                setattr(self, name, None)
                forgotten.append(name)
        ints = {"sightings": 0, "card_rev": 0, "t_first_unix_ns": 0, "t_updated_unix_ns": 0}
        for name, default in ints.items():
            try:
                setattr(self, name, link_int(getattr(self, name), 0, T_NS_MAX, name))
            except LinkValueError:
                setattr(self, name, default)
                forgotten.append(name)
        if self.seq is not None:
            try:
                self.seq = link_int(self.seq, 0, 65535, "seq")
            except LinkValueError:
                self.seq = None
                forgotten.append("seq")
        self.has_picture = self.has_picture is True
        self.why = xml_text(self.why if isinstance(self.why, str) else "", 500)
        sources = []
        for v in self.vehicles:
            try:
                sources.append(v if isinstance(v, HoleSource) else HoleSource.from_json(v))
            except (LinkValueError, TypeError, AttributeError):
                forgotten.append("a vehicle's part")
        self.vehicles = sources
        return forgotten


@dataclass(frozen=True)
class TrackPoint:
    """A vehicle at one instant: Unix clock ns, WGS84 degrees, m above home, heading rad,
    and which vehicle (its MAVLink system id; 0: not known, a state file older than this)."""

    t_unix_ns: int
    lat_deg: float
    lon_deg: float
    rel_alt_m: float
    yaw: float
    sysid: int = 0

    @classmethod
    def from_json(cls, row: list[Any], file_format: str = FORMAT) -> TrackPoint:
        """A track row of the state file (``holescan-ground-1``: time in float seconds;
        rows of five columns have no system id)."""
        t, lat, lon, rel_alt, yaw, *rest = row
        t_ns = ns_of_seconds(t) if file_format == FORMAT_1 else int(t)
        sysid = link_int(rest[0], 0, 255, "system id") if rest else 0
        return cls(t_ns, float(lat), float(lon), float(rel_alt), float(yaw), sysid).checked()

    def checked(self) -> TrackPoint:
        """This point when every value is one the link may give (else
        :class:`missions.LinkValueError`): time, position on the Earth, height, yaw."""
        link_int(self.t_unix_ns, 0, T_NS_MAX, "time")
        link_lat_lon(self.lat_deg, self.lon_deg)
        link_float(self.rel_alt_m, *ALT_M, "height above home")
        link_yaw(self.yaw)
        link_int(self.sysid, 0, 255, "system id")
        return self


def ns_of_seconds(t_s: Any) -> int:
    """A ``holescan-ground-1`` time (float seconds of ``time.time()``) in ns: to the
    microsecond, all a float of today's Unix seconds holds.

    >>> ns_of_seconds(1_700_000_000.25)
    1700000000250000000
    """
    return round(float(t_s) * 1_000_000) * 1000
