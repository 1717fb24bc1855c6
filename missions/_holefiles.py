"""Found holes as the files a ground crew uses: GPX, KML/KMZ, GeoJSON, QGC ``.plan``, WPL.

Holes become :class:`missions.Waypoint` records and go through the generic writers of
:mod:`missions._files`, so every hole file reads back with the same readers. In every
format the holes come in the same order: highest confidence first (best score, then more
sightings, then lower id), as :func:`missions.hole_waypoints` serves them live; ``rank``
is that position (1 = the most promising hole), ``hole_id`` the tracker's stable number.

What each format holds:

* **GPX** (handheld GPS units): one ``wpt`` per hole, name ``hole <id>``, elevation = the
  hole's fused altitude above mean sea level, and a one-line ASCII description with the
  data (rank, score, sightings, size, 1-sigma position error, first/last seen, lat/lon).
* **KML** (Google Earth): one Placemark per hole on the ground (``relativeToGround`` 0;
  its MSL altitude is in the data), the data as ``ExtendedData`` (values as JSON text) and
  an HTML description with a table and the hole's thumbnail embedded as a ``data:`` URI
  (``<img src="data:image/jpeg;base64,...">``). Google Earth Pro renders the description
  as HTML and shows such images; viewers that sanitise balloon HTML or do not render it
  (Google My Maps, QGIS's attribute view, most phone apps) drop the image and keep the
  text and data. This was not checked in those viewers here; where it matters, use KMZ.
* **KMZ**: a zip of ``doc.kml`` (the same placemarks) and ``images/hole_<id>.jpg``, the
  description linking the image by relative path: the packaging every KML viewer knows.
* **GeoJSON**: Point features ``[lon, lat]`` (no third value: RFC 7946 means ellipsoidal
  height, not MSL) with the data in ``properties``.
* **QGC .plan** and **QGC WPL 110** (missions to fly to the holes): home, then one
  NAV_WAYPOINT per hole at ``rel_alt_m`` above home (raised to ``clearance_m`` above the
  hole when the home's altitude is known), as :func:`missions.hole_waypoints` makes them.
  The ``.plan`` items carry each hole's name, description and data under the key
  ``"holescan"``; a WPL line has no room for them: its lines are in rank order.

What each hole is: every file says it, per hole: ``hole_id``, ``tier`` (``announced``,
``review``, ``confirmed``, ``rejected``: :data:`HOLE_TIERS`), ``p_hole`` (the hole-level
confidence, :attr:`geotag.Hole.p_hole`), ``sightings`` (frames it was detected in),
``views`` (distinct viewpoints), the size (``major_m``, ``minor_m``), ``sigma_h_m`` and
``r95_m`` (the 95 % circle's radius) (GeoJSON properties, KML data and description, GPX
description, ``.plan`` item data). The missions (``.plan``, WPL) hold only the announced
and confirmed holes; holes for review or rejected are points, never waypoints to fly to.
Candidates below the review tier are not in these files at all (they stay in the flight
log and the report).

Latitudes and longitudes are written with 8 decimals (about 1 mm).
"""

from __future__ import annotations

import base64
import dataclasses
import html
import math
import tempfile
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final, Literal, get_args

from holescan.errors import InputError
from holescan.geotag import CIRCLE_95_PER_SIGMA, HOLE_TIERS, Hole
from holescan.missions._geofiles import write_geojson, write_gpx, write_kml
from holescan.missions._holeserver import hole_waypoints
from holescan.missions._qgcfiles import write_plan, write_wpl
from holescan.missions._waypoint import MAV_FRAME_GLOBAL, MAV_FRAME_GLOBAL_RELATIVE_ALT, Waypoint
from holescan.utc import utc_text

__all__ = [
    "HOLE_FORMATS",
    "HOLE_SUFFIXES",
    "HoleFormat",
    "hole_description",
    "hole_mission",
    "hole_points",
    "hole_properties",
    "rank_holes",
    "write_hole_file",
]

HoleFormat = Literal["gpx", "kml", "kmz", "geojson", "plan", "wpl"]
HOLE_FORMATS: Final[tuple[HoleFormat, ...]] = get_args(HoleFormat)
HOLE_SUFFIXES: Final[Mapping[HoleFormat, str]] = {
    "gpx": ".gpx",
    "kml": ".kml",
    "kmz": ".kmz",
    "geojson": ".geojson",
    "plan": ".plan",
    "wpl": ".waypoints",
}
_KMZ_IMAGE_DIR = "images"

_MISSION_TIERS: Final = ("announced", "confirmed")


