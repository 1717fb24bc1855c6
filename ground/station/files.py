"""The ground station's files, rewritten after every change (each atomically).

In the station folder:

* ``holes.kml`` - one placemark per hole not rejected, its picture (``cards/``), size,
  score, the detector's "why" and the operator's mark (Google Earth, CalTopo, ATAK);
* ``holes_live.kml`` - a NetworkLink to ``holes.kml`` that Google Earth reloads every
  ``refresh_s`` seconds: open it once, the map follows the flight;
* ``holes.geojson`` - the same points (CalTopo/SARTopo import, QGIS);
* ``holes.gpx`` - waypoints for handheld GPS units.

Written with the project's waypoint writers (:func:`missions.write_kml`,
:func:`missions.write_geojson`, :func:`missions.write_gpx`) from one
:class:`missions.Waypoint` per hole, through the output-path rule
(:func:`outputs.output_via_part`: ``.NAME.part.EXT``, fsynced, renamed).
"""

from __future__ import annotations

import html
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from holescan.geotag import CIRCLE_95_PER_SIGMA
from holescan.ground.station.records import GroundHole
from holescan.missions import (
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    Waypoint,
    write_geojson,
    write_gpx,
    write_kml,
)
from holescan.outputs import atomic_output, output_via_part

__all__ = [
    "hole_points",
    "hole_summary",
    "hole_waypoint",
    "kml_points",
    "network_link_kml",
    "seen_by",
    "write_station_files",
]


def seen_by(h: GroundHole) -> str:
    """Which vehicles reported the hole: ``seen by vehicle 2``, ``seen by vehicles 1 + 2
    (first 1, last 2)``; empty when not known (system ids: numbers the link checked).

    >>> from holescan.ground.station.records import HoleSource
    >>> h = GroundHole(7, 43.6, -79.4, vehicles=[HoleSource(1, 7, 43.6, -79.4)])
    >>> seen_by(h)
    'seen by vehicle 1'
    >>> h.vehicles.append(HoleSource(2, 3, 43.6, -79.4, t_first_unix_ns=5, t_last_unix_ns=5))
    >>> seen_by(h)
    'seen by vehicles 1 + 2 (first 1, last 2)'
    """
    got = h.first_last
    if got is None:
        return ""
    ids = h.sysids
    if len(ids) == 1:
        return f"seen by vehicle {ids[0]}"
    return f"seen by vehicles {' + '.join(map(str, ids))} (first {got[0]}, last {got[1]})"


def hole_summary(h: GroundHole, *, why: bool = True, vehicles: bool = True) -> str:
    """One line: size, score, sightings, uncertainty, (``vehicles``) which vehicles saw it,
    operator's mark, and (``why``) the detector's explanation."""
    parts = [f"hole {h.id}"]
    if h.score is not None:
        parts.append(f"best frame's score {h.score:.2f}")
    if h.major_m is not None and h.minor_m is not None:
        parts.append(f"opening {h.major_m:.2f} x {h.minor_m:.2f} m")
    if h.sightings:
        parts.append(f"seen in {h.sightings} frames")
    if h.sigma_h_m is not None:
        parts.append(f"within {CIRCLE_95_PER_SIGMA * h.sigma_h_m:.2f} m (95 %)")
    if vehicles and h.vehicles:
        parts.append(seen_by(h))
    parts.append(f"operator: {h.mark}")
    text = ", ".join(parts)
    return f"{text}. {h.why}" if h.why and why else text


def hole_waypoint(h: GroundHole, image_src: str | None = None) -> Waypoint:
    """The hole as the project's waypoint record (MSL altitude when known)."""
    props: dict[str, Any] = {
        "hole_id": h.id,
        "tier": h.tier,
        "p_hole": h.p_hole,
        "score": None if h.score is None else round(h.score, 3),
        "mark": h.mark,
        "sightings": h.sightings,
        "sigma_h_m": h.sigma_h_m,
        "major_m": h.major_m,
        "minor_m": h.minor_m,
        "why": h.why,
    }
    first_last = h.first_last
    if first_last is not None:
        props["vehicles"] = h.sysids
        props["first_vehicle"], props["last_vehicle"] = first_last
    p = "unknown" if h.p_hole is None else f"{h.p_hole:.2f}"
    desc = f"{h.tier}, p_hole {p}: {hole_summary(h)}"
    if image_src is not None:
        props["picture"] = image_src
    return Waypoint(
        h.lat_deg,
        h.lon_deg,
        h.alt_m if h.alt_m is not None else 0.0,
        name=f"hole {h.id} ({h.mark})",
        description=desc,
        properties=props,
        frame=MAV_FRAME_GLOBAL if h.alt_m is not None else MAV_FRAME_GLOBAL_RELATIVE_ALT,
    )


def _replace(path: Path, write: Callable[[Path], object]) -> None:
    """Rewrite one of the station's files (they are its own: replaced every time)."""
    with output_via_part(path, force=True, fsync=True) as part:
        write(part)


def hole_points(
    holes: Sequence[GroundHole], picture: Callable[[GroundHole], str | None]
) -> list[Waypoint]:
    """The holes not rejected as waypoints; ``picture(h)`` is where a hole's picture is
    (a file name beside the files, or the station's URL; None: no picture)."""
    return [hole_waypoint(h, picture(h)) for h in holes if h.mark != "rejected"]


def kml_points(points: Sequence[Waypoint]) -> list[Waypoint]:
    """The points with their picture (when they have one) in their KML description."""
    return [
        Waypoint(
            w.lat_deg,
            w.lon_deg,
            w.alt_m,
            name=w.name,
            description=(
                f'<img src="{html.escape(str(w.properties["picture"]))}" width="160"/><br/>'
                if "picture" in w.properties
                else ""
            )
            + html.escape(w.description),
            properties=w.properties,
            frame=w.frame,
        )
        for w in points
    ]


def write_station_files(
    folder: Path, holes: Sequence[GroundHole], *, refresh_s: float = 5.0
) -> list[Path]:
    """Write the station's hole files (see the module docstring); return their paths."""
    points = hole_points(holes, lambda h: f"cards/hole-{h.id}.jpg" if h.has_picture else None)
    kml, live = folder / "holes.kml", folder / "holes_live.kml"
    gj, gpx = folder / "holes.geojson", folder / "holes.gpx"
    kml_doc = kml_points(points)
    _replace(kml, lambda p: write_kml(p, kml_doc, document_name="holescan holes (live)"))
    _replace(gj, lambda p: write_geojson(p, points, altitude=False))
    _replace(gpx, lambda p: write_gpx(p, points))
    if not live.exists():
        with atomic_output(live, force=True) as f:
            f.write(network_link_kml("holes.kml", refresh_s).encode())
    return [kml, live, gj, gpx]


def network_link_kml(href: str, refresh_s: float) -> str:
    """A KML 2.2 NetworkLink to ``href`` that Google Earth reloads every ``refresh_s``."""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2">
  <NetworkLink>
    <name>holescan holes (live)</name>
    <refreshVisibility>0</refreshVisibility>
    <Link>
      <href>{html.escape(href)}</href>
      <refreshMode>onInterval</refreshMode>
      <refreshInterval>{refresh_s:g}</refreshInterval>
    </Link>
  </NetworkLink>
</kml>
"""
