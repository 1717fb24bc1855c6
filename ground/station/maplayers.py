"""The live page's map layers: orthophoto and coverage tiles, served from the map store.

One route function, :func:`map_route`, that the page's ``/map.json`` and ``/map/...``
routes call (kept apart from :mod:`ground.station.web` so that the map is one clearly
separated piece of the server; the page's script is ``static/maplayers.js``, no CDN):

* ``GET /map.json?lat=..&lon=..`` every place of the combined map
  (:mod:`ground.station.mapcombine`: all flights on the first one's grid), its corners in
  the page's local metres (:class:`geotag.LocalFrame` at the page's origin ``lat``/``lon``,
  the state document's ``origin``; without them, the first map's own origin) and where to
  fetch its two layers;
* ``GET /map/all/cov-<tx>_<ty>.png`` and ``/map/all/ortho-<tx>_<ty>.png`` a combined tile
  for the page (RGBA PNG: coverage seen green / not seen red, translucent; the orthophoto
  of the best look, transparent where no flight saw);
* ``GET /map/v<sysid>/cov-<tx>_<ty>.png`` one vehicle's coverage (its flights combined
  on the same grid): cells it searched in its colour, cells of its tiles it did not
  search grey, both translucent; ``/map.json`` lists each vehicle's tiles and colour
  under ``vehicles``;
* ``GET /map/<file>`` a tile as received (coverage PNG, orthophoto JPEG);
* ``GET /map/view/<file>`` a coverage tile coloured for the page: seen cells green, cells
  of the tile not seen red (both translucent), RGBA PNG.

The basemaps the team brought (:mod:`ground.station.basemap`), numbered in the order given:

* ``GET /basemaps.json`` each one's ``id``, ``name``, ``kind``, zoom range and extent;
* ``GET /basemap/<id>/view.json?lat=..&lon=..&x0=..&y0=..&x1=..&y1=..&px=..`` the tiles
  that fill the page's view (its box in the page's metres, ``px`` pixels wide): each
  tile's corners in those metres and where to fetch it (at most
  :data:`~ground.station.basemap.MAX_VIEW_TILES`);
* ``GET /basemap/<id>/<z>/<x>/<y>`` a tile (PNG, JPEG or WebP).

Every request is hostile: file names are looked up in the store's list (never opened as
given), numbers are parsed and range-checked, anything else is 404 / 400.
"""

from __future__ import annotations

import json
import math
import re
import threading
from collections.abc import Callable, Mapping, Sequence
from urllib.parse import parse_qs

import cv2
import numpy as np

from holescan.geotag import LocalFrame
from holescan.ground.station.basemap import MAX_VIEW_M, Basemap, view_tiles
from holescan.ground.station.mapcombine import CombinedCache, combined_places
from holescan.ground.station.mapstore import MapStore
from holescan.missions import read_tile

__all__ = [
    "Reply",
    "VehicleMaps",
    "basemap_route",
    "coverage_view_png",
    "map_document",
    "map_route",
    "vehicle_coverage_png",
]

Reply = tuple[int, bytes, str]
_ALL = re.compile(r"/map/all/(cov|ortho)-(-?\d{1,7})_(-?\d{1,7})\.png")
_VEHICLE = re.compile(r"/map/v(\d{1,3})/cov-(-?\d{1,7})_(-?\d{1,7})\.png")
_NAME = re.compile(r"(v\d{1,3}-)?m\d{1,10}-(cov|ortho)--?\d{1,7}_-?\d{1,7}\.(png|jpg)")
_COLOUR = re.compile(r"#[0-9a-fA-F]{6}")
_VEHICLE_UNSEEN_RGBA = (97, 97, 97, 80)
_VEHICLE_SEEN_ALPHA = 120
_BASEMAP_TILE = re.compile(r"/basemap/(\d{1,2})/(\d{1,2})/(\d{1,8})/(\d{1,8})")
_BASEMAP_VIEW = re.compile(r"/basemap/(\d{1,2})/view\.json")
_SEEN_RGBA = (46, 125, 50, 45)
_UNSEEN_RGBA = (211, 47, 47, 110)


def coverage_view_png(levels: np.ndarray) -> bytes:
    """A coverage tile's levels (n, n) uint8 -> RGBA PNG: seen green, not seen red."""
    seen = levels > 0
    rgba = np.empty((*levels.shape, 4), np.uint8)
    rgba[seen] = _SEEN_RGBA
    rgba[~seen] = _UNSEEN_RGBA
    bgra = rgba[..., [2, 1, 0, 3]]
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(bgra))
    if not ok:  # cannot happen for a uint8 image; say so rather than serve garbage
        raise ValueError("PNG encoding failed")
    return bytes(buf.tobytes())


