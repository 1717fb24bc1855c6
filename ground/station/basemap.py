"""Offline basemaps the team brings, served to the live page as Web Mercator XYZ tiles.

* **MBTiles** (``--basemap FILE.mbtiles``): raster tiles in SQLite (the MBTiles 1.3 spec:
  ``metadata`` and ``tiles`` tables, rows numbered TMS-style from the south, so row
  ``2**z - 1 - y`` holds XYZ tile ``y``); PNG, JPEG or WebP tiles served as they are.
  The file is opened read-only; a tile over :data:`MAX_TILE_BYTES` is not read.
* **GeoTIFF** (``--basemap FILE.tif``): any 8-bit grey, RGB or RGBA GeoTIFF with a CRS,
  among them the orthophoto of an earlier sortie or campaign (``NAME_ortho.tif`` of
  ``holescan reprocess`` / ``holescan campaign``, :mod:`ground.searchmap.geotiff`):
  each tile is reprojected on demand (``rasterio.warp.reproject`` into the tile's
  EPSG:3857 box, 256 x 256, transparent outside the raster) and kept in a bounded cache.

Everything a request names is bounded before anything is read: zoom 0-24 and within the
basemap's own range, column and row within ``2**z``; a GeoTIFF serves no zoom coarser
than :data:`MAX_DECIMATION` source pixels per tile pixel beyond its coarsest overview, so
no request makes the station read or warp more than about 2048 x 2048 source pixels (and
the cache holds at most :data:`CACHE_TILES` tiles).
"""

from __future__ import annotations

import math
import sqlite3
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from holescan.errors import InputError

__all__ = [
    "CACHE_TILES",
    "MAX_DECIMATION",
    "MAX_TILE_BYTES",
    "MAX_VIEW_M",
    "MAX_VIEW_TILES",
    "MAX_ZOOM",
    "Basemap",
    "BasemapInfo",
    "GeoTiffBasemap",
    "MBTilesBasemap",
    "lonlat_of_mercator",
    "mercator_of_lonlat",
    "open_basemap",
    "tile_bounds_m",
    "view_tiles",
]

TILE_PX = 256
MAX_ZOOM = 24
"""Finest zoom served (about 1 cm a pixel at the equator)."""
MAX_TILE_BYTES = 4 * 1024 * 1024
"""Largest MBTiles tile read (a 256 px tile is tens of kB)."""
MAX_DECIMATION = 8
"""Source pixels per tile pixel beyond the coarsest overview: 2048 x 2048 read at most."""
CACHE_TILES = 512
"""GeoTIFF tiles rendered and kept (about 50-100 MB at most)."""
_R = 6378137.0
_HALF = math.pi * _R  # half the Web Mercator world, metres


def tile_bounds_m(z: int, x: int, y: int) -> tuple[float, float, float, float]:
    """(west, south, east, north) of XYZ tile ``z/x/y`` in EPSG:3857 metres.

    >>> [round(v) for v in tile_bounds_m(1, 0, 0)]
    [-20037508, 0, 0, 20037508]
    """
    size = 2 * _HALF / (1 << z)
    west, north = -_HALF + x * size, _HALF - y * size
    return west, north - size, west + size, north


def mercator_of_lonlat(lon_deg: float, lat_deg: float) -> tuple[float, float]:
    """EPSG:4326 degrees -> EPSG:3857 metres (latitude clipped to the Mercator world).

    >>> [round(v, 3) + 0.0 for v in mercator_of_lonlat(0.0, 0.0)]  # + 0.0: no -0.0
    [0.0, 0.0]
    """
    lat = max(-85.05112878, min(85.05112878, lat_deg))
    x = math.radians(lon_deg) * _R
    y = math.log(math.tan(math.pi / 4 + math.radians(lat) / 2)) * _R
    return x, y


