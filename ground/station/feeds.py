"""Live layers for the crew's other tools: QGIS, CalTopo, Google Earth, TAK handhelds.

Served by the live page's server (:mod:`ground.station.webapp`), read-only, under the same
guard as the page (Host check, rate limit, no cross-site browser reads):

* ``GET /holes.geojson`` the holes not rejected, one Point feature each (RFC 7946
  ``[lon, lat]``) with ``hole_id``, ``tier``, ``p_hole``, ``vehicles`` (the system ids of
  the vehicles that reported it, in the order they first did), ``first_vehicle`` and
  ``last_vehicle`` (which reported it first and last), the facts of the station's
  ``holes.geojson`` file and ``picture``: the hole's picture at the station's public URL;
* ``GET /gaps.geojson`` where the live map's coverage is below one half: one Polygon
  feature per gap (``area_m2``, ``mean_coverage``) and the surveyed area (the hull of what
  was seen, with the searched fraction), made by :func:`ground.searchmap.find_gaps` from
  the combined live map (:mod:`ground.station.mapcombine`), at most once every
  ``min_interval_s`` however often it is polled;
* ``GET /holes.kml`` the same holes as KML 2.2 placemarks, each picture at the public URL,
  the vehicles that saw it in its description ("seen by vehicles 1 + 2 (first 1, last 2)")
  and in its ExtendedData;
* ``GET /holes_live.kml`` a KML NetworkLink to ``/holes.kml`` at the public URL that
  Google Earth reloads every ``refresh_s`` (``refreshMode onInterval``).

The feeds need no pairing, as the read-only page does not: they show what that page shows
to anyone who can reach the station (holes for review included, marked by their
``tier``; rejected holes left out); detector candidates that did not become holes never
leave the vehicle, so they cannot appear. Nothing in them changes anything.
"""

from __future__ import annotations

import json
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from urllib.parse import urlsplit

import numpy as np

from holescan.errors import InputError
from holescan.geotag import LocalFrame
from holescan.ground.searchmap import find_gaps, gaps_document
from holescan.ground.station.files import hole_points, kml_points, network_link_kml
from holescan.ground.station.mapcombine import Combined, CombinedCache
from holescan.ground.station.records import GroundHole
from holescan.mapping import MapGrid, MapLayers
from holescan.missions import geojson_document, kml_document

__all__ = [
    "EMPTY",
    "FEEDS",
    "GapsCache",
    "check_public_url",
    "holes_geojson",
    "holes_kml",
    "live_kml",
]

GEOJSON = "application/geo+json"
KML = "application/vnd.google-earth.kml+xml"
FEEDS = {
    "/holes.geojson": GEOJSON,
    "/gaps.geojson": GEOJSON,
    "/holes.kml": KML,
    "/holes_live.kml": KML,
}
"""The feeds' paths and their content types."""

EMPTY = b'{"type": "FeatureCollection", "features": []}'
"""A feed with nothing in it yet."""

Vehicles = Callable[[GroundHole], list[int]]


def check_public_url(url: str) -> str:
    """The station's address as the crew's devices reach it: ``http://HOST:PORT/``.

    >>> check_public_url("http://192.168.1.10:8080")
    'http://192.168.1.10:8080/'
    >>> check_public_url("https://x:1/a")  # doctest: +IGNORE_EXCEPTION_DETAIL
    Traceback (most recent call last):
    ...
    holescan.errors.InputError: --public-url wants http://HOST:PORT ...
    """
    why = (
        "--public-url wants http://HOST:PORT (the station's address on the team's network), "
        f"got {url!r}"
    )
    try:
        parts = urlsplit(url.strip())
        port = parts.port
    except ValueError as err:
        raise InputError(why) from err
    if (
        parts.scheme != "http"
        or not parts.hostname
        or parts.path not in ("", "/")
        or parts.query
        or parts.fragment
        or parts.username is not None
        or port is None
    ):
        raise InputError(why)
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"http://{host}:{port}/"


def _picture(public_url: str) -> Callable[[GroundHole], str | None]:
    return lambda h: f"{public_url}cards/hole-{h.id}.jpg" if h.has_picture else None


def holes_geojson(holes: Sequence[GroundHole], vehicles: Vehicles, public_url: str) -> bytes:
    """``/holes.geojson``: the holes not rejected (see the module docstring)."""
    points = hole_points(holes, _picture(public_url))
    doc = geojson_document(points, altitude=False)
    by_id = {h.id: h for h in holes}
    for f in doc["features"]:
        f["properties"]["vehicles"] = vehicles(by_id[f["properties"]["hole_id"]])
    return json.dumps(doc, allow_nan=False).encode()


def holes_kml(holes: Sequence[GroundHole], public_url: str) -> bytes:
    """``/holes.kml``: the holes not rejected as KML 2.2, pictures at ``public_url``."""
    points = kml_points(hole_points(holes, _picture(public_url)))
    root = kml_document(points, document_name="holescan holes (live)")
    return bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True))


def live_kml(public_url: str, refresh_s: float) -> bytes:
    """``/holes_live.kml``: a NetworkLink to ``/holes.kml`` at ``public_url``."""
    return network_link_kml(f"{public_url}holes.kml", refresh_s).encode()


def combined_layers(c: Combined) -> MapLayers:
    """The combined live map as map layers (coverage and looks; no heights or colour),
    in the base map's metres (:class:`geotag.LocalFrame` at its origin)."""
    n, cell = c.base.n, c.base.cell_m
    h, w = c.cov.shape
    grid = MapGrid(c.tx0 * n * cell, (c.ty1 + 1) * n * cell, cell, w, h, n)
    cov = np.clip(c.cov, 0.0, 1.0 - 1e-7)
    return MapLayers(
        grid,
        np.full((h, w), np.nan, np.float32),
        np.zeros((h, w, 3), np.uint8),
        np.full((h, w), np.inf, np.float32),
        (c.cov > 0).astype(np.uint16),
        np.log1p(-cov).astype(np.float32),
    )


class GapsCache:
    """``/gaps.geojson`` of a live map, made again only when the map changed and at most
    once every ``min_interval_s`` (a tile flood or a polling loop cannot keep the
    station busy polygonising)."""

    def __init__(
        self,
        combined: CombinedCache,
        *,
        min_interval_s: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.combined = combined
        self.min_interval_s = min_interval_s
        self._clock = clock
        self._lock = threading.Lock()
        self._version = -1
        self._made_at = -float("inf")
        self._body = EMPTY

    def get(self) -> bytes:
        with self._lock:
            version = self.combined.store.version
            now = self._clock()
            if version != self._version and now - self._made_at >= self.min_interval_s:
                c = self.combined.get()
                doc: dict[str, object] = {"type": "FeatureCollection", "features": []}
                if c is not None:
                    report = find_gaps(combined_layers(c))
                    frame = LocalFrame(c.base.lat0_deg, c.base.lon0_deg)
                    doc = gaps_document(report, frame)
                self._body = json.dumps(doc, allow_nan=False).encode()
                self._version, self._made_at = version, now
            return self._body
