"""The ground station's memory: holes, their pictures, the operator's marks, the track.

Everything ``holescan ground`` learns is kept here and written to ``DIR/station.json``
after every change (through the output-path rule, :func:`outputs.atomic_output`: written
to ``.station.part.json``, flushed, fsynced, renamed: a crash or a power cut leaves the
previous or the new file, never half of one), pictures to ``DIR/cards/hole-ID.jpg`` the
same way. Writes are batched under a flood: a few at once, then at most one every
``save_every_s`` (the last change always reaches the file; :meth:`StationState.flush`
at the end); an operator's mark is written at once.

Every value from the link is checked before it is kept (:mod:`link._values`:
finite, in range, ids in the protocol's range, text XML can hold); a refused one is
counted in ``rejected`` and logged, and nothing of its packet is kept. At most
``max_holes`` holes are kept (a flood of forged ids cannot exhaust memory or bury a
genuine hole: the genuine one sent later still has room). A state file is checked the same
way when it is read back: a hole whose position is not a number on the Earth is left out,
a bad optional fact is forgotten, each with one log line, and the file as it was is kept
beside as ``station.rejected-<time>.json``.

A restart reads it back, so a link drop, a restart or a second sortie loses nothing, and
holes keep the vehicle's ids. A state file of an older station (``holescan-ground-1``:
``lat``/``lon``/``alt``/``sigma_m``, times in float seconds) is read too, and written back
in the current format with the next change.

A hole is known from any of: the vehicle's STATUSTEXT ``HOLE <id> <score> <lat> <lon>``
(fast, 50 bytes), its card (picture + facts, :func:`missions.read_card`), the hole mission
downloaded from component 191. Later facts update earlier ones; the operator's mark
(``new`` / ``confirmed`` / ``rejected`` / ``visited``) is the ground's own and never
overwritten by the vehicle. ``version`` counts changes (the live page and the files
follow it).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from holescan.errors import InputError
from holescan.geotag import (
    HOLE_TIERS,
    VEHICLE_TIERS,
    Hole,
    HoleTier,
    LocalFrame,
    VehicleTier,
    carry_ids,
    nearest_pairs,
)
from holescan.ground.errors import StationFileError
from holescan.ground.station.vehicles import VehicleStatus
from holescan.link import (
    LinkValueError,
    card_values,
    check_hole_id,
    link_float,
    link_int,
    link_lat_lon,
    link_yaw,
    optional_float,
    read_hole_text,
    xml_text,
)
from holescan.missions import NO_PICTURE, card_picture, with_picture
from holescan.outputs import atomic_output

__all__ = [
    "FORMAT",
    "MARKS",
    "TIERS",
    "VEHICLE_ID_BLOCK",
    "VEHICLE_TIERS",
    "GroundHole",
    "HoleSource",
    "Mark",
    "StationState",
    "Tier",
    "TrackPoint",
    "VehicleTier",
    "parse_hole_statustext",
]

_log = logging.getLogger(__name__)

Mark = Literal["new", "confirmed", "rejected", "visited"]
MARKS: tuple[Mark, ...] = ("new", "confirmed", "rejected", "visited")
Tier = HoleTier
"""What a hole is for the crews (:data:`geotag.HoleTier`, defined once there)."""
TIERS = HOLE_TIERS
FORMAT = "holescan-ground-2"
"""The state file's ``format``; ``holescan-ground-1`` files (older stations) are read too."""
_FORMAT_1 = "holescan-ground-1"
_TRACK_MAX = 20_000
MAX_HOLES = 10_000
"""Holes one station keeps (a flight finds tens; a flood of forged ids stops here)."""
_ALT_M = (-1000.0, 10_000.0)
_SIZE_M = (0.0, 1000.0)
_T_NS_MAX = 2**63 - 1
_TRACK_SAVE_NS = 10 * 10**9
_NS_PER_S = 1_000_000_000
VEHICLE_ID_BLOCK = 1_000_000
"""A hole first reported by a vehicle other than the station's first is numbered
``sysid * VEHICLE_ID_BLOCK + its own id`` (see :class:`StationState`)."""
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
        v.alt_m = optional_float(v.alt_m, *_ALT_M, "alt_m")
        for name in ("sigma_h_m", "major_m", "minor_m"):
            setattr(v, name, optional_float(getattr(v, name), *_SIZE_M, name))
        v.p_hole = optional_float(v.p_hole, 0.0, 1.0, "p_hole")
        v.sightings = link_int(v.sightings, 0, 2**31 - 1, "sightings")
        v.card_rev = link_int(v.card_rev, 0, 2**31 - 1, "card_rev")
        v.seq = None if v.seq is None else link_int(v.seq, 0, 65535, "seq")
        v.t_first_unix_ns = link_int(v.t_first_unix_ns, 0, _T_NS_MAX, "time")
        v.t_last_unix_ns = link_int(v.t_last_unix_ns, 0, _T_NS_MAX, "time")
        if v.tier not in VEHICLE_TIERS:
            v.tier = "announced"
        return v

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

    def to_json(self) -> dict[str, Any]:
        """The hole's fields and its :attr:`tier` (a JSON-able dict)."""
        d = dataclasses.asdict(self)
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
                d.setdefault(new, _ns_of_seconds(d.pop(old)))
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
            "alt_m": _ALT_M,
            "sigma_h_m": _SIZE_M,
            "major_m": _SIZE_M,
            "minor_m": _SIZE_M,
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
                setattr(self, name, link_int(getattr(self, name), 0, _T_NS_MAX, name))
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
        t_ns = _ns_of_seconds(t) if file_format == _FORMAT_1 else int(t)
        sysid = link_int(rest[0], 0, 255, "system id") if rest else 0
        return cls(t_ns, float(lat), float(lon), float(rel_alt), float(yaw), sysid).checked()

    def checked(self) -> TrackPoint:
        """This point when every value is one the link may give (else
        :class:`missions.LinkValueError`): time, position on the Earth, height, yaw."""
        link_int(self.t_unix_ns, 0, _T_NS_MAX, "time")
        link_lat_lon(self.lat_deg, self.lon_deg)
        link_float(self.rel_alt_m, *_ALT_M, "height above home")
        link_yaw(self.yaw)
        link_int(self.sysid, 0, 255, "system id")
        return self


