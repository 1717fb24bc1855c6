"""Survey geometry: the area polygon in local metres, checks, the boustrophedon sweep and
its order."""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from holescan.errors import InputError
from holescan.geotag import LocalFrame
from holescan.missions._waypoint import (
    Area,
)

if TYPE_CHECKING:
    from shapely.geometry import Polygon
    from shapely.geometry.base import BaseGeometry


_HEADING_STEP_DEG = 5.0


# ----------------------------------------------------------------------------- geometry


def polygon_enu(area: Area, frame: LocalFrame) -> Polygon:
    from shapely.geometry import Polygon

    def ring(points: Sequence[tuple[float, float]]) -> npt.NDArray[np.float64]:
        lat, lon = zip(*points, strict=True)
        e, n = frame.to_en(lat, lon)
        return np.column_stack([e, n])

    return Polygon(ring(area.outer), [ring(h) for h in area.holes if len(h) >= 3])


def check_area(area: Area) -> None:
    if len(area.outer) < 3:
        raise InputError(
            f"the area is empty: a polygon needs at least 3 vertices, got {len(area.outer)}"
        )
    for lat, lon in (*area.outer, *(p for h in area.holes for p in h)):
        if not (math.isfinite(lat) and -90.0 <= lat <= 90.0):
            raise InputError(f"area latitude must be within -90..90 deg, got {lat}")
        if not (math.isfinite(lon) and -180.0 <= lon <= 180.0):
            raise InputError(f"area longitude must be within -180..180 deg, got {lon}")


def validate_polygon(poly: Polygon, frame: LocalFrame, max_extent_m: float) -> None:
    import shapely
    from shapely.validation import explain_validity

    # The hull of the vertices (a bow-tie's own hull/area can be 0: GEOS on invalid input).
    hull_m2 = float(shapely.MultiPoint(poly.exterior.coords).convex_hull.area)
    if hull_m2 < 1.0 or (shapely.is_valid(poly) and float(poly.area) < 1.0):
        raise InputError(
            f"the area is empty ({hull_m2:.2f} m2 inside its vertices): they are collinear "
            "or repeated"
        )
    if not shapely.is_valid(poly):
        reason = explain_validity(poly)
        match = re.search(r"\[([-\d.eE+]+) ([-\d.eE+]+)\]", reason)
        where = ""
        if match:
            lat, lon = frame.to_geodetic(float(match.group(1)), float(match.group(2)))
            where = f" near {float(lat):.7f}, {float(lon):.7f}"
        kind = reason.split("[", 1)[0].strip().lower()
        if kind == "self-intersection":
            raise InputError(
                f"the area polygon intersects itself{where}: list its vertices in order "
                "around the boundary"
            )
        raise InputError(f"the area polygon is not valid ({kind}){where}")
    minx, miny, maxx, maxy = poly.bounds
    extent = max(maxx - minx, maxy - miny)
    if extent > max_extent_m:
        raise InputError(
            f"the area spans {extent / 1000:.1f} km; plan areas up to "
            f"{max_extent_m / 1000:g} km across (split it)"
        )


def _rotate(xy: npt.NDArray[np.float64], heading_deg: float) -> npt.NDArray[np.float64]:
    """(east, north) -> (u along the heading, v to its right)."""
    h = math.radians(heading_deg)
    s, c = math.sin(h), math.cos(h)
    e, n = xy[:, 0], xy[:, 1]
    return np.column_stack([e * s + n * c, e * c - n * s])


def _unrotate(u: float, v: float, heading_deg: float) -> tuple[float, float]:
    h = math.radians(heading_deg)
    s, c = math.sin(h), math.cos(h)
    return (u * s + v * c, u * c - v * s)


def _intervals(geom: BaseGeometry) -> list[tuple[float, float]]:
    """u-intervals of a (multi)line along the u axis."""
    if geom.is_empty:
        return []
    parts = getattr(geom, "geoms", [geom])
    out = []
    for g in parts:
        if g.geom_type != "LineString":
            continue
        xs = [x for x, _ in g.coords]
        out.append((min(xs), max(xs)))
    return sorted(out)


