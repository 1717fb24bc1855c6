"""Where the flight did not search well enough: gap polygons, the searched fraction, a re-fly.

* **surveyed area**: the planned area when given, else the convex hull of every cell seen;
* **gaps**: the parts of it whose coverage is below a threshold (default 0.5), polygons
  from the raster (GDAL's polygonize through ``rasterio.features.shapes``) in local metres,
  ``shapely`` for areas and clipping. Strips narrower than ``min_width_m`` (default 0.4 m,
  under the smallest access hole's inscribed disk, 0.42 m for a person) are opened away: an
  opening cannot lie inside them unseen, its rim would be in the covered cells around;
* **re-fly**: a survey over the gaps only through :func:`missions.plan_survey` (its
  altitude rules, the flight's own altitude), one lawnmower per gap, chained into one
  mission; its duration checked against the day's dawn/dusk sun windows.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import rasterio.features
import shapely
from affine import Affine
from shapely.geometry import MultiPoint, Polygon, mapping, shape
from shapely.ops import unary_union

from holescan.errors import InputError
from holescan.geotag import LocalFrame
from holescan.mapping import MapLayers
from holescan.missions import Area, SurveyParams, SurveyPlan, Waypoint, plan_survey
from holescan.outputs import atomic_output

__all__ = [
    "GapReport",
    "Refly",
    "find_gaps",
    "gaps_document",
    "plan_refly",
    "write_gaps_geojson",
]


@dataclass(frozen=True)
class GapReport:
    """The gaps of one map.

    threshold : coverage below which a cell is a gap. area : the surveyed area (local
    metres); planned : whether it was the planned area (else the hull of what was seen).
    searched_m2 : the part of it covered at least ``threshold``; gaps : the gap polygons,
    largest first, with their mean coverage.
    """

    threshold: float
    area: Polygon
    planned: bool
    searched_m2: float
    gaps: tuple[Polygon, ...]
    gap_coverage: tuple[float, ...]

    @property
    def area_m2(self) -> float:
        return float(self.area.area)

    @property
    def searched_fraction(self) -> float:
        return self.searched_m2 / self.area_m2 if self.area_m2 > 0 else 0.0

    @property
    def gap_m2(self) -> float:
        return float(sum(g.area for g in self.gaps))


def _transform(layers: MapLayers) -> Affine:
    g = layers.grid
    return Affine(g.cell_m, 0.0, g.west_m, 0.0, -g.cell_m, g.north_m)


def find_gaps(
    layers: MapLayers,
    area: Polygon | None = None,
    *,
    threshold: float = 0.5,
    min_width_m: float = 0.4,
    min_area_m2: float = 0.1,
) -> GapReport:
    """The gaps of ``layers`` inside ``area`` (local metres; None: the hull of the seen cells)."""
    g = layers.grid
    t = _transform(layers)
    planned = area is not None
    if area is None:
        rows, cols = np.nonzero(layers.looks > 0)
        if len(rows) < 3:
            return GapReport(threshold, Polygon(), False, 0.0, (), ())
        e = g.west_m + (cols + 0.5) * g.cell_m
        n = g.north_m - (rows + 0.5) * g.cell_m
        area = MultiPoint(np.column_stack([e, n])).convex_hull
        if not isinstance(area, Polygon):
            return GapReport(threshold, Polygon(), False, 0.0, (), ())
    inside = rasterio.features.geometry_mask([mapping(area)], g.shape, t, invert=True)
    cov = layers.coverage
    covered = (cov >= threshold) & inside
    searched = float(np.count_nonzero(covered)) * g.cell_m**2
    low = (inside & ~covered).astype(np.uint8)
    r = max(1, round(min_width_m / 2 / g.cell_m))
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    low = cv2.morphologyEx(low, cv2.MORPH_OPEN, disk)
    polys: list[Polygon] = []
    for geom, value in rasterio.features.shapes(low, mask=low.astype(bool), transform=t):
        if value != 1:
            continue
        p = shape(geom).intersection(area)
        for part in getattr(p, "geoms", [p]):
            if isinstance(part, Polygon) and part.area >= min_area_m2:
                polys.append(shapely.simplify(part, g.cell_m, preserve_topology=True))
    polys.sort(key=lambda p: -p.area)
    means = []
    for p in polys:
        m = rasterio.features.geometry_mask([mapping(p)], g.shape, t, invert=True)
        means.append(float(cov[m].mean()) if m.any() else 0.0)
    return GapReport(threshold, area, planned, searched, tuple(polys), tuple(means))


def _ring_ll(frame: LocalFrame, coords: Any) -> list[list[float]]:
    xy = np.asarray(coords, dtype=np.float64)
    lat, lon = frame.to_geodetic(xy[:, 0], xy[:, 1])
    return [[round(float(a), 8), round(float(b), 8)] for a, b in zip(lon, lat, strict=True)]


def _poly_ll(frame: LocalFrame, p: Polygon) -> dict[str, Any]:
    rings = [_ring_ll(frame, p.exterior.coords)]
    rings += [_ring_ll(frame, r.coords) for r in p.interiors]
    return {"type": "Polygon", "coordinates": rings}


def gaps_document(report: GapReport, frame: LocalFrame) -> dict[str, Any]:
    """The gaps as a GeoJSON FeatureCollection: each gap a Polygon feature (``area_m2``,
    ``mean_coverage``), and the surveyed area as a feature of its own (``kind:
    "surveyed area"``); ``frame`` is the local frame of the report's metres."""
    feats: list[dict[str, Any]] = []
    for k, (p, c) in enumerate(zip(report.gaps, report.gap_coverage, strict=True), start=1):
        feats.append(
            {
                "type": "Feature",
                "geometry": _poly_ll(frame, p),
                "properties": {
                    "kind": "gap",
                    "gap": k,
                    "area_m2": round(float(p.area), 3),
                    "mean_coverage": round(c, 4),
                    "threshold": report.threshold,
                },
            }
        )
    if not report.area.is_empty:
        feats.append(
            {
                "type": "Feature",
                "geometry": _poly_ll(frame, report.area),
                "properties": {
                    "kind": "surveyed area",
                    "source": "planned area" if report.planned else "hull of the cells seen",
                    "area_m2": round(report.area_m2, 3),
                    "searched_m2": round(report.searched_m2, 3),
                    "searched_fraction": round(report.searched_fraction, 4),
                    "gaps": len(report.gaps),
                    "gap_m2": round(report.gap_m2, 3),
                    "threshold": report.threshold,
                },
            }
        )
    return {"type": "FeatureCollection", "features": feats}


