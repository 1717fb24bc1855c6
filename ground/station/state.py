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
    HoleTier,
    LocalFrame,
    VehicleTier,
    nearest_pairs,
)
from holescan.ground.errors import StationFileError
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
    "VEHICLE_TIERS",
    "GroundHole",
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
        names = {f.name for f in dataclasses.fields(cls)}
        h = cls(**{k: v for k, v in d.items() if k in names})
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
        return forgotten


@dataclass(frozen=True)
class TrackPoint:
    """The vehicle at one instant: Unix clock ns, WGS84 degrees, m above home, heading rad."""

    t_unix_ns: int
    lat_deg: float
    lon_deg: float
    rel_alt_m: float
    yaw: float

    @classmethod
    def from_json(cls, row: list[Any], file_format: str = FORMAT) -> TrackPoint:
        """A track row of the state file (``holescan-ground-1``: time in float seconds)."""
        t, lat, lon, rel_alt, yaw = row
        t_ns = _ns_of_seconds(t) if file_format == _FORMAT_1 else int(t)
        return cls(t_ns, float(lat), float(lon), float(rel_alt), float(yaw)).checked()

    def checked(self) -> TrackPoint:
        """This point when every value is one the link may give (else
        :class:`missions.LinkValueError`): time, position on the Earth, height, yaw."""
        link_int(self.t_unix_ns, 0, _T_NS_MAX, "time")
        link_lat_lon(self.lat_deg, self.lon_deg)
        link_float(self.rel_alt_m, *_ALT_M, "height above home")
        link_yaw(self.yaw)
        return self


