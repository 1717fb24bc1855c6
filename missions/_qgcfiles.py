"""QGroundControl files: WPL 110 (tab separated) and the ``.plan`` JSON."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.missions._waypoint import (
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    PLAN_DATA_KEY,
    Waypoint,
    default_home,
    fmt_ll,
    fmt_num,
    json_safe,
    open_text,
    round_ll,
)

__all__ = ["read_plan", "read_wpl", "write_plan", "write_wpl"]

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
    home = home if home is not None else default_home(items)
    lines = ["QGC WPL 110"]
    rows = [replace(home, frame=MAV_FRAME_GLOBAL, command=MAV_CMD_NAV_WAYPOINT), *items]
    for seq, w in enumerate(rows):
        lat, lon = (w.lat_deg, w.lon_deg) if w.has_position else (0.0, 0.0)
        fields = [
            str(seq),
            "1" if seq == 0 else "0",
            str(w.frame),
            str(w.command),
            *(fmt_num(p) for p in w.params),
            fmt_ll(lat),
            fmt_ll(lon),
            fmt_num(w.alt_m if w.has_position else 0.0),
            "1" if w.autocontinue else "0",
        ]
        lines.append("\t".join(fields))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_wpl(path: str | Path) -> tuple[Waypoint, list[Waypoint]]:
    """Read a QGC WPL 110 file; returns ``(home, items)`` (items are seq 1..N)."""
    path = Path(path)
    text = open_text(path)
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
        params += [round_ll(w.lat_deg), round_ll(w.lon_deg), w.alt_m]
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
        item[PLAN_DATA_KEY] = {
            "name": w.name,
            "description": w.description,
            "properties": json_safe(dict(w.properties)),
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
    home = home if home is not None else default_home(items)
    polygons = []
    if fence:
        ring = [[round_ll(lat), round_ll(lon)] for lat, lon in fence]
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
                round_ll(home.lat_deg),
                round_ll(home.lon_deg),
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
        doc = json.loads(open_text(path))
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
            data = item.get(PLAN_DATA_KEY) or {}
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
