"""What a reprocessing run or campaign is asked to do, and how far it is.

:class:`ReprocessOptions` (the detector, the engine, the outputs), :class:`Progress`
(what the progress bar shows) and :func:`match_points` (in-flight holes against
reprocessed ones). Pure: no files, no clocks.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np

from holescan.detect import DEFAULT, DetectParams
from holescan.errors import InputError
from holescan.geotag import AnnounceGate, Hole, LocalFrame, nearest_pairs
from holescan.ground.station.marks import StationMark, marks_for_flight, strongest_mark
from holescan.missions import Area, HoleFormat

__all__ = ["TOPICS", "HoleMatch", "Progress", "ReprocessOptions", "match_points"]

TOPICS: Final = ("detections", "detections/annotations", "holes", "holes/geojson")
"""The topics reprocessing writes, under ``ReprocessOptions.topic_prefix``."""


def _finite_params(params: DetectParams) -> None:
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if isinstance(value, float) and math.isnan(value):
            raise InputError(f"detector setting {f.name} is NaN: give a number")
    if not 0.0 <= params.min_score <= 1.0:
        raise InputError(f"min_score must be in [0, 1], got {params.min_score}")


@dataclasses.dataclass(frozen=True)
class ReprocessOptions:
    """How flights are reprocessed.

    params : detector parameters (mode, searcher, thresholds); NaN settings are refused.
    workers : Dask worker processes of the local cluster (one thread each); 0 runs every
        partition in this process, in order (no cluster).
    scheduler : address of an existing Dask scheduler (``tcp://HOST:8786``); ``workers``
        is then ignored. Every worker must read the log paths (a shared folder) or URLs.
    partition_mib : log bytes per task (the chunks of a log are grouped up to this).
    frames : ``all`` frames of the log, or only those the flight's own detector processed
        (``flight``: the frames its ``/detections`` records name, merged in their order;
        all frames are still detected, only those are merged).
    min_sightings : holes written to the hole files (and counted as confirmed).
    formats : hole files to write. rel_alt_m, clearance_m : altitude of ``plan``/``wpl``.
    topic_prefix : topics of the sidecar MCAP files.
    cache : keep finished partitions in ``OUT/.holescan-cache`` and reuse them.
    storage_options : passed to ``fsspec`` for URLs (credentials stay out of the logs).
    map_cell_m : the search map's cells (None: no map); map_every : fuse every n-th frame.
    gap_threshold : coverage below which the map's cells are gaps.
    area : the planned area (None: the hull of what was seen), for gaps and searched fraction.
    announce_min_p_hole, review_min_p_hole : the thresholds of the tiers of the reprocessed
        holes (:class:`geotag.AnnounceGate`); None: the flight's own, as its log records
        them (:meth:`gate_for`).
    marks : the operators' marks by hole id (``confirmed``, ``rejected``, ``visited``),
        applied by id alone to every flight's holes (one flight; the holes keep the
        flight's ids); they decide those holes' tiers in every output.
    station_marks : the marks of station folders
        (:func:`ground.station.marks.read_station_marks`, any number of stations), each
        applied to the flight whose own hole has its id at its place
        (:func:`ground.station.marks.marks_for_flight`), in a campaign through each
        flight's ids to the campaign's (:meth:`marks_for`).
    """

    params: DetectParams = DEFAULT
    workers: int = dataclasses.field(default_factory=lambda: os.cpu_count() or 1)
    scheduler: str | None = None
    partition_mib: float = 32.0
    frames: Literal["all", "flight"] = "all"
    min_sightings: int = 2
    formats: tuple[HoleFormat, ...] = ("gpx", "kml", "geojson", "plan")
    rel_alt_m: float = 10.0
    clearance_m: float = 5.0
    topic_prefix: str = "/reprocess"
    cache: bool = True
    storage_options: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    map_cell_m: float | None = 0.02
    map_every: int = 3
    gap_threshold: float = 0.5
    area: Area | None = None
    announce_min_p_hole: float | None = None
    review_min_p_hole: float | None = None
    marks: Mapping[int, str] = dataclasses.field(default_factory=dict)
    station_marks: tuple[StationMark, ...] = ()

    def __post_init__(self) -> None:
        self.gate_for(None)  # refuses thresholds outside [0, 0.99]
        if self.map_cell_m is not None and not (
            math.isfinite(self.map_cell_m) and 0.005 <= self.map_cell_m <= 1.0
        ):
            raise InputError(f"map cell must be 0.005-1 m, got {self.map_cell_m}")
        if not 1 <= self.map_every <= 1000:
            raise InputError(f"map_every must be 1-1000 frames, got {self.map_every}")
        if not (math.isfinite(self.gap_threshold) and 0.0 < self.gap_threshold < 1.0):
            raise InputError(f"gap threshold must be between 0 and 1, got {self.gap_threshold}")
        if self.workers < 0 or self.min_sightings < 1:
            raise InputError("workers must be >= 0 and min_sightings >= 1")
        if not self.partition_mib > 0 or not math.isfinite(self.partition_mib):
            raise InputError(f"partition_mib must be a positive number, got {self.partition_mib}")
        if self.frames not in ("all", "flight"):
            raise InputError(f"frames must be 'all' or 'flight', got {self.frames!r}")
        if not self.topic_prefix.startswith("/") or self.topic_prefix.endswith("/"):
            raise InputError(f"topic_prefix must look like /name, got {self.topic_prefix!r}")
        if self.scheduler is not None and "://" not in self.scheduler:
            raise InputError(f"scheduler must look like tcp://HOST:8786, got {self.scheduler!r}")
        _finite_params(self.params)

    @property
    def partition_bytes(self) -> int:
        return max(1, round(self.partition_mib * (1 << 20)))

    def gate_for(self, recorded: AnnounceGate | None) -> tuple[AnnounceGate, str]:
        """The gate that gives the reprocessed holes their tiers, and where it comes from.

        recorded : the flight's gate as its log records it (None: the log predates recorded
            tiers, and the default gate stands in). The thresholds given here replace its.
        """
        gate = recorded or AnnounceGate()
        source = "the flight's" if recorded is not None else "default (not in the log)"
        given = []
        if self.announce_min_p_hole is not None:
            gate = dataclasses.replace(gate, min_p_hole=self.announce_min_p_hole)
            given.append(f"announced p_hole >= {self.announce_min_p_hole:g}")
        if self.review_min_p_hole is not None:
            gate = dataclasses.replace(gate, review_min_p_hole=self.review_min_p_hole)
            given.append(f"review p_hole >= {self.review_min_p_hole:g}")
        if given:
            source += ", " + " and ".join(given) + " given"
        return gate, source

    def marks_for(self, flight_holes: Sequence[Hole]) -> dict[int, str]:
        """Hole id -> the operators' mark for one flight whose own holes (the vehicle's ids
        and positions) are ``flight_holes``: :attr:`marks` by id, and every station mark
        that is this flight's (:func:`ground.station.marks.marks_for_flight`); one hole
        marked twice takes :func:`~ground.station.marks.strongest_mark`."""
        got = marks_for_flight(self.station_marks, flight_holes)
        for hid, mark in self.marks.items():
            got[hid] = strongest_mark([mark, got.get(hid, "")]) or mark
        return got

    def settings_key(self) -> dict[str, Any]:
        """What decides a partition's result besides the log bytes (the cache key)."""
        return {"params": repr(self.params), "map": [self.map_cell_m, self.map_every]}