def _tier_of(tiers: Mapping[int, str] | None, hole_id: int) -> str:
    tier = "announced" if tiers is None else tiers.get(hole_id, "announced")
    if tier not in HOLE_TIERS:
        raise InputError(
            f"hole {hole_id}: tier must be one of {', '.join(HOLE_TIERS)}, not {tier!r}"
        )
    return tier


def rank_holes(holes: Iterable[Hole]) -> list[Hole]:
    """Holes by confidence: best score, then more sightings, then lower id."""
    return sorted(holes, key=lambda h: (-h.score, -h.sightings, h.id))


def _utc(t_boot_ns: int, boot_to_unix_ns: int | None) -> str | None:
    if boot_to_unix_ns is None:
        return None
    return utc_text(t_boot_ns + boot_to_unix_ns)


def _r(value: float, digits: int) -> float | None:
    return round(float(value), digits) if math.isfinite(value) else None


def hole_properties(
    hole: Hole, rank: int, boot_to_unix_ns: int | None = None, tier: str = "announced"
) -> dict[str, Any]:
    """The data of one hole as JSON-ready key/values (GeoJSON properties, KML data).

    Parameters
    ----------
    hole : the hole. rank : its place by confidence, from 1.
    boot_to_unix_ns : add this to an autopilot boot time to get Unix time (ns); when
        given, ``first_seen_utc`` / ``last_seen_utc`` (ISO 8601) are included.
    tier : what it is (:data:`HOLE_TIERS`).
    """
    props: dict[str, Any] = {
        "hole_id": hole.id,
        "tier": tier,
        "p_hole": _r(hole.p_hole, 4),
        "rank": rank,
        "score": _r(hole.score, 4),
        "sightings": hole.sightings,
        "views": hole.views,
        "major_m": _r(hole.major_m, 3),
        "minor_m": _r(hole.minor_m, 3),
        "sigma_h_m": _r(hole.sigma_h_m, 3),
        "r95_m": _r(CIRCLE_95_PER_SIGMA * hole.sigma_h_m, 3),
        "alt_msl_m": _r(hole.alt_m, 3),
        "t_first_boot_ns": hole.t_first_boot_ns,
        "t_last_boot_ns": hole.t_last_boot_ns,
    }
    first = _utc(hole.t_first_boot_ns, boot_to_unix_ns)
    last = _utc(hole.t_last_boot_ns, boot_to_unix_ns)
    if first is not None and last is not None:
        props["first_seen_utc"] = first
        props["last_seen_utc"] = last
    props["best_frame_index"] = hole.best_frame_index
    props["best_box"] = list(hole.best_box)
    return props


def _seen(hole: Hole, boot_to_unix_ns: int | None) -> str:
    first = _utc(hole.t_first_boot_ns, boot_to_unix_ns)
    last = _utc(hole.t_last_boot_ns, boot_to_unix_ns)
    if first is None or last is None:
        span_s = (hole.t_last_boot_ns - hole.t_first_boot_ns) / 1e9
        return f"seen over {span_s:.1f} s (autopilot boot time {hole.t_first_boot_ns / 1e9:.1f} s)"
    return f"first seen {first}, last seen {last}"


def _p(hole: Hole) -> str:
    return f"p_hole {hole.p_hole:.2f}" if math.isfinite(hole.p_hole) else "p_hole unknown"


def _sightings(hole: Hole) -> str:
    """Frames and, when known, distinct viewpoints (0 views: unknown, e.g. an older log)."""
    if hole.views > 0:
        return f"{hole.sightings} frames from {hole.views} viewpoints"
    return f"{hole.sightings} frames"


def hole_description(
    hole: Hole, rank: int, boot_to_unix_ns: int | None = None, tier: str = "announced"
) -> str:
    """One ASCII line a person reads on a handheld GPS: the hole's data and position."""
    return (
        f"hole {hole.id} ({tier}, rank {rank}): {_p(hole)}, best frame's score "
        f"{hole.score:.2f}, seen in {_sightings(hole)}, "
        f"opening {hole.major_m:.2f} x {hole.minor_m:.2f} m, within "
        f"{CIRCLE_95_PER_SIGMA * hole.sigma_h_m:.2f} m (95 %), {_seen(hole, boot_to_unix_ns)}, "
        f"lat {hole.lat_deg:.7f} lon {hole.lon_deg:.7f}, alt {hole.alt_m:.1f} m MSL"
    )