def lonlat_of_mercator(x: float, y: float) -> tuple[float, float]:
    """EPSG:3857 metres -> (lon, lat) degrees.

    >>> [round(v, 9) for v in lonlat_of_mercator(*mercator_of_lonlat(-79.3832, 43.6532))]
    [-79.3832, 43.6532]
    """
    return math.degrees(x / _R), math.degrees(2 * math.atan(math.exp(y / _R)) - math.pi / 2)


def _kind_of(data: bytes) -> str | None:
    """The image type of a tile's bytes (None: not PNG, JPEG or WebP)."""
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        return "image/png"
    if data.startswith(b"\xff\xd8\xff"):
        return "image/jpeg"
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "image/webp"
    return None


@dataclass(frozen=True)
class BasemapInfo:
    """What the page is told of a basemap: its name, kind (``mbtiles`` / ``geotiff``),
    zoom range and extent (west, south, east, north degrees)."""

    name: str
    kind: str
    minzoom: int
    maxzoom: int
    bounds: tuple[float, float, float, float]


class Basemap(Protocol):
    """A source of XYZ tiles."""

    info: BasemapInfo

    def tile(self, z: int, x: int, y: int) -> tuple[bytes, str] | None:
        """Tile ``z/x/y`` (bytes, content type), or None: none there, or out of range."""
        ...

    def close(self) -> None: ...


def _in_range(info: BasemapInfo, z: int, x: int, y: int) -> bool:
    return info.minzoom <= z <= info.maxzoom and 0 <= x < (1 << z) and 0 <= y < (1 << z)


