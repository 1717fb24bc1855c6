"""Every file of a flight's search map, written together (reprocess, campaign, demo)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from shapely.geometry import Polygon

from holescan.geotag import Hole, LocalFrame
from holescan.ground.searchmap.gaps import (
    GapReport,
    Refly,
    find_gaps,
    plan_refly,
    write_gaps_geojson,
)
from holescan.ground.searchmap.geotiff import write_map_geotiffs
from holescan.ground.searchmap.kmz import write_map_kmz
from holescan.mapping import MapLayers
from holescan.missions import SurveyParams, check_flight, sun_day, write_waypoints
from holescan.outputs import output_via_part

__all__ = ["MapOutputs", "write_map_outputs"]


@dataclass(frozen=True)
class MapOutputs:
    """What was written: (kind, path) files, the gaps and the re-fly (None: no gap)."""

    files: tuple[tuple[str, Path], ...]
    gaps: GapReport
    refly: Refly | None
    sun: str

    def lines(self) -> list[str]:
        g = self.gaps
        out = [
            f"  searched {g.searched_fraction:.1%} of the {'planned' if g.planned else 'surveyed'}"
            f" area ({g.searched_m2:.1f} of {g.area_m2:.1f} m2 at coverage >= {g.threshold:g});"
            f" {len(g.gaps)} gaps, {g.gap_m2:.1f} m2"
        ]
        if self.refly is not None:
            out.append(
                f"  re-fly: {sum(len(p.lines) for p in self.refly.plans)} lines over "
                f"{len(self.refly.plans)} gap areas, about {self.refly.duration_s / 60:.1f} min; "
                f"{self.sun}"
            )
            out += [f"  re-fly: not planned: {s}" for s in self.refly.skipped]
        return out


def write_map_outputs(
    folder: Path,
    name: str,
    layers: MapLayers,
    frame: LocalFrame,
    holes: Sequence[Hole],
    *,
    area: Polygon | None = None,
    threshold: float = 0.5,
    survey: SurveyParams | None = None,
    day: dt.date | None = None,
    boot_to_unix_ns: int | None = None,
    force: bool = True,
    tiers: Mapping[int, str] | None = None,
) -> MapOutputs:
    """``NAME_ortho.tif``, ``NAME_dsm.tif``, ``NAME_coverage.tif``, ``NAME_map.kmz``,
    ``NAME_gaps.geojson`` and, when there are gaps, ``NAME_refly.plan`` and
    ``NAME_refly.waypoints`` (QGC WPL) in ``folder``.

    ``area`` is the planned area in the frame's metres (None: the hull of what was seen);
    ``survey`` the parameters of the re-fly (the flight's altitude), ``day`` the day whose
    sun windows it is checked against. ``tiers``: the holes' tiers for the KMZ
    (:func:`write_map_kmz`: candidates left out).
    """
    files = write_map_geotiffs(folder, name, layers, frame, force=force)
    kmz = write_map_kmz(
        folder / f"{name}_map.kmz",
        name,
        layers,
        frame,
        holes,
        boot_to_unix_ns=boot_to_unix_ns,
        force=force,
        tiers=tiers,
    )
    files.append(("map", kmz))
    gaps = find_gaps(layers, area, threshold=threshold)
    files.append(
        ("gaps", write_gaps_geojson(folder / f"{name}_gaps.geojson", gaps, frame, force=force))
    )
    refly = plan_refly(gaps.gaps, frame, survey or SurveyParams()) if gaps.gaps else None
    sun = ""
    if refly is not None:
        for suffix in (".plan", ".waypoints"):
            path = folder / f"{name}_refly{suffix}"
            with output_via_part(path, force=force) as tmp:
                write_waypoints(tmp, list(refly.items), refly.home, name=f"holescan re-fly {name}")
            files.append((f"refly{suffix}", path))
        when = day or dt.datetime.now(dt.UTC).date()
        sd = sun_day(frame.lat0_deg, frame.lon0_deg, when)
        fit = check_flight(sd.windows, refly.duration_s, None)
        sun = f"sun {when.isoformat()}: {fit.message}"
    return MapOutputs(tuple(files), gaps, refly, sun)
