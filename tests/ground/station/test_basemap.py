"""Offline basemaps: an MBTiles file made here (sqlite3), a GeoTIFF written with rasterio and
an earlier sortie's orthophoto (the search map's ``NAME_ortho.tif``), served as XYZ tiles
by the station; hostile tile and view requests bounded."""

from __future__ import annotations

import json
import math
import sqlite3
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from holescan.errors import InputError
from holescan.geotag import LocalFrame
from holescan.ground.searchmap import write_map_geotiffs
from holescan.ground.station import StationState, StationWeb
from holescan.ground.station.basemap import (
    MAX_VIEW_TILES,
    GeoTiffBasemap,
    MBTilesBasemap,
    mercator_of_lonlat,
    open_basemap,
    tile_bounds_m,
)
from holescan.ground.station.maplayers import basemap_route
from holescan.mapping import MapGrid, MapLayers

LAT0, LON0 = 43.6532, -79.3832


def _xyz(lon: float, lat: float, z: int) -> tuple[int, int]:
    x, y = mercator_of_lonlat(lon, lat)
    size = 2 * math.pi * 6378137.0 / (1 << z)
    return int((x + math.pi * 6378137.0) // size), int((math.pi * 6378137.0 - y) // size)


def _png(colour: tuple[int, int, int]) -> bytes:
    img = np.zeros((256, 256, 3), np.uint8)
    img[...] = colour[::-1]
    return bytes(cv2.imencode(".png", img)[1].tobytes())


def make_mbtiles(path: Path, zooms: range = range(16, 19)) -> dict[tuple[int, int, int], bytes]:
    """Tiles around (LAT0, LON0): at each zoom the tile holding it (red) and its east
    neighbour (blue), rows stored TMS-style; returns {(z, x, y): bytes} in XYZ."""
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE metadata (name text, value text)")
    db.execute(
        "CREATE TABLE tiles (zoom_level integer, tile_column integer, tile_row integer, "
        "tile_data blob)"
    )
    meta = {"name": "street plan", "format": "png", "minzoom": str(zooms.start),
            "maxzoom": str(zooms.stop - 1), "bounds": f"{LON0 - .01},{LAT0 - .01},"
            f"{LON0 + .01},{LAT0 + .01}"}  # fmt: skip
    db.executemany("INSERT INTO metadata VALUES (?, ?)", meta.items())
    out = {}
    for z in zooms:
        x, y = _xyz(LON0, LAT0, z)
        for dx, colour in ((0, (255, 0, 0)), (1, (0, 0, 255))):
            data = _png(colour)
            tms_row = (1 << z) - 1 - y
            db.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)", (z, x + dx, tms_row, data))
            out[(z, x + dx, y)] = data
    db.commit()
    db.close()
    return out


def make_geotiff(path: Path) -> None:
    """A 200 x 160 px RGB GeoTIFF in UTM 17N at 0.25 m around (LAT0, LON0): west half
    green, east half white."""
    e0, n0 = 630_000.0, 4_834_500.0  # near the centre (converted below)
    from rasterio.warp import transform

    (e,), (n,) = transform("EPSG:4326", "EPSG:32617", [LON0], [LAT0])
    e0, n0 = round(e) - 25.0, round(n) + 20.0
    rgb = np.zeros((3, 160, 200), np.uint8)
    rgb[1, :, :100] = 200
    rgb[:, :, 100:] = 255
    prof = {"driver": "GTiff", "width": 200, "height": 160, "count": 3, "dtype": "uint8",
            "crs": "EPSG:32617", "transform": from_origin(e0, n0, 0.25, 0.25)}  # fmt: skip
    with rasterio.open(path, "w", **prof) as dst:
        dst.write(rgb)


def _decode(data: bytes) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert img is not None
    return img