class MBTilesBasemap:
    """An MBTiles file of raster tiles, opened read-only (see the module docstring)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self._db = sqlite3.connect(
                f"{path.resolve().as_uri()}?mode=ro", uri=True, check_same_thread=False
            )
            meta = dict(self._db.execute("SELECT name, value FROM metadata").fetchall())
            fmt = str(meta.get("format", "png")).lower()
            if fmt not in ("png", "jpg", "jpeg", "webp"):
                raise InputError(
                    f"basemap {path}: its tiles are {fmt!r}; the page shows raster tiles "
                    "(png, jpg, webp), not vector tiles"
                )
            zooms = self._zooms(meta)
            bounds = self._bounds(meta)
        except sqlite3.Error as err:
            raise InputError(f"basemap {path}: not an MBTiles file ({err})") from err
        self._lock = threading.Lock()
        name = str(meta.get("name") or path.stem)[:80]
        self.info = BasemapInfo(name, "mbtiles", zooms[0], zooms[1], bounds)

    def _zooms(self, meta: dict[str, str]) -> tuple[int, int]:
        try:
            lo, hi = int(meta["minzoom"]), int(meta["maxzoom"])
        except (KeyError, ValueError):
            row = self._db.execute("SELECT min(zoom_level), max(zoom_level) FROM tiles").fetchone()
            if row is None or row[0] is None:
                raise InputError(f"basemap {self.path}: it holds no tiles") from None
            lo, hi = int(row[0]), int(row[1])
        return max(0, min(lo, MAX_ZOOM)), max(0, min(hi, MAX_ZOOM))

    def _bounds(self, meta: dict[str, str]) -> tuple[float, float, float, float]:
        try:
            w, s, e, n = (float(v) for v in str(meta["bounds"]).split(","))
        except (KeyError, ValueError):
            return -180.0, -85.0511, 180.0, 85.0511  # the spec's default: the whole world
        if not all(math.isfinite(v) for v in (w, s, e, n)) or not (w < e and s < n):
            return -180.0, -85.0511, 180.0, 85.0511
        return w, s, e, n

    def tile(self, z: int, x: int, y: int) -> tuple[bytes, str] | None:
        if not _in_range(self.info, z, x, y):
            return None
        row = (1 << z) - 1 - y  # TMS rows count from the south
        with self._lock:
            got = self._db.execute(
                "SELECT tile_data FROM tiles WHERE zoom_level = ? AND tile_column = ? "
                "AND tile_row = ? AND length(tile_data) <= ?",
                (z, x, row, MAX_TILE_BYTES),
            ).fetchone()
        if got is None or not isinstance(got[0], bytes):
            return None
        kind = _kind_of(got[0])
        return None if kind is None else (got[0], kind)

    def close(self) -> None:
        self._db.close()


class GeoTiffBasemap:
    """A GeoTIFF reprojected to XYZ tiles on demand (see the module docstring)."""

    def __init__(self, path: Path, *, cache_tiles: int = CACHE_TILES) -> None:
        import rasterio
        import rasterio.warp
        from rasterio.errors import RasterioError

        self.path = path
        try:
            self._src = rasterio.open(path)
        except (RasterioError, OSError) as err:
            raise InputError(f"basemap {path}: not a GeoTIFF GDAL can read ({err})") from err
        src = self._src
        try:
            if src.crs is None:
                raise InputError(f"basemap {path}: it has no coordinate system (CRS)")
            if src.count not in (1, 3, 4) or any(d != "uint8" for d in src.dtypes):
                raise InputError(
                    f"basemap {path}: {src.count} band(s) of {src.dtypes[0]}; a basemap is an "
                    "8-bit grey, RGB or RGBA image (gdal_translate -ot Byte -scale)"
                )
            w, s, e, n = rasterio.warp.transform_bounds(src.crs, "EPSG:4326", *src.bounds)
            self._merc = rasterio.warp.transform_bounds(src.crs, "EPSG:3857", *src.bounds)
        except InputError:
            src.close()
            raise
        # zooms: the finest where a tile pixel is no finer than a source pixel; the
        # coarsest bounded by the overviews (a tile never reads more than ~2048 px a side)
        px_m = (self._merc[2] - self._merc[0]) / src.width
        finest = math.ceil(math.log2(2 * _HALF / TILE_PX / max(px_m, 1e-3)))
        maxzoom = max(0, min(MAX_ZOOM, finest))
        factor = max([1, *src.overviews(1)]) * MAX_DECIMATION
        minzoom = max(0, maxzoom - int(math.log2(factor)))
        self.info = BasemapInfo(path.stem[:80], "geotiff", minzoom, maxzoom, (w, s, e, n))
        self._lock = threading.Lock()
        self._cache: OrderedDict[tuple[int, int, int], bytes | None] = OrderedDict()
        self._cache_tiles = cache_tiles
        self.rendered = 0
        """Tiles reprojected so far (the cache's misses)."""

    def tile(self, z: int, x: int, y: int) -> tuple[bytes, str] | None:
        if not _in_range(self.info, z, x, y):
            return None
        key = (z, x, y)
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                data = self._cache[key]
            else:
                data = self._render(z, x, y)
                self._cache[key] = data
                while len(self._cache) > self._cache_tiles:
                    self._cache.popitem(last=False)
        return None if data is None else (data, "image/png")

    def _render(self, z: int, x: int, y: int) -> bytes | None:
        """The tile as an RGBA PNG, transparent outside the raster (None: no overlap)."""
        import rasterio
        from rasterio.enums import Resampling
        from rasterio.transform import from_bounds
        from rasterio.warp import reproject

        w, s, e, n = tile_bounds_m(z, x, y)
        mw, ms, me, mn = self._merc
        if e <= mw or w >= me or n <= ms or s >= mn:
            return None
        src = self._src
        bands = [1, 2, 3] if src.count >= 3 else [1]
        out = np.zeros((len(bands) + 1, TILE_PX, TILE_PX), np.uint8)
        reproject(
            rasterio.band(src, [*bands, 4] if src.count == 4 else bands),
            out,
            dst_transform=from_bounds(w, s, e, n, TILE_PX, TILE_PX),
            dst_crs="EPSG:3857",
            src_alpha=4 if src.count == 4 else 0,
            dst_alpha=len(bands) + 1,
            resampling=Resampling.bilinear,
        )
        self.rendered += 1
        if not out[-1].any():
            return None
        rgb = out[:3] if len(bands) == 3 else np.repeat(out[:1], 3, axis=0)
        bgra = np.stack([rgb[2], rgb[1], rgb[0], out[-1]], axis=-1)
        ok, buf = cv2.imencode(".png", np.ascontiguousarray(bgra))
        if not ok:  # cannot happen for a uint8 image
            raise ValueError("PNG encoding failed")
        return bytes(buf.tobytes())

    def close(self) -> None:
        self._src.close()


MAX_VIEW_TILES = 48
"""Most tiles one view of the page asks for (the zoom is lowered until they fit)."""
MAX_VIEW_M = 20_000.0
"""Largest view the page may ask for, metres from its origin."""


def view_tiles(
    info: BasemapInfo,
    origin: tuple[float, float],
    box_m: tuple[float, float, float, float],
    width_px: int,
) -> list[tuple[int, int, int, tuple[float, float, float, float]]]:
    """The tiles that fill a view of the page: (z, x, y, (x0, y0, x1, y1) in the page's
    local metres) for each; empty when the view lies outside the basemap or the zoom it
    needs is coarser than the basemap's coarsest.

    origin : (lat, lon) of the page's local frame. box_m : (west, south, east, north) of
    the view in its metres (within :data:`MAX_VIEW_M`). width_px : the view's width.
    """
    from holescan.geotag import LocalFrame

    frame = LocalFrame(*origin)
    x0, y0, x1, y1 = box_m
    lats, lons = frame.to_geodetic(np.array([x0, x1, x0, x1]), np.array([y0, y0, y1, y1]))
    bw, bs, be, bn = info.bounds
    west, east = max(float(lons.min()), bw), min(float(lons.max()), be)
    south, north = max(float(lats.min()), bs), min(float(lats.max()), bn)
    if west >= east or south >= north:
        return []
    mw, ms = mercator_of_lonlat(west, south)
    me, mn = mercator_of_lonlat(east, north)
    # ground metres a page pixel -> Web Mercator metres a pixel -> the zoom that gives them
    scale = 1.0 / max(math.cos(math.radians(origin[0])), 1e-6)
    merc_per_px = (x1 - x0) / max(width_px, 1) * scale
    z = math.ceil(math.log2(2 * _HALF / TILE_PX / max(merc_per_px, 1e-3)))
    z = min(info.maxzoom, max(info.minzoom, z, 0))
    while True:
        n = 1 << z
        size = 2 * _HALF / n
        c0, c1 = math.floor((mw + _HALF) / size), math.floor((me + _HALF) / size)
        r0, r1 = math.floor((_HALF - mn) / size), math.floor((_HALF - ms) / size)
        cols, rows = range(max(0, c0), min(n, c1 + 1)), range(max(0, r0), min(n, r1 + 1))
        if len(cols) * len(rows) <= MAX_VIEW_TILES:
            break
        if z <= info.minzoom:
            return []
        z -= 1
    out = []
    for tx in cols:
        for ty in rows:
            tw, ts, te, tn = tile_bounds_m(z, tx, ty)
            lon_w, lat_s = lonlat_of_mercator(tw, ts)
            lon_e, lat_n = lonlat_of_mercator(te, tn)
            e_sw, n_sw = frame.to_en(lat_s, lon_w)
            e_ne, n_ne = frame.to_en(lat_n, lon_e)
            x0_, y0_, x1_, y1_ = (round(float(v), 3) for v in (e_sw, n_sw, e_ne, n_ne))
            out.append((z, tx, ty, (x0_, y0_, x1_, y1_)))
    return out


def open_basemap(path: Path) -> Basemap:
    """The basemap of a file: ``.mbtiles`` or a GeoTIFF (``.tif``, ``.tiff``).

    Raises
    ------
    InputError : no such file, another kind of file, or one that cannot be a basemap.
    """
    if not path.is_file():
        raise InputError(f"basemap {path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".mbtiles":
        return MBTilesBasemap(path)
    if suffix in (".tif", ".tiff"):
        return GeoTiffBasemap(path)
    raise InputError(
        f"basemap {path}: give an MBTiles file (.mbtiles) or a GeoTIFF (.tif), "
        "e.g. an earlier sortie's NAME_ortho.tif"
    )
