"""The station's live map: tiles kept on disk across restarts, served to the page, drawn
and toggled in headless Chromium."""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest

from holescan.geotag import LocalFrame
from holescan.ground.station import StationState, StationWeb, TrackPoint
from holescan.ground.station.maplayers import map_document, map_route
from holescan.ground.station.mapstore import MapStore
from holescan.missions import TileFacts, encode_coverage_tile, encode_ortho_tile, read_tile

N = 32
CELL = 0.1
LAT0, LON0 = 43.6532, -79.3832
ROOT = Path(__file__).resolve().parents[3]


def tile_pair(tx: int, ty: int, v: int = 1, map_id: int = 9) -> tuple[bytes, bytes]:
    """A coverage and an orthophoto tile: a seen disc over a brick pattern."""
    yy, xx = np.mgrid[0:N, 0:N]
    cx, cy = (2 - tx) * N * 0.7, (ty + 1) * N * 0.5
    seen = (xx - cx) ** 2 + (yy - cy) ** 2 < (1.6 * N) ** 2
    cov = np.where(seen, 0.9, 0.0)
    rgb = np.zeros((N, N, 3), np.uint8)
    rgb[...] = (150, 120, 90)
    rgb[(yy // 4 + xx // 8) % 2 == 0] = (110, 100, 95)
    f = TileFacts(map_id, "cov", tx, ty, N, CELL, LAT0, LON0, v)
    o = TileFacts(map_id, "ortho", tx, ty, N, CELL, LAT0, LON0, v)
    return encode_coverage_tile(cov, f), encode_ortho_tile(rgb, seen, o)


def test_store_keeps_newest_tiles_atomically_and_reads_them_back(tmp_path: Path) -> None:
    store = MapStore.open(tmp_path / "map")
    seen_versions: list[int] = []
    store.listeners.append(seen_versions.append)
    cov, ortho = tile_pair(0, 0, v=3)
    assert store.put(cov) is not None and store.put(ortho) is not None
    old_cov, _ = tile_pair(0, 0, v=2)
    assert store.put(old_cov) is None  # stale: the newer one is kept
    assert store.put(b"\xff\xd8\xff\xd9") is None and store.rejected == 1
    new_cov, _ = tile_pair(0, 0, v=4)
    assert store.put(new_cov) is not None
    assert seen_versions == [1, 2, 3]
    files = sorted(p.name for p in (tmp_path / "map").iterdir())
    assert files == ["m9-cov-0_0.png", "m9-ortho-0_0.jpg"]  # no .part left behind
    assert (tmp_path / "map" / "m9-cov-0_0.png").read_bytes() == new_cov
    # a foreign file in the folder is skipped, the tiles survive a restart
    (tmp_path / "map" / "m9-cov-5_5.png").write_bytes(b"not a png")
    again = MapStore.open(tmp_path / "map")
    assert [t.name for t in again.tiles()] == ["m9-cov-0_0.png", "m9-ortho-0_0.jpg"]
    assert again.get("m9-cov-0_0.png").facts.version == 4  # type: ignore[union-attr]
    mosaic = again.coverage(9)
    assert mosaic is not None
    raster, sw = mosaic
    assert raster.shape == (N, N) and (sw.tx, sw.ty) == (0, 0)
    assert np.array_equal(raster > 0, read_tile(new_cov)[1] > 0)  # type: ignore[index]


def test_route_places_tiles_in_page_metres_and_refuses_anything_else(tmp_path: Path) -> None:
    store = MapStore.open(tmp_path / "map")
    for tx, ty in ((0, 0), (-1, 0)):
        for data in tile_pair(tx, ty):
            store.put(data)
    # the page's origin 10 m east and 5 m north of the map's
    page = LocalFrame(LAT0, LON0).to_geodetic(10.0, 5.0)
    doc = map_document(store, (float(page[0]), float(page[1])))
    t = next(t for t in doc["tiles"] if t["layer"] == "cov" and "0_0" in t["href"])  # type: ignore[attr-defined]
    assert abs(t["x0"] + 10.0) < 0.01 and abs(t["y0"] + 5.0) < 0.01
    assert abs(t["x1"] - t["x0"] - N * CELL) < 1e-6
    code, body, ctype = map_route(store, "/map.json", f"lat={page[0]}&lon={page[1]}")  # type: ignore[misc]
    assert code == 200 and len(json.loads(body)["tiles"]) == 4
    code, body, ctype = map_route(store, "/map/view/m9-cov-0_0.png")  # type: ignore[misc]
    view = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_UNCHANGED)
    assert code == 200 and ctype == "image/png" and view.shape == (N, N, 4)
    assert map_route(store, "/map/m9-ortho-0_0.jpg")[0] == 200  # type: ignore[index]
    for bad in (
        "/map/../station.json",
        "/map/m9-cov-0_0.png/../../x",
        "/map/view/m9-ortho-0_0.jpg",
        "/map/m9-cov-7_7.png",
        "/map/%2e%2e/station.json",
        "/map/" + "m" * 5000,
    ):
        assert map_route(store, bad)[0] == 404, bad  # type: ignore[index]
    # garbage origins fall back to the map's own
    for q in ("lat=nan&lon=0", "lat=1e999&lon=2", "lat=x", "lat=91&lon=0", "&" * 500):
        code, body, _ = map_route(store, "/map.json", q)  # type: ignore[misc]
        assert code == 200 and json.loads(body)["origin"] == [LAT0, LON0]
    assert map_route(store, "/state.json") is None
    assert map_route(None, "/map.json")[0] == 200  # type: ignore[index]


@pytest.mark.skipif(not Path("/usr/bin/chromium").exists(), reason="needs chromium")
def test_page_draws_the_layers_and_toggles_them(tmp_path: Path) -> None:
    from test_station import wait_for
    from test_station_flight import Chromium

    state = StationState.open(tmp_path / "station")
    frame = LocalFrame(LAT0, LON0)
    for i in range(40):  # a lawnmower over the tiles
        e, n = (i % 20) * 0.3 - 3.0, -1.0 + 2.0 * (i // 20)
        lat, lon = frame.to_geodetic(e, n)
        state.on_position(TrackPoint(i * 10**9, float(lat), float(lon), 3.0, 1.5708), 0.0)
    store = MapStore.open(tmp_path / "station" / "map")
    for tx in (-2, -1, 0, 1):
        for ty in (-1, 0):
            for data in tile_pair(tx, ty):
                store.put(data)
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    with StationWeb(state, port=0, map_store=store) as web:
        with pytest.raises(urllib.error.HTTPError, match="404"):
            urllib.request.urlopen(web.url + "map/view/..%2fstation.json", timeout=5)
        browser = Chromium(web.url, tmp_path / "profile")
        try:
            count = "document.querySelectorAll('g.maplayer[data-layer=\"%s\"] image').length"
            wait_for(lambda: browser.js(count % "cov") == 8, 20.0, "coverage tiles drawn")
            assert browser.js(count % "ortho") == 8
            # the layers lie under the track: drawn first
            first = browser.js("document.querySelector('#svg').firstElementChild.dataset.layer")
            assert first == "ortho"
            # every tile image loaded (offline: from the station itself)
            wait_for(
                lambda: browser.js(
                    "Promise.all([...document.querySelectorAll('g.maplayer image')].map("
                    "i => fetch(i.href.baseVal).then(r => r.ok))).then(a => a.every(x => x))"
                ),
                10.0,
                "tile images",
            )
            browser.screenshot(art / "live-map-layers.png")
            browser.js("document.getElementById('layer-cov').click()")
            wait_for(lambda: browser.js(count % "cov") == 0, 5.0, "coverage hidden")
            assert browser.js(count % "ortho") == 8
            browser.js("document.getElementById('layer-ortho').click()")
            wait_for(lambda: browser.js(count % "ortho") == 0, 5.0, "orthophoto hidden")
            browser.js("document.getElementById('layer-cov').click()")
            wait_for(lambda: browser.js(count % "cov") == 8, 5.0, "coverage shown again")
            # north arrow and scale bar are still there
            assert "N" in browser.js("document.querySelector('#svg').textContent")
            assert " m" in browser.js("document.querySelector('#svg').textContent")
            # a new tile shows up without a reload (the page polls the map)
            for data in tile_pair(2, 0):
                store.put(data)
            wait_for(lambda: browser.js(count % "cov") == 9, 10.0, "a new tile drawn")
        finally:
            browser.close()
    assert (art / "live-map-layers.png").stat().st_size > 10_000