def write_gaps_geojson(
    path: Path, report: GapReport, frame: LocalFrame, *, force: bool = True
) -> Path:
    """``NAME_gaps.geojson``: :func:`gaps_document`."""
    doc = gaps_document(report, frame)
    with atomic_output(path, force=force) as f:
        f.write((json.dumps(doc, indent=1) + "\n").encode())
    return path


@dataclass(frozen=True)
class Refly:
    """A re-fly over the gaps: one plan per gap area, chained into one mission."""

    plans: tuple[SurveyPlan, ...]
    items: tuple[Waypoint, ...]
    home: Waypoint
    duration_s: float
    areas: tuple[Area, ...]
    skipped: tuple[str, ...] = ()
    """Gap areas the planner refused (too small or thin for its rules), in words."""


def plan_refly(
    gaps: Sequence[Polygon],
    frame: LocalFrame,
    params: SurveyParams,
    *,
    merge_within_m: float = 1.0,
) -> Refly | None:
    """Survey the gaps again (None when there are none, or the planner refuses them all).
    Gaps closer than ``merge_within_m`` are flown as one area (the hull of their union grown
    by half that)."""
    if not gaps:
        return None
    grown = unary_union([p.buffer(merge_within_m / 2) for p in gaps])
    parts = [p for p in getattr(grown, "geoms", [grown]) if isinstance(p, Polygon)]
    areas: list[Area] = []
    plans: list[SurveyPlan] = []
    skipped: list[str] = []
    for p in sorted(parts, key=lambda q: (-q.centroid.y, q.centroid.x)):
        hull = p.convex_hull
        if not isinstance(hull, Polygon) or hull.is_empty:
            continue
        xy = np.asarray(hull.exterior.coords)[:-1]
        lat, lon = frame.to_geodetic(xy[:, 0], xy[:, 1])
        area = Area(tuple((float(a), float(b)) for a, b in zip(lat, lon, strict=True)))
        try:
            plan = plan_survey(area, params)
        except InputError as err:  # the planner's rules refuse it: said, not flown
            skipped.append(
                f"{hull.area:.1f} m2 at ({hull.centroid.x:.1f}, {hull.centroid.y:.1f}) m: {err}"
            )
            continue
        areas.append(area)
        plans.append(plan)
    if not plans:
        return None
    first = plans[0].mission_items()
    path = [w for pl in plans for w in pl.path]
    items = (first[0], first[1], *path, first[-1])
    duration = sum(pl.duration_s for pl in plans)  # each with its climb: an upper bound
    return Refly(tuple(plans), items, plans[0].home, duration, tuple(areas), tuple(skipped))
