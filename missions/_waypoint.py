"""The waypoint record and area polygon every mission file shares, and the formatting
helpers of the formats."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.link import mavlink

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

KML_NS = "http://www.opengis.net/kml/2.2"
PLAN_DATA_KEY = "holescan"
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


def fmt_ll(value: float) -> str:
    return f"{value:.{_LATLON_DECIMALS}f}"


def fmt_num(value: float) -> str:
    if math.isnan(value):
        return "nan"
    return f"{value:.6f}"


def round_ll(value: float) -> float:
    return round(value, _LATLON_DECIMALS)


def positioned(items: Sequence[Waypoint]) -> list[Waypoint]:
    return [w for w in items if w.has_position]


def default_home(items: Sequence[Waypoint]) -> Waypoint:
    pts = positioned(items)
    if not pts:
        raise InputError("no positioned waypoint to take a home position from: pass home=")
    return Waypoint(pts[0].lat_deg, pts[0].lon_deg, 0.0, name="home", frame=MAV_FRAME_GLOBAL)


def open_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except OSError as err:
        raise InputError(f"cannot read {path}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise InputError(f"{path} is not UTF-8 text") from err


def json_safe(value: Any) -> Any:
    """Plain JSON types for properties (tuples -> lists, numpy scalars -> float/int)."""
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if hasattr(value, "item"):
        return json_safe(value.item())
    return str(value)
