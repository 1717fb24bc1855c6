"""Map files: GeoJSON, KML and GPX, each with its reader."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.link import xml_safe_tree, xml_text
from holescan.missions._waypoint import (
    KML_NS,
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    Area,
    Waypoint,
    fmt_ll,
    json_safe,
    open_text,
    positioned,
    round_ll,
)

__all__ = [
    "geojson_document",
    "kml_document",
    "read_geojson",
    "read_gpx",
    "read_kml",
    "write_geojson",
    "write_gpx",
    "write_kml",
]

# ----------------------------------------------------------------------------- GeoJSON


def _feature_properties(w: Waypoint, seq: int) -> dict[str, Any]:
    props: dict[str, Any] = {
        "name": w.name,
        "description": w.description,
        "seq": seq,
        "command": w.command,
        "frame": w.frame,
        "alt_m": w.alt_m,
    }
    props.update(json_safe(dict(w.properties)))
    return props


def geojson_document(
    items: Sequence[Waypoint], *, path_name: str | None = None, altitude: bool = True
) -> dict[str, Any]:
    """The GeoJSON FeatureCollection of ``items`` (see :func:`write_geojson`), as a dict."""
    features: list[dict[str, Any]] = []
    pts = [(i, w) for i, w in enumerate(items) if w.has_position]
    if path_name is not None and len(pts) >= 2:
        features.append(
            {
                "type": "Feature",
                "geometry": {
                    "type": "LineString",
                    "coordinates": [
                        [round_ll(w.lon_deg), round_ll(w.lat_deg), w.alt_m] for _, w in pts
                    ],
                },
                "properties": {"name": path_name, "kind": "path"},
            }
        )
    for i, w in pts:
        features.append(
            {
                "type": "Feature",
                "geometry": {
                    "type": "Point",
                    "coordinates": [round_ll(w.lon_deg), round_ll(w.lat_deg)]
                    + ([w.alt_m] if altitude else []),
                },
                "properties": _feature_properties(w, i),
            }
        )
    return {"type": "FeatureCollection", "features": features}


def write_geojson(
    path: str | Path,
    items: Sequence[Waypoint],
    *,
    path_name: str | None = None,
    altitude: bool = True,
) -> Path:
    """Write a GeoJSON FeatureCollection: one Point per positioned item (+ the path line).

    Coordinates are ``[lon, lat, alt]`` (RFC 7946 order). Each point's properties hold
    name, description, seq (its index in ``items``), command, frame, alt_m and the
    waypoint's own ``properties``. With ``path_name``, a LineString through the points in
    order is added first (for a map of the flight path). ``altitude=False`` writes
    ``[lon, lat]`` only (RFC 7946's third value is height above the WGS84 ellipsoid, which
    a mean-sea-level altitude is not); ``alt_m`` stays in the properties.
    """
    path = Path(path)
    doc = geojson_document(items, path_name=path_name, altitude=altitude)
    text = json.dumps(doc, indent=2, allow_nan=False)  # strict: properties made finite above
    path.write_text(text + "\n", encoding="utf-8")
    return path


_RESERVED = {"name", "description", "seq", "command", "frame", "alt_m"}


def read_geojson(path: str | Path) -> list[Waypoint]:
    """Read the Point features of a GeoJSON file as waypoints (path lines are skipped)."""
    path = Path(path)
    try:
        doc = json.loads(open_text(path))
    except json.JSONDecodeError as err:
        raise InputError(f"{path}: not JSON ({err})") from err
    feats = doc.get("features", [doc] if doc.get("type") == "Feature" else [])
    out = []
    for f in feats:
        geom = f.get("geometry") or {}
        if geom.get("type") != "Point":
            continue
        coords = geom["coordinates"]
        props = dict(f.get("properties") or {})
        alt = float(props.get("alt_m", coords[2] if len(coords) > 2 else 0.0))
        out.append(
            Waypoint(
                float(coords[1]),
                float(coords[0]),
                alt,
                name=str(props.get("name", "")),
                description=str(props.get("description", "")),
                properties={k: v for k, v in props.items() if k not in _RESERVED},
                command=int(props.get("command", MAV_CMD_NAV_WAYPOINT)),
                frame=int(props.get("frame", MAV_FRAME_GLOBAL_RELATIVE_ALT)),
            )
        )
    return out


# ----------------------------------------------------------------------------- KML


def _kml(tag: str) -> str:
    return f"{{{KML_NS}}}{tag}"


def _kml_coords(points: Sequence[Waypoint]) -> str:
    return " ".join(f"{fmt_ll(w.lon_deg)},{fmt_ll(w.lat_deg)},{w.alt_m:.3f}" for w in points)


def kml_document(
    items: Sequence[Waypoint],
    *,
    document_name: str = "holescan",
    path_name: str | None = None,
    area: Area | None = None,
) -> ET.Element:
    """The KML 2.2 ``kml`` element of ``items`` (see :func:`write_kml`), XML-safe."""
    ET.register_namespace("", KML_NS)
    root = ET.Element(_kml("kml"))
    doc = ET.SubElement(root, _kml("Document"))
    ET.SubElement(doc, _kml("name")).text = document_name
    if area is not None:
        pm = ET.SubElement(doc, _kml("Placemark"))
        ET.SubElement(pm, _kml("name")).text = "area"
        poly = ET.SubElement(pm, _kml("Polygon"))
        rings = [("outerBoundaryIs", area.outer)] + [("innerBoundaryIs", h) for h in area.holes]
        for tag, ring in rings:
            lr = ET.SubElement(ET.SubElement(poly, _kml(tag)), _kml("LinearRing"))
            closed = [*ring, ring[0]]
            ET.SubElement(lr, _kml("coordinates")).text = " ".join(
                f"{fmt_ll(lon)},{fmt_ll(lat)},0" for lat, lon in closed
            )
    pts = positioned(items)
    if path_name is not None and len(pts) >= 2:
        pm = ET.SubElement(doc, _kml("Placemark"))
        ET.SubElement(pm, _kml("name")).text = path_name
        line = ET.SubElement(pm, _kml("LineString"))
        ET.SubElement(line, _kml("altitudeMode")).text = "relativeToGround"
        ET.SubElement(line, _kml("coordinates")).text = _kml_coords(pts)
    for seq, w in enumerate(items):
        if not w.has_position:
            continue
        pm = ET.SubElement(doc, _kml("Placemark"))
        ET.SubElement(pm, _kml("name")).text = w.name
        if w.description:
            ET.SubElement(pm, _kml("description")).text = w.description
        ext = ET.SubElement(pm, _kml("ExtendedData"))
        extra = {"seq": seq, "command": w.command, "frame": w.frame}
        extra.update(json_safe(dict(w.properties)))
        for key, value in extra.items():
            data = ET.SubElement(ext, _kml("Data"), name=str(key))
            ET.SubElement(data, _kml("value")).text = json.dumps(value)
        pt = ET.SubElement(pm, _kml("Point"))
        mode = "absolute" if w.frame == MAV_FRAME_GLOBAL else "relativeToGround"
        ET.SubElement(pt, _kml("altitudeMode")).text = mode
        ET.SubElement(pt, _kml("coordinates")).text = _kml_coords([w])
    ET.indent(root)
    xml_safe_tree(root)  # no text a reader refuses, whatever a name or description holds
    return root


def write_kml(
    path: str | Path,
    items: Sequence[Waypoint],
    *,
    document_name: str = "holescan",
    path_name: str | None = None,
    area: Area | None = None,
) -> Path:
    """Write KML 2.2: a Placemark per positioned item (+ path line, + area polygon).

    Altitudes are ``relativeToGround`` for frame 3 and ``absolute`` for frame 0. Each
    waypoint's ``properties`` go into ``ExtendedData`` (values as JSON text).
    """
    path = Path(path)
    root = kml_document(items, document_name=document_name, path_name=path_name, area=area)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def parse_kml(path: Path) -> ET.Element:
    try:
        return ET.fromstring(open_text(path))
    except ET.ParseError as err:
        raise InputError(f"{path}: not valid KML/XML ({err})") from err


def ns_of(root: ET.Element) -> str:
    match = re.match(r"\{([^}]*)\}", root.tag)
    return match.group(1) if match else ""


def parse_coord_text(text: str | None, where: str) -> list[tuple[float, float, float]]:
    out = []
    for tok in (text or "").split():
        parts = tok.split(",")
        try:
            lon, lat = float(parts[0]), float(parts[1])
            alt = float(parts[2]) if len(parts) > 2 else 0.0
        except (ValueError, IndexError) as err:
            raise InputError(f"{where}: bad KML coordinate {tok!r}") from err
        out.append((lon, lat, alt))
    return out


def read_kml(path: str | Path) -> list[Waypoint]:
    """Read the Point placemarks of a KML file as waypoints (lines/polygons skipped)."""
    path = Path(path)
    root = parse_kml(path)
    ns = ns_of(root)
    q = (lambda t: f"{{{ns}}}{t}") if ns else (lambda t: t)
    out = []
    for pm in root.iter(q("Placemark")):
        point = pm.find(q("Point"))
        if point is None:
            continue
        coords = parse_coord_text(point.findtext(q("coordinates")), str(path))
        if not coords:
            continue
        lon, lat, alt = coords[0]
        extra: dict[str, Any] = {}
        for data in pm.iter(q("Data")):
            raw = data.findtext(q("value")) or ""
            try:
                extra[data.get("name", "")] = json.loads(raw)
            except json.JSONDecodeError:
                extra[data.get("name", "")] = raw
        mode = point.findtext(q("altitudeMode")) or "relativeToGround"
        default_frame = MAV_FRAME_GLOBAL if mode == "absolute" else MAV_FRAME_GLOBAL_RELATIVE_ALT
        out.append(
            Waypoint(
                lat,
                lon,
                alt,
                name=pm.findtext(q("name")) or "",
                description=pm.findtext(q("description")) or "",
                properties={k: v for k, v in extra.items() if k not in _RESERVED},
                command=int(extra.get("command", MAV_CMD_NAV_WAYPOINT)),
                frame=int(extra.get("frame", default_frame)),
            )
        )
    return out


# ----------------------------------------------------------------------------- GPX


def write_gpx(
    path: str | Path, items: Sequence[Waypoint], *, route_name: str | None = None
) -> Path:
    """Write GPX 1.1 waypoints (for handheld GPS units), optionally also as one route.

    GPX ``ele`` means height above mean sea level, so it is written only for frame-0
    (absolute) items; relative altitudes are not elevations.
    """
    import gpxpy.gpx

    path = Path(path)
    gpx = gpxpy.gpx.GPX()
    gpx.creator = "holescan"
    route = gpxpy.gpx.GPXRoute(name=xml_text(route_name)) if route_name is not None else None
    for w in positioned(items):
        ele = w.alt_m if w.frame == MAV_FRAME_GLOBAL else None
        kwargs: dict[str, Any] = {
            "latitude": round_ll(w.lat_deg),
            "longitude": round_ll(w.lon_deg),
            "elevation": ele,
            "name": xml_text(w.name) or None,  # what XML can hold
            "description": xml_text(w.description) or None,
        }
        gpx.waypoints.append(gpxpy.gpx.GPXWaypoint(**kwargs))
        if route is not None:
            route.points.append(gpxpy.gpx.GPXRoutePoint(**kwargs))
    if route is not None:
        gpx.routes.append(route)
    path.write_text(gpx.to_xml(version="1.1"), encoding="utf-8")
    return path


def read_gpx(path: str | Path) -> list[Waypoint]:
    """Read the ``wpt`` points of a GPX file (elevation, when present, as frame 0)."""
    import gpxpy
    import gpxpy.gpx

    path = Path(path)
    try:
        gpx = gpxpy.parse(open_text(path))
    except gpxpy.gpx.GPXException as err:
        raise InputError(f"{path}: not a GPX file ({err})") from err
    out = []
    for p in gpx.waypoints:
        has_ele = p.elevation is not None
        out.append(
            Waypoint(
                p.latitude,
                p.longitude,
                float(p.elevation) if p.elevation is not None else 0.0,
                name=p.name or "",
                description=p.description or "",
                frame=MAV_FRAME_GLOBAL if has_ele else MAV_FRAME_GLOBAL_RELATIVE_ALT,
            )
        )
    return out
