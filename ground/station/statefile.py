"""The files the station keeps in its folder: ``station.json`` and ``cards/hole-ID.jpg``.

``station.json`` holds the holes, the track, the version and the station's first vehicle;
it is written through the output-path rule (:func:`outputs.atomic_output`: written to
``.station.part.json``, flushed, fsynced, renamed: a crash or a power cut leaves the
previous or the new file, never half of one), pictures to ``cards/hole-ID.jpg`` the same
way. Writes are batched under a flood (:class:`WriteBudget`).

A state file is checked when it is read back as values from the link are (the records'
``checked``): a hole whose position is not a number on the Earth is left out, a bad
optional fact is forgotten, each with one log line, and the file as it was is kept beside
as ``station.rejected-<time>.json``. A file of an older station (``holescan-ground-1``) is
read too, and written back in the current format with the next change.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.ground.errors import StationFileError
from holescan.ground.station.records import (
    FORMAT,
    FORMAT_1,
    T_NS_MAX,
    GroundHole,
    TrackPoint,
)
from holescan.link import LinkValueError, link_int
from holescan.outputs import atomic_output

__all__ = ["Kept", "StateFile", "WriteBudget"]

_log = logging.getLogger(__name__)


@dataclass
class Kept:
    """What a state file holds, checked: holes, track, version, the station's first
    vehicle (None: none reported a hole yet)."""

    holes: list[GroundHole] = field(default_factory=list)
    track: list[TrackPoint] = field(default_factory=list)
    version: int = 0
    primary_sysid: int | None = None


@dataclass(frozen=True)
class StateFile:
    """The station's folder and the files in it."""

    folder: Path

    @property
    def path(self) -> Path:
        return self.folder / "station.json"

    def card_path(self, hole_id: int) -> Path:
        return self.folder / "cards" / f"hole-{hole_id}.jpg"

    def make(self) -> None:
        """Create the folder and its ``cards`` (raises InputError when it cannot)."""
        try:
            (self.folder / "cards").mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise InputError(f"cannot create {self.folder}: {err.strerror}") from err

    def read(self) -> Kept:
        """What ``station.json`` holds (nothing when there is none yet).

        Raises
        ------
        StationFileError : it is not a ground station file.
        """
        if not self.path.exists():
            return Kept()
        try:
            doc = json.loads(self.path.read_text())
            fmt = str(doc.get("format", FORMAT_1))
            holes = [GroundHole.from_json(d) for d in doc["holes"]]
            rows = list(doc.get("track", []))
            version = link_int(doc.get("version", 0), 0, T_NS_MAX, "version")
            primary = doc.get("primary_sysid")
            primary_sysid = None if primary is None else link_int(primary, 1, 255, "id")
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
            raise StationFileError(
                f"{self.path} is not a holescan ground station file ({err}); move it away"
            ) from err
        return self._checked(holes, rows, fmt, version, primary_sysid)

    def _checked(
        self,
        holes: list[GroundHole],
        rows: list[Any],
        fmt: str,
        version: int,
        primary_sysid: int | None,
    ) -> Kept:
        """Keep what a state file holds that the link could have given (see the module
        docstring); the file as it was is copied aside when anything was left out."""
        kept = Kept(version=version, primary_sysid=primary_sysid)
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
            kept.holes.append(h)
        for row in rows:
            try:
                kept.track.append(TrackPoint.from_json(row, fmt))
            except (LinkValueError, ValueError, TypeError, OverflowError):
                problems += 1
        if len(kept.track) < len(rows):
            _log.warning("%s: %d track points left out", self.path, len(rows) - len(kept.track))
        if problems:
            aside = self.folder / f"station.rejected-{time.time_ns()}.json"
            try:
                aside.write_bytes(self.path.read_bytes())
                _log.warning("%s kept as it was in %s", self.path.name, aside.name)
            except OSError as err:
                _log.warning("%s not copied aside: %s", self.path, err)
        return kept

    def write(
        self,
        version: int,
        primary_sysid: int | None,
        holes: list[GroundHole],
        track: list[TrackPoint],
    ) -> None:
        """Write ``station.json`` in the current format (strict JSON: every value was
        checked when it came)."""
        doc = {
            "format": FORMAT,
            "version": version,
            "primary_sysid": primary_sysid,
            "holes": [h.to_json() for h in holes],
            "track": [
                [p.t_unix_ns, p.lat_deg, p.lon_deg, p.rel_alt_m, p.yaw, p.sysid] for p in track
            ],
        }
        text = json.dumps(doc, separators=(",", ":"), allow_nan=False)
        with atomic_output(self.path, force=True) as f:
            f.write(text.encode())

    def write_card(self, hole_id: int, jpeg: bytes) -> None:
        """Keep hole ``hole_id``'s card (its JPEG) in ``cards/``."""
        with atomic_output(self.card_path(hole_id), force=True) as f:
            f.write(jpeg)


@dataclass
class WriteBudget:
    """A token bucket for the state file's writes: ``burst`` at once, then one per
    ``every_s`` (monotonic clock)."""

    every_s: float = 0.5
    burst: int = 5
    _tokens: float = field(init=False)
    _t: float = field(default_factory=time.monotonic, init=False)

    def __post_init__(self) -> None:
        self._tokens = float(self.burst)

    def take(self) -> bool:
        """Whether a write may happen now (and it is counted)."""
        now = time.monotonic()
        self._tokens = min(float(self.burst), self._tokens + (now - self._t) / self.every_s)
        self._t = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False