@dataclass
class StationState:
    """Holes, marks and tracks of one ground station, persisted in ``folder``.

    ``listeners`` are called (without the lock held) after every change with the new
    version; the web page's event stream and the file writers hang on them. ``clock`` is
    the Unix clock in ns (the holes' and track's times).

    Several vehicles, one picture. Each hole report names its vehicle (``sysid``; None:
    the station's first). A vehicle's hole is one of the station's holes when it lies at
    the same opening as a hole another vehicle reported: the rule of ``holescan campaign``
    (:func:`geotag.carry_ids`: nearest first, each hole used once, within the tracker's
    gate of position, uncertainties and size), never with another hole of the same
    vehicle (its own tracker already told them apart). The station's ids:

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
    ``announced`` when any vehicle announced it; sightings summed over the vehicles; the
    newest card's picture and "why".
    """

    folder: Path
    holes: dict[int, GroundHole] = field(default_factory=dict)
    track: list[TrackPoint] = field(default_factory=list)
    version: int = 0
    listeners: list[Callable[[int], None]] = field(default_factory=list)
    clock: Callable[[], int] = time.time_ns
    max_holes: int = MAX_HOLES
    save_every_s: float = 0.5
    save_burst: int = 5
    rejected: int = 0
    _lock: threading.RLock = field(default_factory=threading.RLock)
    _last_track_save_ns: int = 0
    _save_tokens: float = 5.0
    _save_t: float = field(default_factory=time.monotonic)
    _unsaved: bool = False
    _timer: threading.Timer | None = None
    primary_sysid: int | None = None
    vehicles: dict[int, VehicleStatus] = field(default_factory=dict)
    """The vehicles heard (live; :mod:`ground.station.vehicles`), by system id."""
    _ids: dict[tuple[int, int], int] = field(default_factory=dict)
    _last_point_ns: dict[int, int] = field(default_factory=dict)

    @property
    def path(self) -> Path:
        return self.folder / "station.json"

    def card_path(self, hole_id: int) -> Path:
        return self.folder / "cards" / f"hole-{hole_id}.jpg"

    @classmethod
    def open(cls, folder: Path) -> StationState:
        """The state kept in ``folder`` (created when new).

        Raises
        ------
        InputError : the folder cannot be created.
        StationFileError : its ``station.json`` is not a ground station file.
        """
        try:
            (folder / "cards").mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise InputError(f"cannot create {folder}: {err.strerror}") from err
        state = cls(folder)
        if state.path.exists():
            try:
                doc = json.loads(state.path.read_text())
                fmt = str(doc.get("format", _FORMAT_1))
                holes = [GroundHole.from_json(d) for d in doc["holes"]]
                rows = list(doc.get("track", []))
                state.version = link_int(doc.get("version", 0), 0, _T_NS_MAX, "version")
                primary = doc.get("primary_sysid")
                state.primary_sysid = None if primary is None else link_int(primary, 1, 255, "id")
            except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
                raise StationFileError(
                    f"{state.path} is not a holescan ground station file ({err}); move it away"
                ) from err
            state._resume(holes, rows, fmt)
            _log.info("resumed %d holes from %s", len(state.holes), state.path)
        return state

    def _resume(self, holes: list[GroundHole], rows: list[Any], fmt: str) -> None:
        """Keep what a state file holds that the link could have given (see the module
        docstring); the file as it was is copied aside when anything was left out."""
        problems = 0
        for h in holes:
            try:
                forgotten = h.checked()
            except LinkValueError as err:
                problems += 1
                _log.warning("%s: a hole left out (%s)", self.path, err)
                continue
            if forgotten:
                problems += 1
                _log.warning("%s: hole %d: %s unknown (not numbers in range)", self.path,
                             h.id, ", ".join(forgotten))  # fmt: skip
            self.holes[h.id] = h
            for v in h.vehicles:
                self._ids[(v.sysid, v.hole_id)] = h.id
        for row in rows:
            try:
                self.track.append(TrackPoint.from_json(row, fmt))
            except (LinkValueError, ValueError, TypeError, OverflowError):
                problems += 1
        if len(self.track) < len(rows):
            _log.warning("%s: %d track points left out", self.path, len(rows) - len(self.track))
        if problems:
            aside = self.folder / f"station.rejected-{time.time_ns()}.json"
            try:
                aside.write_bytes(self.path.read_bytes())
                _log.warning("%s kept as it was in %s", self.path.name, aside.name)
            except OSError as err:
                _log.warning("%s not copied aside: %s", self.path, err)

    # -- reading ------------------------------------------------------------------------
    def snapshot(self) -> tuple[int, list[GroundHole], list[TrackPoint]]:
        """(version, holes by id, track) copies, consistent with each other."""
        with self._lock:
            return (
                self.version,
                [
                    dataclasses.replace(h, vehicles=[dataclasses.replace(v) for v in h.vehicles])
                    for _, h in sorted(self.holes.items())
                ],
                list(self.track),
            )

    def vehicle_snapshot(self) -> list[VehicleStatus]:
        """Copies of the vehicles heard, by system id."""
        with self._lock:
            return [v.copy() for _, v in sorted(self.vehicles.items())]

    # -- changes ------------------------------------------------------------------------
    def _changed(self, *, save_now: bool = False) -> None:
        with self._lock:
            self.version += 1
            version = self.version
            if save_now or self._may_save():
                self._save()
            else:
                self._save_later()
        self._tell(version)

    def _may_save(self) -> bool:
        """A token bucket: ``save_burst`` writes at once, then one per ``save_every_s``."""
        now = time.monotonic()
        self._save_tokens = min(
            float(self.save_burst), self._save_tokens + (now - self._save_t) / self.save_every_s
        )
        self._save_t = now
        if self._save_tokens >= 1.0:
            self._save_tokens -= 1.0
            return True
        return False

    def _save_later(self) -> None:
        self._unsaved = True
        if self._timer is None:
            self._timer = threading.Timer(self.save_every_s, self.flush)
            self._timer.daemon = True
            self._timer.start()

    def flush(self) -> None:
        """Write what a batched save still holds (the station calls it when it stops)."""
        with self._lock:
            self._timer = None
            if self._unsaved:
                self._save()

    def reject(self, what: str, err: Exception) -> None:
        """Count and log a value from the link that was refused (nothing of it is kept)."""
        with self._lock:
            self.rejected += 1
            n = self.rejected
        if n <= 20 or n % 1000 == 0:  # a flood: one line per thousand
            _log.warning("refused %s from the link (%s); %d refused so far", what, err, n)

    def _tell(self, version: int) -> None:
        for fn in list(self.listeners):
            try:
                fn(version)
            except Exception:  # a listener's failure must not lose the state
                _log.exception("state listener failed")

    def _save(self) -> None:
        doc = {
            "format": FORMAT,
            "version": self.version,
            "primary_sysid": self.primary_sysid,
            "holes": [h.to_json() for _, h in sorted(self.holes.items())],
            "track": [dataclasses.astuple(p) for p in self.track],
        }
        text = json.dumps(doc, separators=(",", ":"), allow_nan=False)  # strict: checked above
        with atomic_output(self.path, force=True) as f:
            f.write(text.encode())
        self._unsaved = False
        self._last_track_save_ns = self.clock()

    def _room_for(self, hole_id: int | None) -> bool:
        """Whether hole ``hole_id`` may be kept: known, or fewer than ``max_holes`` kept."""
        if (hole_id is not None and hole_id in self.holes) or len(self.holes) < self.max_holes:
            return True
        self.reject(f"hole {hole_id}", LinkValueError(f"{self.max_holes} holes kept already"))
        return False

    # -- several vehicles, one id per opening (see the class docstring) -----------------------
    def _sysid(self, sysid: int | None) -> int:
        if sysid is None:
            sysid = self.primary_sysid if self.primary_sysid is not None else 1
        if self.primary_sysid is None:
            self.primary_sysid = sysid
        return sysid

    def _own_id(self, sysid: int, own: int) -> int:
        """The station id a new hole of vehicle ``sysid`` (its id ``own``) takes."""
        if sysid == self.primary_sysid:
            return own
        if own >= VEHICLE_ID_BLOCK:
            raise LinkValueError(
                f"vehicle {sysid}'s hole id {own}: a second vehicle's ids must be below "
                f"{VEHICLE_ID_BLOCK}"
            )
        return sysid * VEHICLE_ID_BLOCK + own

    def _same_opening(self, src: HoleSource, exclude: int | None) -> int | None:
        """The station hole (not ``exclude``, none with a part of ``src``'s vehicle) at
        ``src``'s opening by the campaign's rule, or None."""
        others = [
            (h.id, h.vehicles[-1] if h.vehicles else None, h)
            for h in self.holes.values()
            if h.id != exclude and h.vehicles and all(v.sysid != src.sysid for v in h.vehicles)
        ]
        if not others:
            return None
        # each station hole by its most certain vehicle's estimate (the one it shows)
        ref = [_best(h.vehicles).as_hole(hid) for hid, _, h in others]
        m = carry_ids(ref, [src.as_hole(0)])
        hid = m.ids.get(0)
        return hid if hid is not None and hid in m.from_reference else None

    def _source(
        self, sysid: int | None, own: int, lat: float, lon: float
    ) -> tuple[GroundHole, HoleSource, bool] | None:
        """The station hole and vehicle part for vehicle ``sysid``'s hole ``own`` (made
        when new: matched to another vehicle's hole or a new station hole), and whether
        the part is new. None: no room, or an id that cannot be given (counted in
        ``rejected``)."""
        now = self.clock()
        try:
            sysid = self._sysid(sysid)
            hid = self._ids.get((sysid, own))
            if hid is not None and hid in self.holes:
                h = self.holes[hid]
                src = next(v for v in h.vehicles if v.sysid == sysid)
                src.t_last_unix_ns = now
                return h, src, False
            src = HoleSource(sysid, own, lat, lon, t_first_unix_ns=now, t_last_unix_ns=now)
            match = self._same_opening(src, None)
            if match is not None:
                h = self.holes[match]
                h.vehicles.append(src)
                self._ids[(sysid, own)] = h.id
                return h, src, True
            hid = self._own_id(sysid, own)
        except LinkValueError as err:
            self.reject("a hole", err)
            return None
        h_old = self.holes.get(hid)
        if h_old is not None and h_old.vehicles:  # another vehicle's hole has that id
            self.reject(f"vehicle {sysid}'s hole {own}", LinkValueError(f"id {hid} is taken"))
            return None
        if h_old is None and not self._room_for(None):
            return None
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
        self._ids[(sysid, own)] = hid
        return h_old, src, True

    def _fold(self, h: GroundHole, moved: HoleSource) -> GroundHole:
        """Set ``h``'s facts from its vehicles' (see the class docstring), after ``moved``
        told new ones; fold it into another vehicle's hole at the same opening when it has
        only this one vehicle (see the class docstring). Returns the hole that remains."""
        if len(h.vehicles) == 1 and h.mark == "new":
            other = self._same_opening(moved, h.id)
            if other is not None:
                a, b = sorted((h, self.holes[other]), key=lambda x: (x.t_first_unix_ns, x.id))
                self._absorb(a, b)
                h = a
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
        h.t_updated_unix_ns = self.clock()
        return h

    def _absorb(self, keep: GroundHole, gone: GroundHole) -> None:
        """Fold hole ``gone`` into ``keep``: its vehicles, its mark and its picture."""
        _log.info("hole %d is at hole %d's opening (another vehicle's): one hole", gone.id,
                  keep.id)  # fmt: skip
        keep.vehicles += gone.vehicles
        keep.vehicles.sort(key=lambda v: v.t_first_unix_ns)
        for v in gone.vehicles:
            self._ids[(v.sysid, v.hole_id)] = keep.id
        if keep.mark == "new":
            keep.mark = gone.mark
        if gone.has_picture and not keep.has_picture:
            try:
                self.card_path(gone.id).replace(self.card_path(keep.id))
                keep.has_picture, keep.why = True, gone.why
            except OSError as err:
                _log.warning("hole %d's picture not moved: %s", gone.id, err)
        keep.t_first_unix_ns = min(keep.t_first_unix_ns, gone.t_first_unix_ns)
        del self.holes[gone.id]

    def on_statustext(self, text: str, sysid: int | None = None) -> GroundHole | None:
        """Take a ``HOLE ...`` STATUSTEXT of vehicle ``sysid`` (None: the first vehicle);
        return the hole when it was one (a text that starts as one but whose values are out
        of range is counted in ``rejected``)."""
        said = read_hole_text(text)
        if said is None:
            if text.lstrip().startswith(("HOLE ", "REVIEW ")):
                self.reject("a hole STATUSTEXT", LinkValueError(repr(xml_text(text, 60))))
            return None
        hid, lat, lon, tier = said.hole_id, said.lat_deg, said.lon_deg, said.tier
        with self._lock:
            got = self._source(sysid, hid, lat, lon)
            if got is None:
                return None
            h, src, new = got
            p_hole = said.p_hole if said.p_hole is not None else src.p_hole
            score = said.score if said.score is not None else src.score
            told = (lat, lon, p_hole, score, tier)
            if not new and (src.lat_deg, src.lon_deg, src.p_hole, src.score, src.tier) == told:
                return h
            src.lat_deg, src.lon_deg, src.p_hole, src.score, src.tier = told
            h = self._fold(h, src)
        self._changed()
        return h

    def on_card(
        self, facts: dict[str, Any], jpeg: bytes, sysid: int | None = None
    ) -> GroundHole | None:
        """Take a card's facts (:func:`missions.read_card`) and picture (``jpeg``: the
        card's bytes) from vehicle ``sysid`` (None: the first vehicle); an older revision
        than kept is ignored. A facts-only card (:data:`missions.NO_PICTURE`) updates the
        facts and keeps the picture held (its file then carries the new facts)."""
        try:
            v = card_values(facts)
        except LinkValueError as err:
            self.reject("a card", err)
            return None
        with self._lock:
            got = self._source(sysid, v.hole_id, v.lat_deg, v.lon_deg)
            if got is None:
                return None
            h, src, _ = got
            if src.card_rev >= v.rev:
                return h
            picture = card_picture(jpeg) != NO_PICTURE
            if not picture and h.has_picture:
                try:
                    jpeg, picture = with_picture(jpeg, self.card_path(h.id).read_bytes()), True
                except OSError as err:  # the kept picture is gone: facts only, ask again
                    _log.warning("hole %d: kept picture unreadable (%s)", h.id, err)
                    h.has_picture = False
            if picture:
                with atomic_output(self.card_path(h.id), force=True) as f:
                    f.write(jpeg)
            src.lat_deg, src.lon_deg, src.score, src.card_rev = (
                v.lat_deg, v.lon_deg, v.score, v.rev,
            )  # fmt: skip
            src.alt_m, src.sigma_h_m = v.alt_m, v.sigma_h_m
            src.major_m, src.minor_m = v.major_m, v.minor_m
            if v.sightings is not None:
                src.sightings = v.sightings
            src.tier, src.p_hole = v.tier, v.p_hole
            h.has_picture = h.has_picture or picture
            if v.why is not None:
                h.why = v.why
            h = self._fold(h, src)
        self._changed()
        return h

    def on_mission(
        self,
        items: list[tuple[int, float, float]],
        match_m: float = 1.5,
        sysid: int | None = None,
    ) -> int:
        """Take vehicle ``sysid``'s downloaded hole mission ((seq, lat_deg, lon_deg) of the
        hole items; None: the first vehicle); return how many items match none of its
        holes (the ground is missing something).

        Items are paired with that vehicle's holes nearest first, each used once, within
        ``match_m`` (:func:`geotag.nearest_pairs`, distances in local metres): the mission
        may hold a newer position of a hole than its last announcement (the vehicle
        re-announces only moves over 0.5 m). A hole's ``seq`` is its first vehicle's.
        """
        with self._lock:
            sid = self._sysid(sysid)
            mine = [
                (h, v)
                for h in self.holes.values()
                for v in h.vehicles or [HoleSource(sid, h.id, h.lat_deg, h.lon_deg)]
                if v.sysid == sid
            ]
            places = [(v.lat_deg, v.lon_deg) for _, v in mine]
            paired = nearest_pairs(_candidates(items, places, match_m))
            seqs = {id(mine[j][1]): items[i][0] for i, (j, _) in paired.items()}
            for h, v in mine:
                v.seq = seqs.get(id(v))
                if not h.vehicles:  # a hole of an older state file: its own seq
                    h.seq = v.seq
            for h in self.holes.values():
                if h.vehicles:
                    h.seq = h.vehicles[0].seq
            unknown = len(items) - len(paired)
        self._changed()
        return unknown

    def missing_from_mission(self, sysid: int | None = None) -> frozenset[int]:
        """Vehicle ``sysid``'s own ids of its holes (not rejected) not in its mission."""
        with self._lock:
            sid = self._sysid(sysid)
            return frozenset(
                v.hole_id
                for h in self.holes.values()
                if h.mark != "rejected"
                for v in h.vehicles
                if v.sysid == sid and v.seq is None
            )

    def mark(self, hole_id: int, mark: str) -> GroundHole:
        """Set the operator's mark of a hole (raises InputError for unknown ones)."""
        if mark not in MARKS:
            raise InputError(f"mark must be one of {', '.join(MARKS)}, got {mark!r}")
        with self._lock:
            h = self.holes.get(hole_id)
            if h is None:
                raise InputError(f"no hole {hole_id}")
            h.mark = mark
            h.t_updated_unix_ns = self.clock()
        self._changed(save_now=True)  # an operator's word is never held back
        return h

    def on_vehicle_packet(
        self, sysid: int, link: str, compid: int, seq: int, t_mono_s: float
    ) -> None:
        """Count a packet of vehicle ``sysid`` heard on ``link`` (link quality, last heard)."""
        with self._lock:
            v = self.vehicles.get(sysid)
            if v is None:
                v = self.vehicles[sysid] = VehicleStatus(sysid)
            if link not in v.links:
                v.links.append(link)
            v.quality.on_packet(compid, seq, t_mono_s)
            v.t_heard_unix_ns = self.clock()

    def on_vehicle_message(self, sysid: int, msg: Any) -> None:
        """Take what an autopilot message says of vehicle ``sysid``'s status (every value
        checked: a bad one is counted in ``rejected``, nothing of its message kept)."""
        with self._lock:
            v = self.vehicles.get(sysid)
            if v is None:
                v = self.vehicles[sysid] = VehicleStatus(sysid)
            trial = dataclasses.replace(v)  # take() sets fields only: the rest is shared
            try:
                told = trial.take(msg)
            except LinkValueError as err:
                self.reject(f"a {msg.get_type()} of vehicle {sysid}", err)
                return
            if msg.get_type() == "GLOBAL_POSITION_INT":
                trial.t_position_unix_ns = self.clock()
            self.vehicles[sysid] = trial
            if not told:
                return
            self.version += 1
            version = self.version
        self._tell(version)

    def on_position(self, p: TrackPoint, min_step_s: float = 1.0) -> bool:
        """Add a track point (at most one per ``min_step_s`` per vehicle); True when kept.

        The track is saved with the next change, or every 10 s.
        """
        try:
            p.checked()
        except LinkValueError as err:
            self.reject("a track point", err)
            return False
        with self._lock:
            last = self._last_point_ns.get(p.sysid)
            if last is not None and p.t_unix_ns - last < min_step_s * _NS_PER_S:
                return False
            self._last_point_ns[p.sysid] = p.t_unix_ns
            self.track.append(p)
            if len(self.track) > _TRACK_MAX:
                del self.track[: len(self.track) - _TRACK_MAX]
            save = self.clock() - self._last_track_save_ns > _TRACK_SAVE_NS
        if save:
            self._changed()
        else:
            with self._lock:
                self.version += 1
                version = self.version
            self._tell(version)
        return True


