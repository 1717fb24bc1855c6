"""The holes of a logged flight as the ground crew's files.

:func:`export_flight_holes` reads a flight log once (:func:`read_flight_holes`) and writes
GPX/KML/KMZ/GeoJSON/.plan/WPL files with :func:`missions.write_hole_file`, each through
the output-path rule (:func:`outputs.output_via_part`).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from holescan.errors import InputError
from holescan.geotag import Hole
from holescan.ground.flightholes.read import (
    FlightHoles,
    flight_log_files,
    log_stem,
    read_flight_holes,
)
from holescan.missions import HOLE_FORMATS, HOLE_SUFFIXES, HoleFormat, rank_holes, write_hole_file
from holescan.outputs import check_output, output_via_part

__all__ = ["ExportReport", "default_out_path", "export_flight_holes"]


@dataclasses.dataclass(frozen=True)
class ExportReport:
    """What :func:`export_flight_holes` did.

    flight : what was read. exported : the holes written (by confidence).
    files : (format, path) of each file written.
    """

    flight: FlightHoles
    exported: tuple[Hole, ...]
    files: tuple[tuple[HoleFormat, Path], ...]

    def lines(self) -> list[str]:
        """A short human summary, one line per file."""
        f = self.flight
        head = (
            f"{len(self.exported)} of {len(f.holes)} holes from {len(f.paths)} file(s), "
            f"{len(f.thumbnails)} thumbnail(s), home: {f.home_source}"
        )
        if f.truncated:
            head += f"; {len(f.truncated)} file(s) cut off, read up to their last chunk"
        how = (
            "the flight's" if f.gate_recorded else "default gate (the log predates recorded tiers)"
        )
        gate = f"tiers: {how}: {f.gate.summary()}"
        return [head, gate, *(f"wrote {path} ({fmt})" for fmt, path in self.files)]


def default_out_path(log: Path, fmt: HoleFormat) -> Path:
    """``/data/flight_holes.gpx`` for ``/data/flight_0000.mcap`` and format ``gpx``."""
    stem = log_stem(log)
    return stem.with_name(f"{stem.name}_holes{HOLE_SUFFIXES[fmt]}")


def _out_paths(
    log: Path, formats: Sequence[HoleFormat], out: Path | None
) -> list[tuple[HoleFormat, Path]]:
    if out is None:
        return [(fmt, default_out_path(log, fmt)) for fmt in formats]
    if out.is_dir():
        return [(fmt, out / default_out_path(log, fmt).name) for fmt in formats]
    if len(formats) == 1:
        return [(formats[0], out)]
    return [(fmt, out.with_suffix(HOLE_SUFFIXES[fmt])) for fmt in formats]


def export_flight_holes(
    logs: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    formats: Iterable[HoleFormat],
    *,
    out: str | os.PathLike[str] | None = None,
    min_sightings: int = 2,
    rel_alt_m: float = 10.0,
    clearance_m: float = 5.0,
    thumb_height_px: int = 160,
    force: bool = False,
) -> ExportReport:
    """Write the holes of a logged flight to ground-crew files.

    Parameters
    ----------
    logs : the flight log (see :func:`flight_log_files`).
    formats : any of ``gpx``, ``kml``, ``kmz``, ``geojson``, ``plan``, ``wpl``.
    out : output file (one format), or a path whose suffix is replaced per format, or an
        existing directory; default: ``<log prefix>_holes.<ext>`` next to the log.
    min_sightings : export only holes seen in at least this many frames.
    rel_alt_m, clearance_m : mission altitude for ``plan``/``wpl`` (see
        :func:`missions.hole_mission`).
    thumb_height_px : thumbnail height for ``kml``/``kmz``.
    force : replace existing output files (never a ``.mcap`` or one of the logs). Each file
        is written as ``.NAME.part.EXT`` and renamed when complete.

    Raises
    ------
    InputError : unknown format, bad log, no holes record, or no hole seen often enough.
    """
    fmts: list[HoleFormat] = []
    for fmt in formats:
        if fmt not in HOLE_FORMATS:
            raise InputError(f"unknown format {fmt!r}; use one of {', '.join(HOLE_FORMATS)}")
        if fmt not in fmts:
            fmts.append(fmt)
    if not fmts:
        raise InputError("no output format given")
    if min_sightings < 1:
        raise InputError(f"min_sightings must be >= 1, got {min_sightings}")
    files = flight_log_files(logs)
    targets = _out_paths(files[0], fmts, None if out is None else Path(out))
    for _fmt, path in targets:  # before reading: a bad output costs no time
        check_output(path, inputs=files, force=force)
    need_pictures = any(f in ("kml", "kmz") for f in fmts)
    flight = read_flight_holes(logs, thumbnails=need_pictures, thumb_height_px=thumb_height_px)
    if not flight.holes:
        raise InputError(f"{flight.paths[0]}: the flight found no holes (its hole list is empty)")
    gate, tiers = flight.gate, flight.tiers  # the flight's own (default gate for old logs)
    seen = tuple(h for h in flight.holes if h.sightings >= min_sightings)
    if not seen:
        most = max(h.sightings for h in flight.holes)
        raise InputError(
            f"none of the {len(flight.holes)} holes was seen in >= {min_sightings} frames "
            f"(at most {most}); lower --min-sightings to export them"
        )
    keep = tuple(h for h in seen if tiers[h.id] != "candidate")  # candidates: not for the crew
    if not keep:
        raise InputError(
            f"none of the {len(seen)} holes seen in >= {min_sightings} frames is announced or "
            f"for review (p_hole >= {gate.review_min_p_hole}): no file for the crew"
        )
    jpegs = {hid: t.jpeg for hid, t in flight.thumbnails.items()}
    name = f"holescan holes: {log_stem(flight.paths[0]).name}"
    written = []
    for fmt, path in targets:
        with output_via_part(path, inputs=files, force=force, fsync=True) as tmp:
            write_hole_file(
                tmp,
                keep,
                fmt,
                home=flight.home,
                thumbnails=jpegs,
                boot_to_unix_ns=flight.boot_to_unix_ns,
                rel_alt_m=rel_alt_m,
                clearance_m=clearance_m,
                name=name,
                tiers={h.id: tiers[h.id] for h in keep},
            )
        written.append((fmt, path))
    return ExportReport(flight, tuple(rank_holes(keep)), tuple(written))