def vehicle_coverage_png(seen: np.ndarray, colour: str) -> bytes:
    """Where one vehicle searched (n, n) bool -> RGBA PNG: searched in ``colour``
    (``#rrggbb``), not searched grey, both translucent.

    >>> png = vehicle_coverage_png(np.eye(4, dtype=bool), "#1565c0")
    >>> rgba = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    >>> rgba[0, 0].tolist(), rgba[0, 1].tolist()  # BGRA
    ([192, 101, 21, 120], [97, 97, 97, 80])
    """
    if not _COLOUR.fullmatch(colour):
        raise ValueError(f"a colour is #rrggbb, got {colour!r}")
    rgb = tuple(int(colour[i : i + 2], 16) for i in (1, 3, 5))
    rgba = np.empty((*seen.shape, 4), np.uint8)
    rgba[seen] = (*rgb, _VEHICLE_SEEN_ALPHA)
    rgba[~seen] = _VEHICLE_UNSEEN_RGBA
    return _png(rgba)


class VehicleMaps:
    """Each vehicle's combined coverage (:class:`CombinedCache` of its tiles, made when
    first asked for) and its colour on the page (``colours()``: system id -> ``#rrggbb``,
    the colours the page's vehicles have)."""

    def __init__(self, store: MapStore, colours: Callable[[], Mapping[int, str]]) -> None:
        self.store = store
        self.colours = colours
        self._caches: dict[int, CombinedCache] = {}
        self._lock = threading.Lock()

    def cache(self, sysid: int) -> CombinedCache:
        with self._lock:  # at most one per system id (1..255)
            if sysid not in self._caches:
                self._caches[sysid] = CombinedCache(self.store, sysid)
            return self._caches[sysid]

    def colour(self, sysid: int) -> str:
        return self.colours().get(sysid, _FALLBACK_COLOUR)


_FALLBACK_COLOUR = "#455a64"


def _vehicle_tile(maps: VehicleMaps, sysid: int, tx: int, ty: int) -> bytes | None:
    if sysid not in maps.store.vehicles() or sysid == 0:
        return None
    combined = maps.cache(sysid).get()
    cov = None if combined is None else combined.tile("cov", tx, ty)
    if cov is None:
        return None
    return vehicle_coverage_png(cov > 0, maps.colour(sysid))


def _png(rgba: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgba[..., [2, 1, 0, 3]]))
    if not ok:
        raise ValueError("PNG encoding failed")
    return bytes(buf.tobytes())


def _combined_tile(cache: CombinedCache, layer: str, tx: int, ty: int) -> bytes | None:
    combined = cache.get()
    if combined is None:
        return None
    if layer == "cov":
        cov = combined.tile("cov", tx, ty)
        return None if cov is None else coverage_view_png((cov > 0).astype(np.uint8))
    got = combined.ortho(tx, ty)
    if got is None:
        return None
    rgb, known = got
    rgba = np.zeros((*known.shape, 4), np.uint8)
    rgba[..., :3] = rgb
    rgba[..., 3] = np.where(known, 255, 0)
    return _png(rgba)


def _origin(query: str, max_fields: int = 4) -> tuple[float, float] | None:
    try:
        q = parse_qs(query[:400], max_num_fields=max_fields)
        lat, lon = float(q["lat"][0]), float(q["lon"][0])
    except (KeyError, IndexError, ValueError):  # also too many fields
        return None
    if not (math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90 and abs(lon) <= 180):
        return None
    return lat, lon


def map_document(
    store: MapStore,
    origin: tuple[float, float] | None,
    colours: Mapping[int, str] | None = None,
) -> dict[str, object]:
    """``/map.json``: the store's version and each combined tile's corners in the page's
    metres, with where to fetch it (``?v=`` changes when a tile under it arrived); under
    ``vehicles``, each vehicle's coverage tiles the same way, with its colour.

    origin : (lat_deg, lon_deg) of the page's local frame (None: the first map's own).
    colours : each vehicle's colour on the page (by system id).
    """
    out: list[dict[str, object]] = []
    vehicles: list[dict[str, object]] = []
    doc: dict[str, object] = {"version": store.version, "origin": origin, "tiles": out}
    doc["vehicles"] = vehicles
    if not store.tiles():
        return doc
    base, places = combined_places(store)
    if origin is None:
        origin = doc["origin"] = (base.lat0_deg, base.lon0_deg)
    dx, dy = (float(v) for v in LocalFrame(*origin).to_en(base.lat0_deg, base.lon0_deg))
    side = base.n * base.cell_m

    def corners(tx: int, ty: int) -> dict[str, object]:
        return {
            "x0": round(tx * side + dx, 3),
            "y0": round(ty * side + dy, 3),
            "x1": round((tx + 1) * side + dx, 3),
            "y1": round((ty + 1) * side + dy, 3),
        }

    for (tx, ty), (seq, has_ortho) in sorted(places.items()):
        for layer in ("ortho", "cov") if has_ortho else ("cov",):
            out.append(
                {
                    "layer": layer,
                    "map": base.map_id,
                    **corners(tx, ty),
                    "href": f"/map/all/{layer}-{tx}_{ty}.png?v={seq}",
                }
            )
    for sid in store.vehicles():
        if sid == 0:  # tiles of an older station: in the combined layer only
            continue
        _, mine = combined_places(store, sid)
        tiles = [
            {"layer": "cov", **corners(tx, ty), "href": f"/map/v{sid}/cov-{tx}_{ty}.png?v={seq}"}
            for (tx, ty), (seq, _) in sorted(mine.items())
        ]
        colour = (colours or {}).get(sid, _FALLBACK_COLOUR)
        vehicles.append({"sysid": sid, "colour": colour, "tiles": tiles})
    return doc


