"""A reprocessed flight's (or a campaign's) search map: merged windows -> files and figures.

The partitions' windows are merged (:func:`mapchunk.merge_flight_maps`) and written beside
the hole files (:func:`ground.searchmap.write_map_outputs`: GeoTIFFs, KMZ, gaps, re-fly);
the report gets the map's section. The re-fly keeps the flight's altitude (the median of
its track above home, within the planner's altitude band) and is checked against the sun
windows of the day the flight was flown.
"""

from __future__ import annotations

import dataclasses
import logging
import statistics
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from shapely.geometry import Polygon

from holescan.errors import InputError
from holescan.geotag import Hole, LocalFrame, VehiclePose
from holescan.ground.report.searchmap import search_map_section
from holescan.ground.reprocessing.mapchunk import merge_flight_maps
from holescan.ground.reprocessing.options import ReprocessOptions
from holescan.mapping import MapLayers
from holescan.missions import Area, SurveyParams
from holescan.utc import utc_datetime

__all__ = ["MapResult", "area_polygon", "flight_map_outputs"]

_log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class MapResult:
    """What the map of one flight gave: files, report section, summary, lines to print."""

    files: tuple[tuple[str, Path], ...]
    section: str | None
    summary: dict[str, Any]
    lines: tuple[str, ...]

    @property
    def overlay(self) -> Path | None:
        """The ``NAME_map.kmz`` this flight's map wrote (None: none)."""
        return next((path for kind, path in self.files if kind == "map"), None)


def area_polygon(area: Area, frame: LocalFrame) -> Polygon:
    """An area (WGS84) as a polygon in ``frame``'s east/north metres."""

    def ring(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
        e, n = frame.to_en([p[0] for p in points], [p[1] for p in points])
        return [(float(x), float(y)) for x, y in zip(e, n, strict=True)]

    return Polygon(ring(area.outer), [ring(h) for h in area.holes])


def _survey(track: Sequence[VehiclePose], home: tuple[float, float, float] | None) -> SurveyParams:
    base = SurveyParams()
    lo, hi = base.altitude_band()
    rel = [p.rel_alt_m for p in track if np.isfinite(p.rel_alt_m) and p.rel_alt_m > 0.5]
    alt = min(max(statistics.median(rel), lo), hi) if rel else base.altitude_m
    return dataclasses.replace(
        base,
        altitude_m=round(alt, 2),
        home=(home[0], home[1]) if home else None,
        home_amsl_m=home[2] if home else 0.0,
    )


def flight_map_outputs(
    out: Path,
    name: str,
    parts: Sequence[MapLayers],
    anchor: tuple[float, float, float],
    holes: Sequence[Hole],
    opts: ReprocessOptions,
    *,
    track: Sequence[VehiclePose],
    home: tuple[float, float, float] | None,
    boot_to_unix_ns: int | None,
    pose_gap_m: Sequence[float] = (),
    map_s: float = 0.0,
    map_frames: int = 0,
    tiers: Mapping[int, str] | None = None,
) -> MapResult:
    """Merge the windows and write the map's files (nothing when nothing was seen)."""
    cell = opts.map_cell_m or 0.02
    layers = merge_flight_maps(parts, cell)
    if layers is None:
        return MapResult((), None, {"map": "no posed frame"}, ("  map: no posed frame",))
    frame = LocalFrame(*anchor)
    try:
        from holescan.ground.searchmap import write_map_outputs
    except ImportError:  # rasterio is the ground extra
        line = "  map: not written (GeoTIFFs need rasterio: pip install 'holescan[ground]')"
        return MapResult((), None, {"map": "rasterio missing"}, (line,))
    area = area_polygon(opts.area, frame) if opts.area is not None else None
    day = None
    if boot_to_unix_ns is not None and track:
        day = utc_datetime(track[0].t_boot_ns + boot_to_unix_ns).date()
    try:
        res = write_map_outputs(
            out,
            name,
            layers,
            frame,
            holes,
            area=area,
            threshold=opts.gap_threshold,
            survey=_survey(track, home),
            day=day,
            boot_to_unix_ns=boot_to_unix_ns,
            tiers=tiers,
        )
    except InputError as err:  # e.g. a file that cannot be written
        _log.warning("%s: map files: %s", name, err)
        return MapResult((), None, {"map": str(err)}, (f"  map: {err}",))
    gap = sorted(pose_gap_m)
    notes = []
    if gap:
        notes.append(
            f"Frames were placed by the pose logged with each (the flight's); it differs from "
            f"the re-interpolated pose the holes use by median {gap[len(gap) // 2]:.3f} m, "
            f"max {gap[-1]:.3f} m over {len(gap)} frames."
        )
    g = res.gaps
    section = search_map_section(
        layers,
        frame,
        holes,
        searched_fraction=g.searched_fraction,
        area_m2=g.area_m2,
        planned=g.planned,
        threshold=g.threshold,
        gaps=g.gaps,
        notes=notes,
    )
    summary = {
        "cell_m": cell,
        "frames_fused": map_frames,
        "fuse_s": round(map_s, 2),
        "grid": [layers.grid.nx, layers.grid.ny],
        "area_m2": round(g.area_m2, 2),
        "area_source": "planned" if g.planned else "hull of the cells seen",
        "searched_fraction": round(g.searched_fraction, 4),
        "gap_threshold": g.threshold,
        "gaps": len(g.gaps),
        "gap_m2": round(g.gap_m2, 2),
        "pose_gap_m_median": round(gap[len(gap) // 2], 4) if gap else None,
        "pose_gap_m_max": round(gap[-1], 4) if gap else None,
        "refly_lines": sum(len(p.lines) for p in res.refly.plans) if res.refly else 0,
        "refly_sun": res.sun,
    }
    return MapResult(res.files, section, summary, tuple(res.lines()))