def _html_description(
    hole: Hole, rank: int, boot_to_unix_ns: int | None, image_src: str | None, tier: str
) -> str:
    rows = [
        ("tier", tier),
        ("p_hole", _p(hole).removeprefix("p_hole ")),
        ("rank", str(rank)),
        ("best frame's score", f"{hole.score:.2f}"),
        ("sightings", _sightings(hole)),
        ("opening", f"{hole.major_m:.2f} x {hole.minor_m:.2f} m"),
        ("95 % circle", f"{CIRCLE_95_PER_SIGMA * hole.sigma_h_m:.2f} m"),
        ("lat, lon", f"{hole.lat_deg:.7f}, {hole.lon_deg:.7f}"),
        ("altitude", f"{hole.alt_m:.1f} m MSL"),
    ]
    first = _utc(hole.t_first_boot_ns, boot_to_unix_ns)
    last = _utc(hole.t_last_boot_ns, boot_to_unix_ns)
    if first is not None and last is not None:
        rows += [("first seen", first), ("last seen", last)]
    parts = []
    if image_src is not None:
        alt = f"hole {hole.id}, frame {hole.best_frame_index}: colour | depth"
        parts.append(f'<img src="{html.escape(image_src)}" alt="{html.escape(alt)}"/><br/>')
    parts.append(f"<b>hole {hole.id}</b><table>")
    parts += [f"<tr><td>{html.escape(k)}</td><td>{html.escape(v)}</td></tr>" for k, v in rows]
    parts.append("</table>")
    return "".join(parts)


def hole_points(
    holes: Iterable[Hole],
    *,
    boot_to_unix_ns: int | None = None,
    on_ground: bool = False,
    image_src: Mapping[int, str] | None = None,
    tiers: Mapping[int, str] | None = None,
) -> list[Waypoint]:
    """Points of interest, one per hole, by confidence (GPX, KML, GeoJSON).

    Parameters
    ----------
    holes : the holes (filter them by :attr:`geotag.Hole.sightings` before).
    boot_to_unix_ns : see :func:`hole_properties`.
    on_ground : place the point on the ground (frame 3, altitude 0: KML
        ``relativeToGround``) instead of at the hole's MSL altitude (frame 0).
    image_src : hole id -> image URL for an HTML description (KML); without it the
        description is the plain line of :func:`hole_description`.
    tiers : hole id -> its tier (:data:`HOLE_TIERS`; missing or None: ``announced``).
    """
    out = []
    for rank, h in enumerate(rank_holes(holes), start=1):
        tier = _tier_of(tiers, h.id)
        if image_src is not None:
            desc = _html_description(h, rank, boot_to_unix_ns, image_src.get(h.id), tier)
        else:
            desc = hole_description(h, rank, boot_to_unix_ns, tier)
        out.append(
            Waypoint(
                h.lat_deg,
                h.lon_deg,
                0.0 if on_ground else h.alt_m,
                name=f"hole {h.id}" if tier in _MISSION_TIERS else f"{tier} {h.id}",
                description=desc,
                properties=hole_properties(h, rank, boot_to_unix_ns, tier),
                frame=MAV_FRAME_GLOBAL_RELATIVE_ALT if on_ground else MAV_FRAME_GLOBAL,
            )
        )
    return out


def hole_mission(
    holes: Iterable[Hole],
    *,
    home: tuple[float, float, float] | None = None,
    rel_alt_m: float = 10.0,
    clearance_m: float = 5.0,
    boot_to_unix_ns: int | None = None,
    tiers: Mapping[int, str] | None = None,
) -> tuple[Waypoint | None, list[Waypoint]]:
    """A mission to fly over the holes, by confidence: ``(home, items)``.

    Parameters
    ----------
    home : (lat_deg, lon_deg, alt_m MSL) of the vehicle's home; None when unknown (the
        writers then use the first item's position at altitude 0).
    rel_alt_m, clearance_m : waypoint altitude, see :func:`missions.hole_waypoints`.
    boot_to_unix_ns : see :func:`hole_properties`.

    The items are NAV_WAYPOINTs in MAV_FRAME_GLOBAL_RELATIVE_ALT at the holes' full
    precision positions (the live server sends them as degE7) with each hole's name,
    description and data.
    """
    holes = tuple(holes)
    by_id = {h.id: h for h in holes}
    if len(by_id) != len(holes):
        raise InputError("hole ids must be unique")
    served = hole_waypoints(holes, home=home, rel_alt_m=rel_alt_m, clearance_m=clearance_m)
    items = []
    for seq, item in enumerate(served[1:], start=1):
        h = by_id[int(item.properties["hole_id"])]
        items.append(
            dataclasses.replace(
                item,
                description=hole_description(h, seq, boot_to_unix_ns, _tier_of(tiers, h.id)),
                properties=hole_properties(h, seq, boot_to_unix_ns, _tier_of(tiers, h.id)),
            )
        )
    home_wp = None
    if home is not None:
        home_wp = Waypoint(home[0], home[1], home[2], name="home", frame=MAV_FRAME_GLOBAL)
    return home_wp, items