def map_route(
    store: MapStore | None,
    path: str,
    query: str = "",
    cache: CombinedCache | None = None,
    vehicles: VehicleMaps | None = None,
) -> Reply | None:
    """The reply to a GET of ``path`` (without its query) if it is a map path, else None.

    cache : the store's combined map, kept between requests (None: combined for this one).
    vehicles : each vehicle's map and colour (None: made for this request, default colours).
    Returns (status, body, content type).
    """
    if path == "/map.json":
        if store is None:
            body = b'{"version": 0, "origin": null, "tiles": [], "vehicles": []}'
            return 200, body, "application/json"
        colours = vehicles.colours() if vehicles is not None else None
        body = json.dumps(map_document(store, _origin(query), colours)).encode()
        return 200, body, "application/json"
    if not path.startswith("/map/"):
        return None
    if (m := _VEHICLE.fullmatch(path)) is not None:
        maps = vehicles if vehicles is not None or store is None else VehicleMaps(store, dict)
        data = None if maps is None else _vehicle_tile(maps, int(m[1]), int(m[2]), int(m[3]))
        if data is None:
            return 404, b"no such tile", "text/plain"
        return 200, data, "image/png"
    if (m := _ALL.fullmatch(path)) is not None:
        if store is None:
            return 404, b"no such tile", "text/plain"
        data = _combined_tile(cache or CombinedCache(store), m[1], int(m[2]), int(m[3]))
        if data is None:
            return 404, b"no such tile", "text/plain"
        return 200, data, "image/png"
    view = path.startswith("/map/view/")
    name = path[len("/map/view/") :] if view else path[len("/map/") :]
    if store is None or not _NAME.fullmatch(name) or (view and not name.endswith(".png")):
        return 404, b"no such tile", "text/plain"
    data = store.read(name)
    if data is None:
        return 404, b"no such tile", "text/plain"
    if not view:
        return 200, data, "image/png" if name.endswith(".png") else "image/jpeg"
    got = read_tile(data)
    if got is None:
        return 404, b"no such tile", "text/plain"
    return 200, coverage_view_png(got[1]), "image/png"


def _view_query(query: str) -> tuple[tuple[float, float], tuple[float, ...], int] | None:
    """(origin, (x0, y0, x1, y1), px) of a view request, or None when out of bounds."""
    origin = _origin(query, 8)
    try:
        q = parse_qs(query[:400], max_num_fields=8)
        box = tuple(float(q[k][0]) for k in ("x0", "y0", "x1", "y1"))
        px = int(q["px"][0])
    except (KeyError, IndexError, ValueError):
        return None
    if origin is None or not 1 <= px <= 8192:
        return None
    if not all(math.isfinite(v) and abs(v) <= MAX_VIEW_M for v in box):
        return None
    if not (box[0] < box[2] and box[1] < box[3]):
        return None
    return origin, box, px


def basemap_route(basemaps: Sequence[Basemap], path: str, query: str = "") -> Reply | None:
    """The reply to a GET of a basemap path (None: not one); see the module docstring."""
    if path == "/basemaps.json":
        doc = [
            {
                "id": i,
                "name": b.info.name,
                "kind": b.info.kind,
                "minzoom": b.info.minzoom,
                "maxzoom": b.info.maxzoom,
                "bounds": b.info.bounds,
            }
            for i, b in enumerate(basemaps)
        ]
        return 200, json.dumps({"basemaps": doc}).encode(), "application/json"
    if not path.startswith("/basemap/"):
        return None
    if (m := _BASEMAP_VIEW.fullmatch(path)) is not None:
        i = int(m[1])
        got = _view_query(query)
        if i >= len(basemaps):
            return 404, b"no such basemap", "text/plain"
        if got is None:
            return 400, b"a view wants lat, lon, x0, y0, x1, y1 (metres) and px", "text/plain"
        origin, (x0, y0, x1, y1), px = got
        tiles = [
            {"x0": b[0], "y0": b[1], "x1": b[2], "y1": b[3], "href": f"/basemap/{i}/{z}/{x}/{y}"}
            for z, x, y, b in view_tiles(basemaps[i].info, origin, (x0, y0, x1, y1), px)
        ]
        return 200, json.dumps({"id": i, "tiles": tiles}).encode(), "application/json"
    if (m := _BASEMAP_TILE.fullmatch(path)) is not None:
        i, z, x, y = (int(v) for v in m.groups())
        tile = basemaps[i].tile(z, x, y) if i < len(basemaps) else None
        if tile is None:
            return 404, b"no such tile", "text/plain"
        return 200, tile[0], tile[1]
    return 404, b"no such basemap", "text/plain"
