"""The ground station's memory: holes, their pictures, the operator's marks, the track,
the vehicles heard.

Everything ``holescan ground`` learns is kept here and written to ``DIR/station.json``
after every change, pictures to ``DIR/cards/hole-ID.jpg`` (:mod:`.statefile`: the output
rule, batched under a flood: a few at once, then at most one every ``save_every_s``; the
last change always reaches the file; :meth:`StationState.flush` at the end); an
operator's mark is written at once. A restart reads it back, so a link drop, a restart or
a second sortie loses nothing, and holes keep the vehicle's ids.

Every value from the link is checked before it is kept (:mod:`link._values`:
finite, in range, ids in the protocol's range, text XML can hold); a refused one is
counted in ``rejected`` and logged, and nothing of its packet is kept. At most
``max_holes`` holes are kept (a flood of forged ids cannot exhaust memory or bury a
genuine hole: the genuine one sent later still has room).

A hole is known from any of: the vehicle's STATUSTEXT ``HOLE <id> <score> <lat> <lon>``
(fast, 50 bytes), its card (picture + facts, :func:`missions.read_card`), the hole mission
downloaded from component 191. Later facts update earlier ones; the operator's mark
(``new`` / ``confirmed`` / ``rejected`` / ``visited``) is the ground's own and never
overwritten by the vehicle. Several vehicles' reports make one hole per opening
(:mod:`.openings`). ``version`` counts changes (the live page and the files follow it).
The records themselves: :mod:`.records`.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from holescan.errors import InputError
from holescan.geotag import LocalFrame, nearest_pairs
from holescan.ground.station.openings import Openings
from holescan.ground.station.records import MARKS, GroundHole, HoleSource, TrackPoint
from holescan.ground.station.statefile import StateFile, WriteBudget
from holescan.ground.station.vehicles import VehicleStatus
from holescan.link import LinkValueError, card_values, read_hole_text, xml_text
from holescan.missions import NO_PICTURE, card_picture, with_picture

__all__ = ["StationState"]

_log = logging.getLogger(__name__)

_TRACK_MAX = 20_000
_TRACK_SAVE_NS = 10 * 10**9
_NS_PER_S = 1_000_000_000


@dataclass
class StationState:
    """Holes, marks and tracks of one ground station, persisted in ``folder``.

    ``listeners`` are called (without the lock held) after every change with the new
    version; the web page's event stream and the file writers hang on them. ``clock`` is
    the Unix clock in ns (the holes' and track's times).

    Each hole report names its vehicle (``sysid``; None: the station's first); the
    station's holes, one per opening and their ids: :class:`openings.Openings`. A hole's
    picture and "why" are its newest card's.
    """

    folder: Path
    track: list[TrackPoint] = field(default_factory=list)
    version: int = 0
    listeners: list[Callable[[int], None]] = field(default_factory=list)
    clock: Callable[[], int] = time.time_ns
    save_every_s: float = 0.5
    save_burst: int = 5
    rejected: int = 0
    vehicles: dict[int, VehicleStatus] = field(default_factory=dict)
    """The vehicles heard (live; :mod:`ground.station.vehicles`), by system id."""
    openings: Openings = field(default_factory=Openings)
    """The holes, one per opening across vehicles (:mod:`.openings`)."""
    _lock: threading.RLock = field(default_factory=threading.RLock)
    _last_track_save_ns: int = 0
    _unsaved: bool = False
    _timer: threading.Timer | None = None
    _last_point_ns: dict[int, int] = field(default_factory=dict)
    _file: StateFile = field(init=False)
    _budget: WriteBudget = field(init=False)

    def __post_init__(self) -> None:
        self._file = StateFile(self.folder)
        self._budget = WriteBudget(self.save_every_s, self.save_burst)

    @property
    def holes(self) -> dict[int, GroundHole]:
        """The holes by station id (live; read them under no lock with :meth:`snapshot`)."""
        return self.openings.holes

    @property
    def primary_sysid(self) -> int | None:
        """The first vehicle that reported a hole (its ids are the station's)."""
        return self.openings.primary_sysid

    @property
    def max_holes(self) -> int:
        """Holes kept at most (:data:`openings.MAX_HOLES`)."""
        return self.openings.max_holes

    @max_holes.setter
    def max_holes(self, n: int) -> None:
        self.openings.max_holes = n

    @property
    def path(self) -> Path:
        return self._file.path

    def card_path(self, hole_id: int) -> Path:
        return self._file.card_path(hole_id)

    @classmethod
    def open(cls, folder: Path) -> StationState:
        """The state kept in ``folder`` (created when new).

        Raises
        ------
        InputError : the folder cannot be created.
        StationFileError : its ``station.json`` is not a ground station file.
        """
        state = cls(folder)
        state._file.make()
        if state.path.exists():
            kept = state._file.read()
            state.version = kept.version
            state.openings.primary_sysid = kept.primary_sysid
            for h in kept.holes:
                state.openings.keep(h)
            state.track = kept.track
            _log.info("resumed %d holes from %s", len(state.holes), state.path)
        return state

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

    def track_sysids(self) -> set[int]:
        """The vehicles (system ids) with points in the track (0: a point of an older
        state file, whose vehicle is not known)."""
        with self._lock:
            return {p.sysid for p in self.track}

    def vehicle_snapshot(self) -> list[VehicleStatus]:
        """Copies of the vehicles heard, by system id."""
        with self._lock:
            return [v.copy() for _, v in sorted(self.vehicles.items())]

    # -- changes ------------------------------------------------------------------------
    def _changed(self, *, save_now: bool = False) -> None:
        with self._lock:
            self.version += 1
            version = self.version
            if save_now or self._budget.take():
                self._save()
            else:
                self._save_later()
        self._tell(version)

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
        self._file.write(
            self.version, self.primary_sysid, [h for _, h in sorted(self.holes.items())],
            self.track,
        )  # fmt: skip
        self._unsaved = False
        self._last_track_save_ns = self.clock()

    # -- several vehicles, one id per opening (:mod:`.openings`) ------------------------------
    def _source(
        self, sysid: int | None, own: int, lat: float, lon: float
    ) -> tuple[GroundHole, HoleSource, bool] | None:
        """The station hole and vehicle part for vehicle ``sysid``'s hole ``own``
        (:meth:`Openings.source`); None: no room, or an id that cannot be given (counted
        in ``rejected``)."""
        try:
            return self.openings.source(sysid, own, lat, lon, self.clock())
        except LinkValueError as err:
            self.reject("a hole", err)
            return None

    def _fold(self, h: GroundHole, moved: HoleSource) -> GroundHole:
        """Set ``h``'s facts from its vehicles' (:meth:`Openings.fold`); the picture of a
        hole folded into another goes with it. Returns the hole that remains."""
        h, gone = self.openings.fold(h, moved, self.clock())
        if gone is not None and gone.has_picture and not h.has_picture:
            try:
                self.card_path(gone.id).replace(self.card_path(h.id))
                h.has_picture, h.why = True, gone.why
            except OSError as err:
                _log.warning("hole %d's picture not moved: %s", gone.id, err)
        return h

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
                self._file.write_card(h.id, jpeg)
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
            sid = self.openings.sysid(sysid)
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
            sid = self.openings.sysid(sysid)
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