def _write_kmz(
    path: Path,
    holes: Sequence[Hole],
    thumbnails: Mapping[int, bytes],
    boot_to_unix_ns: int | None,
    name: str,
    tiers: Mapping[int, str] | None,
) -> Path:
    images = {h.id: f"{_KMZ_IMAGE_DIR}/hole_{h.id}.jpg" for h in holes if h.id in thumbnails}
    points = hole_points(
        holes, boot_to_unix_ns=boot_to_unix_ns, on_ground=True, image_src=images, tiers=tiers
    )
    with tempfile.TemporaryDirectory(prefix="holescan-kmz-") as tmp:
        doc = write_kml(Path(tmp) / "doc.kml", points, document_name=name)
        with zipfile.ZipFile(path, "w") as kmz:
            kmz.write(doc, "doc.kml", compress_type=zipfile.ZIP_DEFLATED)  # first entry
            for hole_id, arcname in images.items():
                kmz.writestr(arcname, thumbnails[hole_id], compress_type=zipfile.ZIP_STORED)
    return path


def write_hole_file(
    path: str | Path,
    holes: Iterable[Hole],
    fmt: HoleFormat,
    *,
    home: tuple[float, float, float] | None = None,
    thumbnails: Mapping[int, bytes] | None = None,
    boot_to_unix_ns: int | None = None,
    rel_alt_m: float = 10.0,
    clearance_m: float = 5.0,
    name: str = "holescan holes",
    tiers: Mapping[int, str] | None = None,
) -> Path:
    """Write ``holes`` to ``path`` in format ``fmt`` (see the module docstring).

    Parameters
    ----------
    path : output file (overwritten).
    holes : the holes to write (at least one).
    fmt : ``gpx``, ``kml``, ``kmz``, ``geojson``, ``plan`` or ``wpl`` (QGC WPL 110).
    home : (lat_deg, lon_deg, alt_m MSL) of the vehicle's home, for ``plan``/``wpl``.
    thumbnails : hole id -> JPEG bytes of its best view (KML/KMZ only; holes without one
        get no picture).
    boot_to_unix_ns : add to autopilot boot times to get Unix time (first/last seen).
    rel_alt_m, clearance_m : mission altitude (``plan``/``wpl``), see :func:`hole_mission`.
    name : the KML document's name.
    tiers : hole id -> its tier (:data:`HOLE_TIERS`; missing or None: ``announced``).
        Holes for review and rejected ones are points named ``review <id>`` /
        ``rejected <id>`` (GPX, KML, KMZ, GeoJSON), never in a mission (``plan``,
        ``wpl``). Pass no candidates (holes below the review tier): they are not for the
        crew.
    """
    path = Path(path)
    holes = tuple(holes)
    if not holes:
        raise InputError(f"{path}: no holes to write")
    if fmt not in HOLE_FORMATS:
        raise InputError(f"unknown hole file format {fmt!r}; use one of {', '.join(HOLE_FORMATS)}")
    thumbs = thumbnails or {}
    if fmt == "gpx":
        return write_gpx(path, hole_points(holes, boot_to_unix_ns=boot_to_unix_ns, tiers=tiers))
    if fmt == "geojson":
        points = hole_points(holes, boot_to_unix_ns=boot_to_unix_ns, tiers=tiers)
        return write_geojson(path, points, altitude=False)
    if fmt == "kml":
        src = {
            h.id: "data:image/jpeg;base64," + base64.b64encode(thumbs[h.id]).decode("ascii")
            for h in holes
            if h.id in thumbs
        }
        points = hole_points(
            holes, boot_to_unix_ns=boot_to_unix_ns, on_ground=True, image_src=src, tiers=tiers
        )
        return write_kml(path, points, document_name=name)
    if fmt == "kmz":
        return _write_kmz(path, holes, thumbs, boot_to_unix_ns, name, tiers)
    home_wp, items = hole_mission(
        [h for h in holes if _tier_of(tiers, h.id) in _MISSION_TIERS],
        home=home,
        rel_alt_m=rel_alt_m,
        clearance_m=clearance_m,
        boot_to_unix_ns=boot_to_unix_ns,
        tiers=tiers,
    )
    if fmt == "plan":
        return write_plan(path, items, home_wp, item_data=True)
    return write_wpl(path, items, home_wp)
