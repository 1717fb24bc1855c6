"""Files a reprocessed flight (or a campaign) leaves for the ground crew and for people.

:func:`write_hole_outputs` writes the hole files (``NAME_holes.gpx|.kml|.geojson|.plan``,
the ground crew's formats, :func:`missions.write_hole_file`), the TAK data package
(``NAME_holes_datapackage.zip``: the holes with their pictures and the map overlay
``NAME_map.kmz`` when this run wrote one, :func:`ground.station.write_datapackage`) and
the HTML report (:func:`ground.write_report`); :class:`FlightResult` is one flight's numbers, also
written as ``NAME_reprocess.json``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from holescan.flightlog import jsonable
from holescan.geotag import CIRCLE_95_PER_SIGMA, FOUND_TIERS, AnnounceGate, Hole, VehiclePose
from holescan.ground.flightholes.views import render_thumbnail
from holescan.ground.report.page import write_report
from holescan.ground.reprocessing.options import HoleMatch, ReprocessOptions
from holescan.ground.station.datapackage import ground_hole_of, write_datapackage
from holescan.missions import HOLE_SUFFIXES, write_hole_file
from holescan.outputs import output_via_part

__all__ = ["FlightResult", "write_hole_outputs"]

_Box = tuple[int, int, int, int]


@dataclasses.dataclass(frozen=True)
class FlightResult:
    """What reprocessing did for one flight.

    name : the flight's name (log prefix). sources : its log files. outputs : the sidecar
    MCAP written. files : (kind, path) of the hole files, report and JSON summary.
    frames_read : complete frames in the log; frames_detected : frames detected and merged;
    frames_unposed : of those with detections, frames no pose could be found for.
    holes : every hole (sorted by id), with the flight's ids (:func:`geotag.carry_ids`).
    tiers : hole id -> tier (the one gate, :meth:`geotag.AnnounceGate.tiers`, then the
        operators' marks); :attr:`found` are the holes found (:data:`geotag.FOUND_TIERS`).
    new_ids : ids of the holes only reprocessing found (above every id the flight used).
    flight_holes : the log's own final hole list (what the flight found).
    flight_matches : each hole the flight found (announced or for review) and the
        reprocessed hole with its id (indices into ``flight found`` and :attr:`holes`;
        distance between them); flight_same_ids : of those, found again.
    flight_tiers : the tiers the flight itself gave its holes (its last record; empty for
        a log that predates recorded tiers); :attr:`tier_changes` compares them.
    truncated : files cut off or damaged, in words (read up to their last good chunk).
    interrupted : stopped early; the outputs hold what was done.
    partitions, partitions_cached : tasks of this flight, and how many came from the cache.
    detect_ms_mean : worker time per frame. elapsed_s : wall clock of the whole run up to
    this flight's end. map_summary, map_lines : the search map's figures (searched
    fraction, gaps, re-fly; empty without a map). frames_no_depth : frames without any
    depth reading (closer than the sensor's range, e.g. on the ground), counted apart from
    detect_errors.
    """

    name: str
    sources: tuple[Path | str, ...]
    outputs: tuple[Path, ...]
    files: tuple[tuple[str, Path], ...]
    frames_read: int
    frames_detected: int
    frames_unposed: int
    detections: int
    detect_errors: int
    holes: tuple[Hole, ...]
    tiers: Mapping[int, str]
    new_ids: tuple[int, ...]
    flight_holes: tuple[Hole, ...]
    flight_matches: tuple[HoleMatch, ...]
    flight_same_ids: int
    flight_tiers: Mapping[int, str]
    truncated: tuple[str, ...]
    interrupted: bool
    partitions: int
    partitions_cached: int
    detect_ms_mean: float
    elapsed_s: float
    map_summary: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    map_lines: tuple[str, ...] = ()
    frames_no_depth: int = 0

    @property
    def found(self) -> tuple[Hole, ...]:
        """The holes found (announced, for review, confirmed by an operator)."""
        return tuple(h for h in self.holes if self.tiers.get(h.id) in FOUND_TIERS)

    @property
    def for_crew(self) -> tuple[Hole, ...]:
        """The holes the crew's files hold: found ones and those an operator rejected
        (shown as rejected); never candidates."""
        return tuple(h for h in self.holes if self.tiers.get(h.id, "candidate") != "candidate")

    @property
    def tier_changes(self) -> tuple[tuple[int, str, str], ...]:
        """(hole id, the flight's tier, the reprocessed tier) of each of the flight's holes
        whose tier differs now, by id: a candidate the flight never showed that now reaches
        the crew, a hole it delivered that no longer passes (or is no longer found: "not
        found"). Holes only reprocessing found are :attr:`new_ids`, not here. Empty for a
        log that predates recorded tiers (nothing to compare with)."""
        now = {h.id: self.tiers.get(h.id, "candidate") for h in self.holes}
        changes = []
        for i, before in sorted(self.flight_tiers.items()):
            after = now.get(i, "not found")
            if before != after and not (before == "candidate" and after == "not found"):
                changes.append((i, before, after))
        return tuple(changes)

    @property
    def frames_per_s(self) -> float:
        return self.frames_detected / self.elapsed_s if self.elapsed_s > 0 else 0.0

    def summary(self) -> dict[str, Any]:
        """The numbers, as JSON-ready values."""
        found = [m for m in self.flight_matches if m.found is not None]
        return {
            "flight": self.name,
            "sources": [str(p) for p in self.sources],
            "outputs": [str(p) for p in self.outputs],
            "files": {kind: str(path) for kind, path in self.files},
            "frames_read": self.frames_read,
            "frames_detected": self.frames_detected,
            "frames_unposed": self.frames_unposed,
            "detections": self.detections,
            "detect_errors": self.detect_errors,
            "frames_no_depth": self.frames_no_depth,
            "holes_found": len(self.found),
            "holes_found_means": "announced + for review + confirmed by an operator",
            "tiers": self._counts(),
            "holes_tracked": len(self.holes),
            "new_in_reprocessing": list(self.new_ids),
            "flight_found": len(self.flight_matches),
            "flight_reproduced": len(found),
            "flight_same_ids": self.flight_same_ids,
            "flight_max_offset_m": max((m.distance_m for m in found), default=None),
            "tier_changes": [
                {"hole_id": i, "flight": a, "reprocessed": b} for i, a, b in self.tier_changes
            ],
            "truncated": list(self.truncated),
            "interrupted": self.interrupted,
            "partitions": self.partitions,
            "partitions_cached": self.partitions_cached,
            "detect_ms_mean": round(self.detect_ms_mean, 2),
            "elapsed_s": round(self.elapsed_s, 2),
            "holes": [self._hole_json(h) for h in self.for_crew],
            "map": dict(self.map_summary),
        }

    def _counts(self) -> dict[str, int]:
        return {t: sum(v == t for v in self.tiers.values()) for t in _ALL_TIERS}

    def _hole_json(self, h: Hole) -> dict[str, Any]:
        d = jsonable(h)
        d["tier"] = self.tiers.get(h.id, "candidate")
        d["frames"] = d.pop("sightings")  # frames it was detected in; views: viewpoints
        d["r95_m"] = CIRCLE_95_PER_SIGMA * h.sigma_h_m if math.isfinite(h.sigma_h_m) else None
        d["found_in_flight"] = h.id not in self.new_ids
        return dict(d)

    def lines(self) -> list[str]:
        """A short human summary."""
        cut = f", {len(self.truncated)} file(s) cut off or damaged" if self.truncated else ""
        stop = " INTERRUPTED" if self.interrupted else ""
        found = [m for m in self.flight_matches if m.found is not None]
        worst = max((m.distance_m for m in found), default=math.nan)
        out = [
            f"{self.name}:{stop} {self.frames_detected}/{self.frames_read} frames "
            f"({self.partitions_cached}/{self.partitions} partitions from the cache){cut}; "
            f"{len(self.found)} holes found (announced + for review + confirmed: "
            + ", ".join(f"{n} {t}" for t, n in self._counts().items() if n)
            + ")",
            f"  holes the flight found, found again with their ids: {self.flight_same_ids}/"
            f"{len(self.flight_matches)}"
            + (f" (farthest {worst:.2f} m)" if found else "")
            + "; found only by reprocessing: "
            + (", ".join(f"hole {i}" for i in self.new_ids) or "none"),
        ]
        if self.tier_changes:
            out.append(
                "  tiers changed from the flight's: "
                + ", ".join(f"hole {i} {a} -> {b}" for i, a, b in self.tier_changes)
            )
        out += [f"  {t}" for t in self.truncated]
        out += list(self.map_lines)
        out += [f"  wrote {path} ({kind})" for kind, path in self.files]
        out += [f"  wrote {p} (sidecar mcap: open it with the logs)" for p in self.outputs]
        return out


_ALL_TIERS = ("announced", "review", "confirmed", "rejected", "candidate")


def _hole_files(
    out: Path,
    name: str,
    holes: Sequence[Hole],
    opts: ReprocessOptions,
    thumbnails: Mapping[int, bytes],
    home: tuple[float, float, float] | None,
    boot_to_unix_ns: int | None,
    tiers: Mapping[int, str],
) -> list[tuple[str, Path]]:
    written: list[tuple[str, Path]] = []
    holes = [h for h in holes if tiers.get(h.id, "candidate") != "candidate"]
    if not holes:
        return written
    for fmt in opts.formats:
        path = out / f"{name}_holes{HOLE_SUFFIXES[fmt]}"
        with output_via_part(path, force=True, fsync=True) as tmp:  # a rerun replaces it
            write_hole_file(
                tmp,
                holes,
                fmt,
                home=home,
                thumbnails=thumbnails,
                boot_to_unix_ns=boot_to_unix_ns,
                rel_alt_m=opts.rel_alt_m,
                clearance_m=opts.clearance_m,
                name=f"holescan holes: {name}",
                tiers=tiers,
            )
        written.append((fmt, path))
    return written


def _datapackage(
    out: Path,
    name: str,
    holes: Sequence[Hole],
    thumbnails: Mapping[int, bytes],
    boot_to_unix_ns: int | None,
    overlay: Path | None,
) -> list[tuple[str, Path]]:
    if not holes:
        return []
    path = write_datapackage(
        out / f"{name}_holes_datapackage.zip",
        [ground_hole_of(h, boot_to_unix_ns) for h in holes],
        thumbnails,
        station=name,
        name=f"holescan holes: {name}",
        overlay=overlay,
    )
    return [("datapackage", path)]


def write_hole_outputs(
    out: Path,
    name: str,
    holes: Sequence[Hole],
    views: Mapping[int, tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], _Box]],
    track: Sequence[VehiclePose],
    *,
    opts: ReprocessOptions | None = None,
    home: tuple[float, float, float] | None = None,
    boot_to_unix_ns: int | None = None,
    truth: Sequence[tuple[str, float, float]] = (),
    facts: Mapping[str, str] | None = None,
    title: str | None = None,
    track_breaks: Sequence[int] = (),
    search_map: str | None = None,
    overlay: Path | None = None,
    tiers: Mapping[int, str] | None = None,
) -> list[tuple[str, Path]]:
    """Write a flight's hole files (``NAME_holes.*``), TAK data package
    (``NAME_holes_datapackage.zip``) and report (``NAME_report.html``).

    holes : the holes to write (confirmed ones). views : hole id -> (rgb, depth, box) of
    its best view, the box (x, y, w, h) in that picture's pixels. track : vehicle poses.
    truth : (name, lat_deg, lon_deg) drawn on the report's map. track_breaks : where in
    ``track`` another flight starts (a campaign). search_map : the report's search-map
    section. overlay : the map overlay (``.kmz``) this run wrote, for the data package
    (None: none; a ``NAME_map.kmz`` left in ``out`` by an earlier run is not taken).
    tiers : hole id ->
    ``announced``, ``review``, ``confirmed``, ``rejected`` or ``candidate`` (default: the
    vehicle's :meth:`geotag.AnnounceGate.tier` with its default thresholds); candidates
    are in no file (not even the report: every file here may reach a crew), holes for
    review not in the TAK data package. Returns (kind, path) pairs.
    """
    opts = opts or ReprocessOptions()
    if tiers is None:
        gate = AnnounceGate()
        tiers = {h.id: gate.tier(h) for h in holes}
    holes = [h for h in holes if tiers.get(h.id, "candidate") != "candidate"]
    wanted = {h.id for h in holes}
    jpegs = {
        hid: render_thumbnail(rgb, depth, box)[0]
        for hid, (rgb, depth, box) in views.items()
        if hid in wanted
    }
    written = _hole_files(out, name, holes, opts, jpegs, home, boot_to_unix_ns, tiers)
    for_tak = [h for h in holes if tiers.get(h.id) in ("announced", "confirmed")]
    written += _datapackage(out, name, for_tak, jpegs, boot_to_unix_ns, overlay)
    report_holes = [
        dataclasses.replace(h, best_box=views[h.id][2]) if h.id in views else h for h in holes
    ]
    report_views = {h.id: (views[h.id][0], views[h.id][1]) for h in holes if h.id in views}
    path = write_report(
        out / f"{name}_report.html",
        title=title or f"holescan flight report: {name}",
        holes=report_holes,
        track=track,
        views=report_views,
        truth=truth,
        facts=facts,
        track_breaks=track_breaks,
        search_map=search_map,
        tiers=tiers,
    )
    written.append(("report", path))
    return written