@dataclasses.dataclass(frozen=True)
class Progress:
    """Where a run is. ``partitions_cached`` of the done ones came from the cache."""

    partitions_done: int
    partitions_total: int
    partitions_cached: int
    frames_done: int
    flights_done: int
    flights: int
    elapsed_s: float
    dashboard: str | None = None

    @property
    def fraction(self) -> float:
        return self.partitions_done / self.partitions_total if self.partitions_total else 1.0

    @property
    def frames_per_s(self) -> float:
        return self.frames_done / self.elapsed_s if self.elapsed_s > 0 else 0.0


@dataclasses.dataclass(frozen=True)
class HoleMatch:
    """A reference point (truth, or a hole of the flight) and the nearest found hole.

    reference : index into the reference list. found : index into the found list, or None
    when nothing lies within the distance. distance_m : horizontal distance (NaN if None).
    """

    reference: int
    found: int | None
    distance_m: float


def match_points(
    reference: Sequence[tuple[float, float]],
    found: Sequence[tuple[float, float]],
    max_distance_m: float,
) -> list[HoleMatch]:
    """Pair each reference (lat_deg, lon_deg) with at most one found point, nearest pairs
    first (a found point serves one reference; :func:`geotag.nearest_pairs`), within
    ``max_distance_m`` (local metres around the first reference, :class:`geotag.LocalFrame`).

    Returns one :class:`HoleMatch` per reference, in reference order.

    Examples
    --------
    >>> [m.found for m in match_points([(43.0, -79.0)], [(43.1, -79.0), (43.0, -79.0)], 1.0)]
    [1]
    """
    pairs: list[tuple[float, int, int]] = []
    if reference and found:
        frame = LocalFrame(*reference[0])
        re_, rn = frame.to_en([p[0] for p in reference], [p[1] for p in reference])
        fe, fn = frame.to_en([p[0] for p in found], [p[1] for p in found])
        dist = np.hypot(re_[:, None] - fe[None, :], rn[:, None] - fn[None, :])
        pairs = [
            (float(dist[i, j]), i, j)
            for i in range(len(reference))
            for j in range(len(found))
            if dist[i, j] <= max_distance_m
        ]
    taken_ref = nearest_pairs(pairs)
    return [
        HoleMatch(i, taken_ref[i][0], taken_ref[i][1])
        if i in taken_ref
        else HoleMatch(i, None, math.nan)
        for i in range(len(reference))
    ]


def out_folder(out: str | os.PathLike[str], inputs: Sequence[Path]) -> Path:
    """Check the output folder before any work: not a file, writable, not an input's
    folder. Created when missing. Raises :class:`InputError`."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise InputError(f"{path} is a file: --out takes a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"cannot create the output folder {path}: {err.strerror}") from err
    if not os.access(path, os.W_OK | os.X_OK):
        raise InputError(f"cannot write into the output folder {path} (read-only?)")
    here = path.resolve()
    for p in inputs:
        if p.resolve().parent == here:
            raise InputError(f"{p} is a source log in {path}: choose another --out folder")
    return path
