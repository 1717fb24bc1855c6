"""The ground station's memory: holes, their pictures, the operator's marks, the track.

Everything ``holescan ground`` learns is kept here and written to ``DIR/station.json``
after every change (written to ``station.json.part``, flushed, fsynced, renamed: a crash or
a power cut leaves the previous or the new file, never half of one), pictures to
``DIR/cards/hole-ID.jpg`` the same way. A restart reads it back, so a link drop, a restart
or a second sortie loses nothing, and holes keep the vehicle's ids.

A hole is known from any of: the vehicle's STATUSTEXT ``HOLE <id> <score> <lat> <lon>``
(fast, 50 bytes), its card (picture + facts, :mod:`missions._holecards`), the hole mission
downloaded from component 191. Later facts update earlier ones; the operator's mark
(``new`` / ``confirmed`` / ``rejected`` / ``visited``) is the ground's own and never
overwritten by the vehicle. ``version`` counts changes (the live page and the files
follow it).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from holescan.errors import InputError

__all__ = [
    "MARKS",
    "GroundHole",
    "Mark",
    "StationState",
    "TrackPoint",
    "atomic_write",
    "parse_hole_statustext",
]

_log = logging.getLogger(__name__)

Mark = Literal["new", "confirmed", "rejected", "visited"]
MARKS: tuple[Mark, ...] = ("new", "confirmed", "rejected", "visited")
_STATUSTEXT = re.compile(r"HOLE (\d+) ([\d.]+) (-?[\d.]+) (-?[\d.]+)")
_TRACK_MAX = 20_000


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through ``path.part`` + fsync + rename."""
    part = path.with_name(path.name + ".part")
    with open(part, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(part, path)


def parse_hole_statustext(text: str) -> tuple[int, float, float, float] | None:
    """``HOLE <id> <score> <lat> <lon>`` -> (id, score, lat, lon); None for other texts.

    >>> parse_hole_statustext("HOLE 3 0.88 43.6533100 -79.3831200")
    (3, 0.88, 43.65331, -79.38312)
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

    id : the vehicle's hole id. lat, lon : WGS84; alt : m MSL (None: unknown).
    sigma_m : 1-sigma horizontal uncertainty (None until the card came).
    score, sightings, major_m, minor_m : the detector's. why : its explanation.
    card_rev : revision of the newest card (0: no card yet). has_picture : a JPEG is kept.
    mark : the operator's (``new`` until set). seq : waypoint number in the downloaded
    hole mission (None: not in it). first_unix, updated_unix : when the ground first heard
    of it / last changed it (seconds).
    """

    id: int
    lat: float
    lon: float
    score: float
    alt: float | None = None
    sigma_m: float | None = None
    sightings: int = 0
    major_m: float | None = None
    minor_m: float | None = None
    why: str = ""
    card_rev: int = 0
    has_picture: bool = False
    mark: Mark = "new"
    seq: int | None = None
    first_unix: float = 0.0
    updated_unix: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> GroundHole:
        names = {f.name for f in dataclasses.fields(cls)}
        h = cls(**{k: v for k, v in d.items() if k in names})
        if h.mark not in MARKS:
            h.mark = "new"
        return h


@dataclass(frozen=True)
class TrackPoint:
    """The vehicle at one instant: unix s, WGS84, m above home, heading rad."""

    t_unix: float
    lat: float
    lon: float
    rel_alt_m: float
    yaw: float


@dataclass
class StationState:
    """Holes, marks and track of one ground station, persisted in ``folder``.

    ``listeners`` are called (without the lock held) after every change with the new
    version; the web page's event stream and the file writers hang on them.
    """

    folder: Path
    holes: dict[int, GroundHole] = field(default_factory=dict)
    track: list[TrackPoint] = field(default_factory=list)
    version: int = 0
    listeners: list[Callable[[int], None]] = field(default_factory=list)
    clock: Callable[[], float] = time.time
    _lock: threading.RLock = field(default_factory=threading.RLock)
    _last_track_save: float = 0.0

    @property
    def path(self) -> Path:
        return self.folder / "station.json"

    def card_path(self, hole_id: int) -> Path:
        return self.folder / "cards" / f"hole-{hole_id}.jpg"

    @classmethod
    def open(cls, folder: Path) -> StationState:
        """The state kept in ``folder`` (created when new)."""
        try:
            (folder / "cards").mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise InputError(f"cannot create {folder}: {err.strerror}") from err
        state = cls(folder)
        if state.path.exists():
            try:
                doc = json.loads(state.path.read_text())
                state.holes = {int(d["id"]): GroundHole.from_json(d) for d in doc["holes"]}
                state.track = [TrackPoint(*p) for p in doc.get("track", [])]
                state.version = int(doc.get("version", 0))
            except (OSError, ValueError, KeyError, TypeError) as err:
                raise InputError(
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
        for fn in list(self.listeners):
            try:
                fn(version)
            except Exception:  # a listener's failure must not lose the state
                _log.exception("state listener failed")

    def _save(self) -> None:
        doc = {
            "format": "holescan-ground-1",
            "version": self.version,
            "holes": [h.to_json() for _, h in sorted(self.holes.items())],
            "track": [dataclasses.astuple(p) for p in self.track],
        }
        atomic_write(self.path, json.dumps(doc, separators=(",", ":")).encode())
        self._last_track_save = self.clock()

    def _hole(self, hole_id: int, lat: float, lon: float, score: float) -> GroundHole:
        now = self.clock()
        h = self.holes.get(hole_id)
        if h is None:
            h = GroundHole(hole_id, lat, lon, score, first_unix=now)
            self.holes[hole_id] = h
        h.updated_unix = now
        return h

    def on_statustext(self, text: str) -> GroundHole | None:
        """Take a ``HOLE ...`` STATUSTEXT; return the hole when it was one."""
        parsed = parse_hole_statustext(text)
        if parsed is None:
            return None
        hid, score, lat, lon = parsed
        with self._lock:
            h = self.holes.get(hid)
            if h is not None and (h.lat, h.lon, h.score) == (lat, lon, score):
                return h
            h = self._hole(hid, lat, lon, score)
            h.lat, h.lon, h.score = lat, lon, score
        self._changed()
        return h

    def on_card(self, facts: dict[str, Any], jpeg: bytes) -> GroundHole | None:
        """Take a card's facts and picture; an older revision than kept is ignored."""
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
            atomic_write(self.card_path(hid), jpeg)
            h = self._hole(hid, lat, lon, score)
            h.lat, h.lon, h.score, h.card_rev, h.has_picture = lat, lon, score, rev, True
            h.alt = _opt(facts.get("alt"))
            h.sigma_m = _opt(facts.get("sigma"))
            h.major_m = _opt(facts.get("major"))
            h.minor_m = _opt(facts.get("minor"))
            h.sightings = int(facts.get("n", h.sightings))
            h.why = str(facts.get("why", h.why))[:500]
        self._changed()
        return h

    def on_mission(self, items: list[tuple[int, float, float]], match_m: float = 1.5) -> int:
        """Take a downloaded hole mission ((seq, lat, lon) of the hole items); return how
        many items match no known hole (the ground is missing something).

        Items are paired with holes nearest first, each used once, within ``match_m``: the
        mission may hold a newer position of a hole than its last announcement (the
        vehicle re-announces only moves over 0.5 m).
        """
        with self._lock:
            holes = list(self.holes.values())
            pairs = []
            for seq, lat, lon in items:
                k = 111_320.0 * math.cos(math.radians(lat))
                for h in holes:
                    d = math.hypot((h.lat - lat) * 111_320.0, (h.lon - lon) * k)
                    if d <= match_m:
                        pairs.append((d, seq, h.id))
            pairs.sort()
            seqs: dict[int, int] = {}
            used: set[int] = set()
            for _, seq, hid in pairs:
                if seq not in used and hid not in seqs:
                    seqs[hid] = seq
                    used.add(seq)
            for h in holes:
                h.seq = seqs.get(h.id)
            unknown = len(items) - len(used)
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
            h.updated_unix = self.clock()
        self._changed()
        return h

    def on_position(self, p: TrackPoint, min_step_s: float = 1.0) -> bool:
        """Add a track point (at most one per ``min_step_s``); True when kept.

        The track is saved with the next change, or every 10 s.
        """
        with self._lock:
            if self.track and p.t_unix - self.track[-1].t_unix < min_step_s:
                return False
            self.track.append(p)
            if len(self.track) > _TRACK_MAX:
                del self.track[: len(self.track) - _TRACK_MAX]
            save = self.clock() - self._last_track_save > 10.0
        if save:
            self._changed()
        else:
            with self._lock:
                self.version += 1
            for fn in list(self.listeners):
                try:
                    fn(self.version)
                except Exception:
                    _log.exception("state listener failed")
        return True


def _opt(v: Any) -> float | None:
    try:
        return None if v is None else float(v)
    except (TypeError, ValueError):
        return None