def test_mbtiles_rows_flip_and_requests_are_bounded(tmp_path: Path) -> None:
    tiles = make_mbtiles(tmp_path / "plan.mbtiles")
    b = open_basemap(tmp_path / "plan.mbtiles")
    assert isinstance(b, MBTilesBasemap)
    assert (b.info.name, b.info.minzoom, b.info.maxzoom) == ("street plan", 16, 18)
    for (z, x, y), data in tiles.items():
        assert b.tile(z, x, y) == (data, "image/png")  # XYZ asked, TMS row read
        assert b.tile(z, x, (1 << z) - 1 - y) is None  # the unflipped row holds nothing
    z, x, y = next(iter(tiles))
    for bad in ((z, -1, y), (z, 1 << z, y), (z, x, 1 << z), (25, x, y), (15, x // 2, y // 2)):
        assert b.tile(*bad) is None
    routes = [b]
    assert basemap_route(routes, f"/basemap/0/{z}/{x}/{y}") == (200, tiles[(z, x, y)], "image/png")
    hostile = ("/basemap/0/99/0/0", "/basemap/0/1/2/3/4", f"/basemap/0/{z}/{x}/123456789",
               "/basemap/../x", "/basemap/0/-1/0/0", f"/basemap/1/{z}/{x}/{y}")  # fmt: skip
    for path in hostile:
        got = basemap_route(routes, path)
        assert got is not None and got[0] == 404, path
    # the file is opened read-only: the station cannot change it
    with pytest.raises(sqlite3.OperationalError):
        b._db.execute("DELETE FROM tiles")
    b.close()


def test_view_fills_the_page_with_tiles_at_its_scale(tmp_path: Path) -> None:
    make_mbtiles(tmp_path / "plan.mbtiles", range(12, 19))
    b = open_basemap(tmp_path / "plan.mbtiles")
    q = f"lat={LAT0}&lon={LON0}&x0=-40&y0=-30&x1=40&y1=30&px=800"
    code, body, _ = basemap_route([b], "/basemap/0/view.json", q)  # type: ignore[misc]
    assert code == 200
    tiles = json.loads(body)["tiles"]
    assert 1 <= len(tiles) <= MAX_VIEW_TILES
    z = int(tiles[0]["href"].split("/")[3])
    assert z == 18  # 0.1 m a page pixel: the finest the file has
    frame = LocalFrame(LAT0, LON0)
    for t in tiles:
        *_, zs, xs, ys = t["href"].split("/")
        w, _, e, _ = tile_bounds_m(int(zs), int(xs), int(ys))
        assert t["x1"] - t["x0"] == pytest.approx((e - w) * math.cos(math.radians(LAT0)), rel=0.01)
        assert t["x0"] < 40 and t["x1"] > -40 and t["y0"] < 30 and t["y1"] > -30
    x, y = _xyz(LON0, LAT0, 18)
    (home,) = [t for t in tiles if t["href"] == f"/basemap/0/18/{x}/{y}"]
    assert home["x0"] <= 0 <= home["x1"] and home["y0"] <= 0 <= home["y1"]
    assert frame.to_en(LAT0, LON0) == (0.0, 0.0)
    # a wide view takes a coarser zoom, never more than MAX_VIEW_TILES tiles
    wide = f"lat={LAT0}&lon={LON0}&x0=-5000&y0=-5000&x1=5000&y1=5000&px=8000"
    code, body, _ = basemap_route([b], "/basemap/0/view.json", wide)  # type: ignore[misc]
    got = json.loads(body)["tiles"]
    assert code == 200 and len(got) <= MAX_VIEW_TILES
    (zw,) = {int(t["href"].split("/")[3]) for t in got}
    assert 12 <= zw < 18  # coarser (the view is clipped to the file's bounds first)
    for bad in ("", f"lat={LAT0}&lon={LON0}&x0=0&y0=0&x1=-1&y1=1&px=10",
                f"lat={LAT0}&lon={LON0}&x0=-1e9&y0=0&x1=1&y1=1&px=10",
                f"lat={LAT0}&lon={LON0}&x0=nan&y0=0&x1=1&y1=1&px=10",
                f"lat={LAT0}&lon={LON0}&x0=0&y0=0&x1=1&y1=1&px=99999",
                "lat=91&lon=0&x0=0&y0=0&x1=1&y1=1&px=10"):  # fmt: skip
        got2 = basemap_route([b], "/basemap/0/view.json", bad)
        assert got2 is not None and got2[0] == 400, bad
    b.close()


def test_geotiff_tiles_reprojected_on_demand_and_cached(tmp_path: Path) -> None:
    make_geotiff(tmp_path / "plan.tif")
    b = open_basemap(tmp_path / "plan.tif")
    assert isinstance(b, GeoTiffBasemap)
    assert b.info.kind == "geotiff" and b.info.maxzoom == 19  # 0.25 m pixels
    assert b.info.minzoom == 16  # no overviews: at most 8 source pixels a tile pixel
    w, s, e, n = b.info.bounds
    assert w < LON0 < e and s < LAT0 < n
    x, y = _xyz(LON0, LAT0, 19)
    got = b.tile(19, x, y)
    assert got is not None and got[1] == "image/png"
    img = _decode(got[0])
    assert img.shape == (256, 256, 4)
    inside = img[..., 3] == 255
    assert inside.mean() > 0.2
    colours = {tuple(int(v) for v in c) for c in img[inside][:, :3]}
    assert (0, 200, 0) in colours and (255, 255, 255) in colours  # BGR: green and white
    rendered = b.rendered
    assert b.tile(19, x, y) == got and b.rendered == rendered  # from the cache
    assert b.tile(19, x + 50, y) is None  # beyond the raster: nothing drawn, 404
    for bad in ((15, x >> 4, y >> 4), (20, 2 * x, 2 * y), (19, -1, 0)):
        assert b.tile(*bad) is None  # coarser than its overviews allow, finer than it
    b.close()


def test_an_earlier_sorties_orthophoto_is_a_basemap(tmp_path: Path) -> None:
    grid = MapGrid(-10.0, 10.0, 0.05, 400, 400)
    layers = MapLayers.empty(grid)
    layers.rgb[...] = (180, 90, 40)
    layers.height_m[...] = 0.0
    layers.looks[...] = 1
    frame = LocalFrame(LAT0, LON0, 80.0)
    (ortho, path), *_ = write_map_geotiffs(tmp_path, "sortie1", layers, frame)
    assert ortho == "ortho"
    b = open_basemap(path)
    x, y = _xyz(LON0, LAT0, 19)
    got = b.tile(19, x, y)
    assert got is not None
    img = _decode(got[0])
    solid = img[img[..., 3] == 255]
    assert len(solid) > 1000 and (np.abs(solid[:, :3].astype(int) - (40, 90, 180)) <= 2).all()
    b.close()


def test_bad_basemaps_are_one_clear_line(tmp_path: Path) -> None:
    (tmp_path / "x.mbtiles").write_bytes(b"not sqlite at all" * 100)
    (tmp_path / "x.tif").write_bytes(b"II*\x00 not a tiff")
    (tmp_path / "x.png").write_bytes(b"\x89PNG")
    vec = tmp_path / "v.mbtiles"
    make_mbtiles(vec)
    with sqlite3.connect(vec) as db:
        db.execute("UPDATE metadata SET value = 'pbf' WHERE name = 'format'")
    for path, why in (
        (tmp_path / "none.mbtiles", "no such file"),
        (tmp_path / "x.mbtiles", "not an MBTiles file"),
        (tmp_path / "x.tif", "not a GeoTIFF"),
        (tmp_path / "x.png", "give an MBTiles file"),
        (vec, "not vector tiles"),
    ):
        with pytest.raises(InputError, match=why):
            open_basemap(path)
    prof = {"driver": "GTiff", "width": 4, "height": 4, "count": 1, "dtype": "float32",
            "crs": "EPSG:32617", "transform": from_origin(0, 0, 1, 1)}  # fmt: skip
    with rasterio.open(tmp_path / "dem.tif", "w", **prof) as dst:
        dst.write(np.zeros((1, 4, 4), np.float32))
    with pytest.raises(InputError, match="8-bit"):
        open_basemap(tmp_path / "dem.tif")


def test_station_serves_basemaps(tmp_path: Path) -> None:
    tiles = make_mbtiles(tmp_path / "plan.mbtiles")
    make_geotiff(tmp_path / "plan.tif")
    maps = [open_basemap(tmp_path / "plan.mbtiles"), open_basemap(tmp_path / "plan.tif")]
    state = StationState.open(tmp_path / "st")
    with StationWeb(state, "127.0.0.1", 0, basemaps=maps) as web:
        with urllib.request.urlopen(f"{web.url}basemaps.json", timeout=10) as r:
            doc = json.loads(r.read())
        assert [(m["id"], m["kind"]) for m in doc["basemaps"]] == [(0, "mbtiles"), (1, "geotiff")]
        (z, x, y), data = next(iter(tiles.items()))
        with urllib.request.urlopen(f"{web.url}basemap/0/{z}/{x}/{y}", timeout=10) as r:
            assert r.read() == data and r.headers["Content-Type"] == "image/png"
            assert "max-age" in r.headers["Cache-Control"]
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(f"{web.url}basemap/1/3/0/0", timeout=10)
        assert err.value.code == 404
    for m in maps:
        m.close()