def sweep_lines(
    poly: Polygon,
    reach: BaseGeometry,
    heading_deg: float,
    width_m: float,
    spacing_m: float,
    margin_m: float,
) -> list[tuple[float, float, float]]:
    """Lines over ``poly`` (ENU) at ``heading_deg``: (v, u_start, u_end), sorted by v.

    ``reach`` is ``poly`` grown by the turn margin: line ends stay inside it.
    """
    import shapely

    rot = shapely.transform(poly, lambda xy: _rotate(xy, heading_deg))
    reach = shapely.transform(reach, lambda xy: _rotate(xy, heading_deg))
    minx, miny, maxx, maxy = rot.bounds
    span = maxy - miny
    n = 1 if span <= width_m else math.ceil((span - width_m) / spacing_m - 1e-9) + 1
    v = (miny + maxy) / 2.0 + (np.arange(n) - (n - 1) / 2.0) * spacing_m
    # The part of the area each line's footprint strip sweeps (vectorised GEOS calls).
    strips = shapely.box(minx - 1.0, v - width_m / 2.0, maxx + 1.0, v + width_m / 2.0)
    parts = shapely.intersection(rot, strips)
    keep = ~shapely.is_empty(parts)
    v, bounds = v[keep], shapely.bounds(parts[keep])
    a, b = bounds[:, 0], bounds[:, 2]
    probes = shapely.linestrings(
        np.stack(
            [np.column_stack([a - margin_m - 1.0, v]), np.column_stack([b + margin_m + 1.0, v])],
            axis=1,
        )
    )
    lines = []
    for vk, ak, bk, inside in zip(v, a, b, shapely.intersection(reach, probes), strict=True):
        spans = _intervals(inside)
        starts = [max(s, ak - margin_m) for s, e in spans if e >= ak - margin_m]
        ends = [min(e, bk + margin_m) for s, e in spans if s <= bk + margin_m]
        u0 = min(starts) if starts else float(ak)
        u1 = max(ends) if ends else float(bk)
        lines.append((float(vk), float(u0), float(max(u1, u0))))
    return lines


def heading_candidates(poly: Polygon) -> list[float]:
    hull = np.asarray(poly.convex_hull.exterior.coords)
    d = np.diff(hull, axis=0)
    edges = np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 180.0
    grid = np.arange(0.0, 180.0, _HEADING_STEP_DEG)
    return sorted({round(float(h), 6) for h in np.concatenate([edges, grid])})


def order_lines(
    lines: list[tuple[float, float, float]],
    heading_deg: float,
    home_enu: tuple[float, float] | None,
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """Boustrophedon order as ENU (start, end) pairs; the variant nearest home."""
    variants = []
    for reverse_lines in (False, True):
        seq = lines[::-1] if reverse_lines else lines
        for first_forward in (True, False):
            pairs = []
            for k, (v, u0, u1) in enumerate(seq):
                forward = first_forward == (k % 2 == 0)
                a, b = (u0, u1) if forward else (u1, u0)
                pairs.append((_unrotate(a, v, heading_deg), _unrotate(b, v, heading_deg)))
            variants.append(pairs)
    if home_enu is None:
        return variants[0]
    hx, hy = home_enu

    def cost(pairs: list[tuple[tuple[float, float], tuple[float, float]]]) -> tuple[float, float]:
        # Shortest transit out and back; on a tie, start near home.
        (sx, sy), (ex, ey) = pairs[0][0], pairs[-1][1]
        out = math.hypot(sx - hx, sy - hy)
        return (round(out + math.hypot(ex - hx, ey - hy), 3), out)

    return min(variants, key=cost)


def _path_length(points: Sequence[tuple[float, float]]) -> float:
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(points))


def estimate_flight(
    points: Sequence[tuple[float, float]],
    speed: float,
    *,
    altitude_m: float,
    climb_m_s: float,
    accel_m_s2: float,
) -> tuple[float, float]:
    """(distance m, duration s) of home -> points -> home: climb to ``altitude_m`` and back
    down at ``climb_m_s``, fly at ``speed`` m/s, stop at each waypoint (``accel_m_s2``)."""
    dist = _path_length(points)
    stops = max(len(points) - 2, 0)
    vertical = 2.0 * altitude_m / climb_m_s
    return dist, vertical + dist / speed + stops * speed / accel_m_s2