def _best(sources: list[HoleSource]) -> HoleSource:
    """The vehicle part with the most certain position (smallest sigma; ties: latest)."""
    return min(
        sources,
        key=lambda v: (
            v.sigma_h_m if v.sigma_h_m is not None else float("inf"),
            -v.t_last_unix_ns,
        ),
    )


def _candidates(
    items: list[tuple[int, float, float]], places: list[tuple[float, float]], match_m: float
) -> list[tuple[float, int, int]]:
    """(distance m, item index, place index) of every item and place within ``match_m``."""
    if not items or not places:
        return []
    frame = LocalFrame(*places[0])
    he, hn = frame.to_en([p[0] for p in places], [p[1] for p in places])
    ie, in_ = frame.to_en([it[1] for it in items], [it[2] for it in items])
    d = np.hypot(ie[:, None] - he[None, :], in_[:, None] - hn[None, :])
    return [
        (float(d[i, j]), i, j)
        for i in range(len(items))
        for j in range(len(places))
        if d[i, j] <= match_m
    ]


def _ns_of_seconds(t_s: Any) -> int:
    """A ``holescan-ground-1`` time (float seconds of ``time.time()``) in ns: to the
    microsecond, all a float of today's Unix seconds holds.

    >>> _ns_of_seconds(1_700_000_000.25)
    1700000000250000000
    """
    return round(float(t_s) * 1_000_000) * 1000