@dataclass
class StationState:
    """Holes, marks and track of one ground station, persisted in ``folder``.

    ``listeners`` are called (without the lock held) after every change with the new
    version; the web page's event stream and the file writers hang on them. ``clock`` is
    the Unix clock in ns (the holes' and track's times).
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
                [dataclasses.replace(h) for _, h in sorted(self.holes.items())],
                list(self.track),
            )

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
            "holes": [h.to_json() for _, h in sorted(self.holes.items())],
            "track": [dataclasses.astuple(p) for p in self.track],
        }
        text = json.dumps(doc, separators=(",", ":"), allow_nan=False)  # strict: checked above
        with atomic_output(self.path, force=True) as f:
            f.write(text.encode())
        self._unsaved = False
        self._last_track_save_ns = self.clock()

    def _room_for(self, hole_id: int) -> bool:
        """Whether hole ``hole_id`` may be kept: known, or fewer than ``max_holes`` kept."""
        if hole_id in self.holes or len(self.holes) < self.max_holes:
            return True
        self.reject(f"hole {hole_id}", LinkValueError(f"{self.max_holes} holes kept already"))
        return False

    def _hole(self, hole_id: int, lat_deg: float, lon_deg: float) -> GroundHole:
        now = self.clock()
        h = self.holes.get(hole_id)
        if h is None:
            h = GroundHole(hole_id, lat_deg, lon_deg, t_first_unix_ns=now)
            self.holes[hole_id] = h
        h.t_updated_unix_ns = now
        return h

    def on_statustext(self, text: str) -> GroundHole | None:
        """Take a ``HOLE ...`` STATUSTEXT; return the hole when it was one (a text that
        starts as one but whose values are out of range is counted in ``rejected``). Its
        number is kept as what it is: ``p_hole`` (``p0.97``), or ``score`` from a vehicle
        that sent the old form (:func:`link.read_hole_text`)."""
        said = read_hole_text(text)
        if said is None:
            if text.lstrip().startswith(("HOLE ", "REVIEW ")):
                self.reject("a hole STATUSTEXT", LinkValueError(repr(xml_text(text, 60))))
            return None
        hid, lat, lon, tier = said.hole_id, said.lat_deg, said.lon_deg, said.tier
        with self._lock:
            if not self._room_for(hid):
                return None
            h = self.holes.get(hid)
            p_hole = said.p_hole if said.p_hole is not None else (h.p_hole if h else None)
            score = said.score if said.score is not None else (h.score if h else None)
            if h is not None and (h.lat_deg, h.lon_deg, h.p_hole, h.score, h.vehicle_tier) == (
                lat,
                lon,
                p_hole,
                score,
                tier,
            ):
                return h
            h = self._hole(hid, lat, lon)
            h.lat_deg, h.lon_deg, h.vehicle_tier = lat, lon, tier
            h.p_hole, h.score = p_hole, score
        self._changed()
        return h

    def on_card(self, facts: dict[str, Any], jpeg: bytes) -> GroundHole | None:
        """Take a card's facts (:func:`missions.read_card`) and picture (``jpeg``: the
        card's bytes); an older revision than kept is ignored. A facts-only card
        (:data:`missions.NO_PICTURE`) updates the facts and keeps the picture held (its
        file then carries the new facts)."""
        try:
            v = card_values(facts)
        except LinkValueError as err:
            self.reject("a card", err)
            return None
        hid, rev = v.hole_id, v.rev
        with self._lock:
            h = self.holes.get(hid)
            if h is not None and h.card_rev >= rev:
                return h
            if not self._room_for(hid):
                return None
            picture = card_picture(jpeg) != NO_PICTURE
            if not picture and h is not None and h.has_picture:
                try:
                    jpeg, picture = with_picture(jpeg, self.card_path(hid).read_bytes()), True
                except OSError as err:  # the kept picture is gone: facts only, ask again
                    _log.warning("hole %d: kept picture unreadable (%s)", hid, err)
                    h.has_picture = False
            if picture:
                with atomic_output(self.card_path(hid), force=True) as f:
                    f.write(jpeg)
            h = self._hole(hid, v.lat_deg, v.lon_deg)
            h.lat_deg, h.lon_deg, h.score, h.card_rev = v.lat_deg, v.lon_deg, v.score, rev
            h.has_picture = h.has_picture or picture
            h.alt_m, h.sigma_h_m = v.alt_m, v.sigma_h_m
            h.major_m, h.minor_m = v.major_m, v.minor_m
            if v.sightings is not None:
                h.sightings = v.sightings
            if v.why is not None:
                h.why = v.why
            h.vehicle_tier = v.tier
            h.p_hole = v.p_hole
        self._changed()
        return h

    def on_mission(self, items: list[tuple[int, float, float]], match_m: float = 1.5) -> int:
        """Take a downloaded hole mission ((seq, lat_deg, lon_deg) of the hole items);
        return how many items match no known hole (the ground is missing something).

        Items are paired with holes nearest first, each used once, within ``match_m``
        (:func:`geotag.nearest_pairs`, distances in local metres): the mission may hold a
        newer position of a hole than its last announcement (the vehicle re-announces only
        moves over 0.5 m).
        """
        with self._lock:
            holes = list(self.holes.values())
            paired = nearest_pairs(_candidates(items, holes, match_m))
            seqs = {holes[j].id: items[i][0] for i, (j, _) in paired.items()}
            for h in holes:
                h.seq = seqs.get(h.id)
            unknown = len(items) - len(paired)
        self._changed()
        return unknown

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

    def on_position(self, p: TrackPoint, min_step_s: float = 1.0) -> bool:
        """Add a track point (at most one per ``min_step_s``); True when kept.

        The track is saved with the next change, or every 10 s.
        """
        try:
            p.checked()
        except LinkValueError as err:
            self.reject("a track point", err)
            return False
        with self._lock:
            if self.track and p.t_unix_ns - self.track[-1].t_unix_ns < min_step_s * _NS_PER_S:
                return False
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


def _candidates(
    items: list[tuple[int, float, float]], holes: list[GroundHole], match_m: float
) -> list[tuple[float, int, int]]:
    """(distance m, item index, hole index) of every item and hole within ``match_m``."""
    if not items or not holes:
        return []
    frame = LocalFrame(holes[0].lat_deg, holes[0].lon_deg)
    he, hn = frame.to_en([h.lat_deg for h in holes], [h.lon_deg for h in holes])
    ie, in_ = frame.to_en([it[1] for it in items], [it[2] for it in items])
    d = np.hypot(ie[:, None] - he[None, :], in_[:, None] - hn[None, :])
    return [
        (float(d[i, j]), i, j)
        for i in range(len(items))
        for j in range(len(holes))
        if d[i, j] <= match_m
    ]


def _ns_of_seconds(t_s: Any) -> int:
    """A ``holescan-ground-1`` time (float seconds of ``time.time()``) in ns: to the
    microsecond, all a float of today's Unix seconds holds.

    >>> _ns_of_seconds(1_700_000_000.25)
    1700000000250000000
    """
    return round(float(t_s) * 1_000_000) * 1000
