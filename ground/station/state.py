"""The ground station's memory: holes, their pictures, the operator's marks, the track.

Everything ``holescan ground`` learns is kept here and written to ``DIR/station.json``
after every change (through the output-path rule, :func:`outputs.atomic_output`: written
to ``.station.part.json``, flushed, fsynced, renamed: a crash or a power cut leaves the
previous or the new file, never half of one), pictures to ``DIR/cards/hole-ID.jpg`` the
same way. A restart reads it back, so a link drop, a restart or a second sortie loses
nothing, and holes keep the vehicle's ids. A state file of an older station
(``holescan-ground-1``: ``lat``/``lon``/``alt``/``sigma_m``, times in float seconds) is
read too, and written back in the current format with the next change.

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
import re
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from holescan.errors import InputError
from holescan.geotag import LocalFrame, nearest_pairs
from holescan.ground.errors import StationFileError
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
VehicleTier = Literal["announced", "review"]
VEHICLE_TIERS: tuple[VehicleTier, ...] = ("announced", "review")
Tier = Literal["announced", "review", "confirmed", "rejected"]
TIERS: tuple[Tier, ...] = ("announced", "review", "confirmed", "rejected")
FORMAT = "holescan-ground-2"
"""The state file's ``format``; ``holescan-ground-1`` files (older stations) are read too."""
_FORMAT_1 = "holescan-ground-1"
_STATUSTEXT = re.compile(r"(?:HOLE|REVIEW) (\d+) ([\d.]+) (-?[\d.]+) (-?[\d.]+)")
_TRACK_MAX = 20_000
_TRACK_SAVE_NS = 10 * 10**9
_NS_PER_S = 1_000_000_000
# keys of a holescan-ground-1 hole -> this version's
_OLD_KEYS = {"lat": "lat_deg", "lon": "lon_deg", "alt": "alt_m", "sigma_m": "sigma_h_m"}
_OLD_SECONDS = {"first_unix": "t_first_unix_ns", "updated_unix": "t_updated_unix_ns"}


def parse_hole_statustext(text: str) -> tuple[int, float, float, float] | None:
    """``HOLE <id> <score> <lat> <lon>`` (an announced hole) or ``REVIEW <id> ...`` (a hole
    for review) -> (id, score, lat_deg, lon_deg); None for other texts.

    >>> parse_hole_statustext("HOLE 3 0.88 43.6533100 -79.3831200")
    (3, 0.88, 43.65331, -79.38312)
    >>> parse_hole_statustext("REVIEW 4 0.30 43.6533100 -79.3831200")
    (4, 0.3, 43.65331, -79.38312)
    >>> parse_hole_statustext("PreArm: GPS") is None
    True
    """
    m = _STATUSTEXT.fullmatch(text.strip().rstrip("\x00"))
    if m is None:
        return None
    hid, score, lat, lon = int(m[1]), float(m[2]), float(m[3]), float(m[4])
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and 0 <= score <= 1):
        return None
    return hid, score, lat, lon


@dataclass
class GroundHole:
    """One hole as the ground knows it.

    id : the vehicle's hole id. lat_deg, lon_deg : WGS84; alt_m : m MSL (None: unknown).
    sigma_h_m : 1-sigma horizontal uncertainty, m (None until the card came).
    score, sightings, major_m, minor_m : the detector's. why : its explanation.
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
    score: float
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
        if self.mark == "rejected":
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
        return cls(t_ns, float(lat), float(lon), float(rel_alt), float(yaw))


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
    _lock: threading.RLock = field(default_factory=threading.RLock)
    _last_track_save_ns: int = 0

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
                state.holes = {int(d["id"]): GroundHole.from_json(d) for d in doc["holes"]}
                state.track = [TrackPoint.from_json(p, fmt) for p in doc.get("track", [])]
                state.version = int(doc.get("version", 0))
            except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
                raise StationFileError(
                    f"{state.path} is not a holescan ground station file ({err}); move it away"
                ) from err
            _log.info("resumed %d holes from %s", len(state.holes), state.path)
        return state

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
    def _changed(self) -> None:
        with self._lock:
            self.version += 1
            version = self.version
            self._save()
        self._tell(version)

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
        with atomic_output(self.path, force=True) as f:
            f.write(json.dumps(doc, separators=(",", ":")).encode())
        self._last_track_save_ns = self.clock()

    def _hole(self, hole_id: int, lat_deg: float, lon_deg: float, score: float) -> GroundHole:
        now = self.clock()
        h = self.holes.get(hole_id)
        if h is None:
            h = GroundHole(hole_id, lat_deg, lon_deg, score, t_first_unix_ns=now)
            self.holes[hole_id] = h
        h.t_updated_unix_ns = now
        return h

    def on_statustext(self, text: str) -> GroundHole | None:
        """Take a ``HOLE ...`` STATUSTEXT; return the hole when it was one."""
        parsed = parse_hole_statustext(text)
        if parsed is None:
            return None
        hid, score, lat, lon = parsed
        tier: VehicleTier = "review" if text.strip().startswith("REVIEW") else "announced"
        with self._lock:
            h = self.holes.get(hid)
            if h is not None and (h.lat_deg, h.lon_deg, h.score, h.vehicle_tier) == (
                lat,
                lon,
                score,
                tier,
            ):
                return h
            h = self._hole(hid, lat, lon, score)
            h.lat_deg, h.lon_deg, h.score, h.vehicle_tier = lat, lon, score, tier
        self._changed()
        return h

    def on_card(self, facts: dict[str, Any], jpeg: bytes) -> GroundHole | None:
        """Take a card's facts (:func:`missions.read_card`) and picture; an older revision
        than kept is ignored."""
        try:
            hid, rev = int(facts["id"]), int(facts.get("rev", 1))
            lat, lon, score = float(facts["lat"]), float(facts["lon"]), float(facts["score"])
        except (KeyError, TypeError, ValueError) as err:
            _log.warning("card without usable facts ignored (%s)", err)
            return None
        with self._lock:
            h = self.holes.get(hid)
            if h is not None and h.card_rev >= rev:
                return h
            with atomic_output(self.card_path(hid), force=True) as f:
                f.write(jpeg)
            h = self._hole(hid, lat, lon, score)
            h.lat_deg, h.lon_deg, h.score, h.card_rev, h.has_picture = lat, lon, score, rev, True
            h.alt_m = _opt(facts.get("alt"))
            h.sigma_h_m = _opt(facts.get("sigma"))
            h.major_m = _opt(facts.get("major"))
            h.minor_m = _opt(facts.get("minor"))
            h.sightings = int(facts.get("n", h.sightings))
            h.why = str(facts.get("why", h.why))[:500]
            h.vehicle_tier = "review" if facts.get("tier") == "review" else "announced"
            h.p_hole = _opt(facts.get("p"))
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
        self._changed()
        return h

    def on_position(self, p: TrackPoint, min_step_s: float = 1.0) -> bool:
        """Add a track point (at most one per ``min_step_s``); True when kept.

        The track is saved with the next change, or every 10 s.
        """
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


def _opt(v: Any) -> float | None:
    try:
        return None if v is None else float(v)
    except (TypeError, ValueError):
        return None
