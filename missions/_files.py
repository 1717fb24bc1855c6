"""Waypoint records and the files ground crews use: QGC ``.plan``, QGC WPL 110, KML, GeoJSON, GPX.

The writers are generic over a sequence of :class:`Waypoint` records, so a survey mission
and a list of found holes are written by the same code. Every writer has a reader, so each
format round-trips (the tests rely on it). Latitudes and longitudes are written with 8
decimals (about 1 mm).
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.missions._geofiles import (
    ns_of,
    parse_coord_text,
    parse_kml,
    read_geojson,
    read_gpx,
    read_kml,
    write_geojson,
    write_gpx,
    write_kml,
)
from holescan.missions._qgcfiles import read_plan, read_wpl, write_plan, write_wpl
from holescan.missions._waypoint import Area, Waypoint, open_text

__all__ = ["read_area", "read_waypoints", "write_waypoints"]

# ----------------------------------------------------------------------------- dispatch

_WRITERS = {
    ".plan": "plan",
    ".waypoints": "wpl",
    ".wpl": "wpl",
    ".txt": "wpl",
    ".kml": "kml",
    ".geojson": "geojson",
    ".json": "geojson",
    ".gpx": "gpx",
}


def write_waypoints(
    path: str | Path,
    items: Sequence[Waypoint],
    home: Waypoint | None = None,
    *,
    name: str = "holescan",
    area: Area | None = None,
    path_line: bool = True,
) -> Path:
    """Write ``items`` in the format the file extension names.

    ``.plan`` (QGC), ``.waypoints``/``.wpl``/``.txt`` (QGC WPL 110), ``.kml``,
    ``.geojson``/``.json``, ``.gpx``. ``path_line`` adds the flight path to KML/GeoJSON
    (and a route to GPX); ``area`` adds the survey polygon to KML and as a fence to .plan.
    """
    path = Path(path)
    kind = _WRITERS.get(path.suffix.lower())
    line_name = name if path_line else None
    if kind == "plan":
        return write_plan(path, items, home, fence=area.outer if area else ())
    if kind == "wpl":
        return write_wpl(path, items, home)
    if kind == "kml":
        return write_kml(path, items, document_name=name, path_name=line_name, area=area)
    if kind == "geojson":
        return write_geojson(path, items, path_name=line_name)
    if kind == "gpx":
        return write_gpx(path, items, route_name=line_name)
    known = ", ".join(sorted(_WRITERS))
    raise InputError(f"{path}: unknown waypoint file type {path.suffix!r}; use one of {known}")


def read_waypoints(path: str | Path) -> list[Waypoint]:
    """Read mission items / points from any format :func:`write_waypoints` writes."""
    path = Path(path)
    kind = _WRITERS.get(path.suffix.lower())
    if kind == "plan":
        return read_plan(path)[1]
    if kind == "wpl":
        return read_wpl(path)[1]
    if kind == "kml":
        return read_kml(path)
    if kind == "geojson":
        return read_geojson(path)
    if kind == "gpx":
        return read_gpx(path)
    raise InputError(f"{path}: unknown waypoint file type {path.suffix!r}")


# ----------------------------------------------------------------------------- areas


def _ring_from_lonlat(
    coords: Sequence[Sequence[float]], where: str
) -> tuple[tuple[float, float], ...]:
    try:
        ring = [(float(c[1]), float(c[0])) for c in coords]
    except (TypeError, ValueError, IndexError) as err:
        raise InputError(f"{where}: bad polygon coordinates ({err})") from err
    if len(ring) >= 2 and ring[0] == ring[-1]:
        ring = ring[:-1]
    return tuple(ring)


def _area_from_geojson(doc: Any, where: str) -> Area:
    polys: list[Any] = []

    def collect(obj: Any) -> None:
        kind = obj.get("type") if isinstance(obj, dict) else None
        if kind == "FeatureCollection":
            for f in obj.get("features", []):
                collect(f)
        elif kind == "Feature":
            collect(obj.get("geometry") or {})
        elif kind == "GeometryCollection":
            for g in obj.get("geometries", []):
                collect(g)
        elif kind == "Polygon":
            polys.append(obj["coordinates"])
        elif kind == "MultiPolygon":
            polys.extend(obj["coordinates"])

    collect(doc)
    if not polys:
        raise InputError(f"{where}: no Polygon in this GeoJSON (the area must be a polygon)")
    if len(polys) > 1:
        raise InputError(f"{where}: {len(polys)} polygons; plan one area at a time")
    rings = polys[0]
    if not rings:
        raise InputError(f"{where}: the polygon has no coordinates (empty area)")
    return Area(
        _ring_from_lonlat(rings[0], where),
        tuple(_ring_from_lonlat(r, where) for r in rings[1:]),
    )


def _area_from_kml(root: ET.Element, where: str) -> Area:
    ns = ns_of(root)
    q = (lambda t: f"{{{ns}}}{t}") if ns else (lambda t: t)
    polys = list(root.iter(q("Polygon")))
    if not polys:
        raise InputError(f"{where}: no Polygon in this KML (the area must be a polygon)")
    if len(polys) > 1:
        raise InputError(f"{where}: {len(polys)} polygons; plan one area at a time")

    def ring(elem: ET.Element | None) -> tuple[tuple[float, float], ...]:
        text = elem.findtext(f"{q('LinearRing')}/{q('coordinates')}") if elem is not None else ""
        return _ring_from_lonlat(parse_coord_text(text, where), where)

    poly = polys[0]
    holes = tuple(ring(e) for e in poly.findall(q("innerBoundaryIs")))
    return Area(ring(poly.find(q("outerBoundaryIs"))), holes)


def _area_from_text(text: str, where: str) -> Area:
    pts = []
    for chunk in re.split(r"[;\n]", text):
        chunk = chunk.split("#", 1)[0].strip()
        if not chunk:
            continue
        parts = [p for p in re.split(r"[,\s]+", chunk) if p]
        if len(parts) != 2:
            raise InputError(f"{where}: expected 'lat,lon' per point, got {chunk!r}")
        try:
            pts.append((float(parts[0]), float(parts[1])))
        except ValueError as err:
            raise InputError(f"{where}: expected 'lat,lon' numbers, got {chunk!r}") from err
    if len(pts) >= 2 and pts[0] == pts[-1]:
        pts = pts[:-1]
    return Area(tuple(pts))


def read_area(source: str | Path) -> Area:
    """Read a survey polygon from GeoJSON, KML, a text file of ``lat,lon`` lines, or a string.

    A string that is not an existing file is parsed as ``"lat,lon; lat,lon; ..."``.
    Only the ring is read here; :func:`missions.plan_survey` checks that it is a valid,
    non-empty polygon.
    """
    path = Path(source)
    if not path.is_file():
        text = str(source)
        if ";" in text or "\n" in text:
            return _area_from_text(text, "area")
        raise InputError(f"area file not found: {source}")
    suffix = path.suffix.lower()
    if suffix in {".geojson", ".json"}:
        try:
            doc = json.loads(open_text(path))
        except json.JSONDecodeError as err:
            raise InputError(f"{path}: not JSON ({err})") from err
        return _area_from_geojson(doc, str(path))
    if suffix == ".kml":
        return _area_from_kml(parse_kml(path), str(path))
    return _area_from_text(open_text(path), str(path))
