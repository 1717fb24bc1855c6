"""Waypoint records and the files ground crews use: QGC ``.plan``, QGC WPL 110, KML, GeoJSON, GPX.

The writers are generic over a sequence of :class:`Waypoint` records, so a survey mission
and a list of found holes are written by the same code. Every writer has a reader, so each
format round-trips (the tests rely on it). Latitudes and longitudes are written with 8
decimals (about 1 mm).
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from holescan_errors import InputError
from missions._link import mavlink

__all__ = [
    "MAV_CMD_DO_CHANGE_SPEED",
    "MAV_CMD_NAV_LAND",
    "MAV_CMD_NAV_RETURN_TO_LAUNCH",
    "MAV_CMD_NAV_TAKEOFF",
    "MAV_CMD_NAV_WAYPOINT",
    "MAV_FRAME_GLOBAL",
    "MAV_FRAME_GLOBAL_RELATIVE_ALT",
    "MAV_FRAME_MISSION",
    "Area",
    "Waypoint",
    "read_area",
    "read_geojson",
    "read_gpx",
    "read_kml",
    "read_plan",
    "read_waypoints",
    "read_wpl",
    "write_geojson",
    "write_gpx",
    "write_kml",
    "write_plan",
    "write_waypoints",
    "write_wpl",
]

# MAVLink values the files use, from pymavlink's dialect (re-exported for the writers' callers)
MAV_FRAME_GLOBAL: int = mavlink.MAV_FRAME_GLOBAL
MAV_FRAME_MISSION: int = mavlink.MAV_FRAME_MISSION
MAV_FRAME_GLOBAL_RELATIVE_ALT: int = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
MAV_CMD_NAV_WAYPOINT: int = mavlink.MAV_CMD_NAV_WAYPOINT
MAV_CMD_NAV_RETURN_TO_LAUNCH: int = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
MAV_CMD_NAV_LAND: int = mavlink.MAV_CMD_NAV_LAND
MAV_CMD_NAV_TAKEOFF: int = mavlink.MAV_CMD_NAV_TAKEOFF
MAV_CMD_DO_CHANGE_SPEED: int = mavlink.MAV_CMD_DO_CHANGE_SPEED

_KML_NS = "http://www.opengis.net/kml/2.2"
_PLAN_DATA_KEY = "holescan"
_LATLON_DECIMALS = 8


@dataclass(frozen=True)
class Waypoint:
    """One mission item or one point of interest.

    lat_deg, lon_deg : WGS84 degrees (ignored when ``frame`` is ``MAV_FRAME_MISSION``).
    alt_m : metres; above home for ``MAV_FRAME_GLOBAL_RELATIVE_ALT`` (3), above mean sea
        level for ``MAV_FRAME_GLOBAL`` (0).
    name, description : shown by map tools (KML/GeoJSON/GPX).
    properties : extra key/value pairs (JSON-serialisable) carried into GeoJSON/KML.
    command : MAV_CMD (16 = NAV_WAYPOINT); frame : MAV_FRAME.
    params : MAVLink param1..param4 (for NAV_WAYPOINT: hold s, accept radius m, pass
        radius m, yaw deg; NaN = autopilot default).
    autocontinue : go on to the next item when this one is done.
    """

    lat_deg: float
    lon_deg: float
    alt_m: float
    name: str = ""
    description: str = ""
    properties: Mapping[str, Any] = field(default_factory=dict, compare=False, hash=False)
    command: int = MAV_CMD_NAV_WAYPOINT
    frame: int = MAV_FRAME_GLOBAL_RELATIVE_ALT
    params: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    autocontinue: bool = True

    def __post_init__(self) -> None:
        if self.has_position:
            if not (math.isfinite(self.lat_deg) and -90.0 <= self.lat_deg <= 90.0):
                raise InputError(f"latitude must be within -90..90 deg, got {self.lat_deg}")
            if not (math.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
                raise InputError(f"longitude must be within -180..180 deg, got {self.lon_deg}")
            if not math.isfinite(self.alt_m):
                raise InputError(f"altitude must be finite, got {self.alt_m}")
        if len(self.params) != 4:
            raise InputError(f"params must hold param1..param4, got {len(self.params)} values")

    @property
    def has_position(self) -> bool:
        """True when lat/lon/alt mean something (every frame but MAV_FRAME_MISSION)."""
        return self.frame != MAV_FRAME_MISSION


@dataclass(frozen=True)
class Area:
    """A survey area: one polygon, WGS84 degrees.

    outer : ring of (lat_deg, lon_deg), not closed (first vertex not repeated).
    holes : rings cut out of the area (may be empty).
    """

    outer: tuple[tuple[float, float], ...]
    holes: tuple[tuple[tuple[float, float], ...], ...] = ()


# ----------------------------------------------------------------------------- helpers


def _fmt_ll(value: float) -> str:
    return f"{value:.{_LATLON_DECIMALS}f}"


def _fmt_num(value: float) -> str:
    if math.isnan(value):
        return "nan"
    return f"{value:.6f}"


def _round_ll(value: float) -> float:
    return round(value, _LATLON_DECIMALS)


def _positioned(items: Sequence[Waypoint]) -> list[Waypoint]:
    return [w for w in items if w.has_position]


def _default_home(items: Sequence[Waypoint]) -> Waypoint:
    pts = _positioned(items)
    if not pts:
        raise InputError("no positioned waypoint to take a home position from: pass home=")
    return Waypoint(pts[0].lat_deg, pts[0].lon_deg, 0.0, name="home", frame=MAV_FRAME_GLOBAL)


def _open_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except OSError as err:
        raise InputError(f"cannot read {path}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise InputError(f"{path} is not UTF-8 text") from err


def _json_safe(value: Any) -> Any:
    """Plain JSON types for properties (tuples -> lists, numpy scalars -> float/int)."""
    if isinstance(value, Mapping):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if hasattr(value, "item"):
        return _json_safe(value.item())
    return str(value)


# ----------------------------------------------------------------------------- QGC WPL 110


def write_wpl(path: str | Path, items: Sequence[Waypoint], home: Waypoint | None = None) -> Path:
    """Write a QGC WPL 110 file (what MAVProxy's ``wp load`` and Mission Planner read).

    Tab separated ``INDEX CURRENT FRAME COMMAND P1 P2 P3 P4 LAT LON ALT AUTOCONTINUE``;
    line 0 is the home position (frame 0, altitude above mean sea level).

    Parameters
    ----------
    path : output file.
    items : mission items in order (they become seq 1..N).
    home : home position; defaults to the first positioned item at altitude 0.
    """
    path = Path(path)
    home = home if home is not None else _default_home(items)
    lines = ["QGC WPL 110"]
    rows = [replace(home, frame=MAV_FRAME_GLOBAL, command=MAV_CMD_NAV_WAYPOINT), *items]
    for seq, w in enumerate(rows):
        lat, lon = (w.lat_deg, w.lon_deg) if w.has_position else (0.0, 0.0)
        fields = [
            str(seq),
            "1" if seq == 0 else "0",
            str(w.frame),
            str(w.command),
            *(_fmt_num(p) for p in w.params),
            _fmt_ll(lat),
            _fmt_ll(lon),
            _fmt_num(w.alt_m if w.has_position else 0.0),
            "1" if w.autocontinue else "0",
        ]
        lines.append("\t".join(fields))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_wpl(path: str | Path) -> tuple[Waypoint, list[Waypoint]]:
    """Read a QGC WPL 110 file; returns ``(home, items)`` (items are seq 1..N)."""
    path = Path(path)
    text = _open_text(path)
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines or not lines[0].startswith("QGC WPL 110"):
        raise InputError(f"{path}: not a QGC WPL 110 file (first line must be 'QGC WPL 110')")
    rows: list[Waypoint] = []
    for number, line in enumerate(lines[1:], start=2):
        parts = line.split("\t") if "\t" in line else line.split()
        if len(parts) != 12:
            raise InputError(f"{path}:{number}: expected 12 fields, got {len(parts)}")
        try:
            seq, _current, frame, command = (int(p) for p in parts[:4])
            p1, p2, p3, p4, lat, lon, alt = (float(p) for p in parts[4:11])
            autocontinue = int(parts[11]) != 0
        except ValueError as err:
            raise InputError(f"{path}:{number}: {err}") from err
        if seq != len(rows):
            raise InputError(f"{path}:{number}: index {seq} out of order (expected {len(rows)})")
        rows.append(
            Waypoint(
                lat,
                lon,
                alt,
                command=command,
                frame=frame,
                params=(p1, p2, p3, p4),
                autocontinue=autocontinue,
            )
        )
    if not rows:
        raise InputError(f"{path}: no home line")
    return replace(rows[0], name="home"), rows[1:]


# ----------------------------------------------------------------------------- QGC .plan


def _plan_item(w: Waypoint, jump_id: int, item_data: bool = False) -> dict[str, Any]:
    params: list[float | None] = [None if math.isnan(p) else p for p in w.params]
    if w.has_position:
        params += [_round_ll(w.lat_deg), _round_ll(w.lon_deg), w.alt_m]
    else:
        params += [0.0, 0.0, 0.0]
    item: dict[str, Any] = {
        "autoContinue": w.autocontinue,
        "command": w.command,
        "doJumpId": jump_id,
        "frame": w.frame,
        "params": params,
        "type": "SimpleItem",
    }
    if w.frame == MAV_FRAME_GLOBAL_RELATIVE_ALT:
        item.update({"AMSLAltAboveTerrain": None, "Altitude": w.alt_m, "AltitudeMode": 1})
    elif w.frame == MAV_FRAME_GLOBAL:
        item.update({"AMSLAltAboveTerrain": None, "Altitude": w.alt_m, "AltitudeMode": 2})
    if item_data:
        item[_PLAN_DATA_KEY] = {
            "name": w.name,
            "description": w.description,
            "properties": _json_safe(dict(w.properties)),
        }
    return item


def write_plan(
    path: str | Path,
    items: Sequence[Waypoint],
    home: Waypoint | None = None,
    *,
    cruise_speed_m_s: float = 5.0,
    hover_speed_m_s: float = 1.0,
    firmware_type: int = 3,
    vehicle_type: int = 2,
    fence: Sequence[tuple[float, float]] = (),
    item_data: bool = False,
) -> Path:
    """Write a QGroundControl ``.plan`` (JSON, fileType "Plan", mission version 2).

    Parameters
    ----------
    items : mission items, written as ``SimpleItem`` s with doJumpId 1..N.
    home : plannedHomePosition (lat, lon, altitude above mean sea level).
    cruise_speed_m_s, hover_speed_m_s : QGC's default speeds for fixed wing / multirotor.
    firmware_type : MAV_AUTOPILOT (3 = ArduPilot, 12 = PX4).
    vehicle_type : MAV_TYPE (2 = quadrotor).
    fence : optional inclusion geofence ring of (lat, lon).
    item_data : also store each item's name, description and properties in the item, under
        the key ``"holescan"`` (QGC ignores keys it does not know; :func:`read_plan` reads
        them back).
    """
    path = Path(path)
    home = home if home is not None else _default_home(items)
    polygons = []
    if fence:
        ring = [[_round_ll(lat), _round_ll(lon)] for lat, lon in fence]
        polygons.append({"inclusion": True, "polygon": ring, "version": 1})
    doc = {
        "fileType": "Plan",
        "geoFence": {"circles": [], "polygons": polygons, "version": 2},
        "groundStation": "holescan",
        "mission": {
            "cruiseSpeed": cruise_speed_m_s,
            "firmwareType": firmware_type,
            "globalPlanAltitudeMode": 1,
            "hoverSpeed": hover_speed_m_s,
            "items": [_plan_item(w, i, item_data) for i, w in enumerate(items, start=1)],
            "plannedHomePosition": [
                _round_ll(home.lat_deg),
                _round_ll(home.lon_deg),
                home.alt_m,
            ],
            "vehicleType": vehicle_type,
            "version": 2,
        },
        "rallyPoints": {"points": [], "version": 2},
        "version": 1,
    }
    path.write_text(json.dumps(doc, indent=4) + "\n", encoding="utf-8")
    return path


def read_plan(path: str | Path) -> tuple[Waypoint, list[Waypoint]]:
    """Read the SimpleItems of a QGroundControl ``.plan``; returns ``(home, items)``.

    ComplexItems (QGC's own surveys) are refused with a clear error.
    """
    path = Path(path)
    try:
        doc = json.loads(_open_text(path))
        if doc.get("fileType") != "Plan":
            raise InputError(f"{path}: not a QGroundControl plan (fileType is not 'Plan')")
        mission = doc["mission"]
        hlat, hlon, halt = mission["plannedHomePosition"]
        home = Waypoint(
            float(hlat), float(hlon), float(halt or 0.0), name="home", frame=MAV_FRAME_GLOBAL
        )
        items = []
        for n, item in enumerate(mission["items"], start=1):
            if item.get("type") != "SimpleItem":
                raise InputError(f"{path}: item {n} is a {item.get('type')}; only SimpleItem")
            p = [float("nan") if v is None else float(v) for v in item["params"]]
            data = item.get(_PLAN_DATA_KEY) or {}
            items.append(
                Waypoint(
                    p[4],
                    p[5],
                    p[6],
                    name=str(data.get("name", "")),
                    description=str(data.get("description", "")),
                    properties=dict(data.get("properties") or {}),
                    command=int(item["command"]),
                    frame=int(item["frame"]),
                    params=(p[0], p[1], p[2], p[3]),
                    autocontinue=bool(item.get("autoContinue", True)),
                )
            )
    except (KeyError, TypeError, ValueError, IndexError) as err:
        if isinstance(err, InputError):
            raise
        raise InputError(f"{path}: malformed .plan file ({err!r})") from err
    return home, items


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
    props.update(_json_safe(dict(w.properties)))
    return props


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
    features: list[dict[str, Any]] = []
    pts = [(i, w) for i, w in enumerate(items) if w.has_position]
    if path_name is not None and len(pts) >= 2:
        features.append(
            {
                "type": "Feature",
                "geometry": {
                    "type": "LineString",
                    "coordinates": [
                        [_round_ll(w.lon_deg), _round_ll(w.lat_deg), w.alt_m] for _, w in pts
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
                    "coordinates": [_round_ll(w.lon_deg), _round_ll(w.lat_deg)]
                    + ([w.alt_m] if altitude else []),
                },
                "properties": _feature_properties(w, i),
            }
        )
    doc = {"type": "FeatureCollection", "features": features}
    path.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return path


_RESERVED = {"name", "description", "seq", "command", "frame", "alt_m"}


def read_geojson(path: str | Path) -> list[Waypoint]:
    """Read the Point features of a GeoJSON file as waypoints (path lines are skipped)."""
    path = Path(path)
    try:
        doc = json.loads(_open_text(path))
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
    return f"{{{_KML_NS}}}{tag}"


def _kml_coords(points: Sequence[Waypoint]) -> str:
    return " ".join(f"{_fmt_ll(w.lon_deg)},{_fmt_ll(w.lat_deg)},{w.alt_m:.3f}" for w in points)


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
    ET.register_namespace("", _KML_NS)
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
                f"{_fmt_ll(lon)},{_fmt_ll(lat)},0" for lat, lon in closed
            )
    pts = _positioned(items)
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
        extra.update(_json_safe(dict(w.properties)))
        for key, value in extra.items():
            data = ET.SubElement(ext, _kml("Data"), name=str(key))
            ET.SubElement(data, _kml("value")).text = json.dumps(value)
        pt = ET.SubElement(pm, _kml("Point"))
        mode = "absolute" if w.frame == MAV_FRAME_GLOBAL else "relativeToGround"
        ET.SubElement(pt, _kml("altitudeMode")).text = mode
        ET.SubElement(pt, _kml("coordinates")).text = _kml_coords([w])
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def _parse_kml(path: Path) -> ET.Element:
    try:
        return ET.fromstring(_open_text(path))
    except ET.ParseError as err:
        raise InputError(f"{path}: not valid KML/XML ({err})") from err


def _ns_of(root: ET.Element) -> str:
    match = re.match(r"\{([^}]*)\}", root.tag)
    return match.group(1) if match else ""


def _parse_coord_text(text: str | None, where: str) -> list[tuple[float, float, float]]:
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
    root = _parse_kml(path)
    ns = _ns_of(root)
    q = (lambda t: f"{{{ns}}}{t}") if ns else (lambda t: t)
    out = []
    for pm in root.iter(q("Placemark")):
        point = pm.find(q("Point"))
        if point is None:
            continue
        coords = _parse_coord_text(point.findtext(q("coordinates")), str(path))
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
    route = gpxpy.gpx.GPXRoute(name=route_name) if route_name is not None else None
    for w in _positioned(items):
        ele = w.alt_m if w.frame == MAV_FRAME_GLOBAL else None
        kwargs: dict[str, Any] = {
            "latitude": _round_ll(w.lat_deg),
            "longitude": _round_ll(w.lon_deg),
            "elevation": ele,
            "name": w.name or None,
            "description": w.description or None,
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
        gpx = gpxpy.parse(_open_text(path))
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
    ns = _ns_of(root)
    q = (lambda t: f"{{{ns}}}{t}") if ns else (lambda t: t)
    polys = list(root.iter(q("Polygon")))
    if not polys:
        raise InputError(f"{where}: no Polygon in this KML (the area must be a polygon)")
    if len(polys) > 1:
        raise InputError(f"{where}: {len(polys)} polygons; plan one area at a time")

    def ring(elem: ET.Element | None) -> tuple[tuple[float, float], ...]:
        text = elem.findtext(f"{q('LinearRing')}/{q('coordinates')}") if elem is not None else ""
        return _ring_from_lonlat(_parse_coord_text(text, where), where)

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
            doc = json.loads(_open_text(path))
        except json.JSONDecodeError as err:
            raise InputError(f"{path}: not JSON ({err})") from err
        return _area_from_geojson(doc, str(path))
    if suffix == ".kml":
        return _area_from_kml(_parse_kml(path), str(path))
    return _area_from_text(_open_text(path), str(path))
