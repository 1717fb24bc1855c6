"""Several flights on one station: their tiles combined per cell (a second sortie's "not
seen" never hides what the first saw), and the map served only past the page's guard."""

from __future__ import annotations

import http.client
import json
import urllib.request
from pathlib import Path

import cv2
import numpy as np

from holescan.geotag import LocalFrame
from holescan.ground.station import StationState, StationWeb
from holescan.ground.station.mapcombine import combine
from holescan.ground.station.maplayers import map_document, map_route
from holescan.ground.station.mapstore import MapStore
from holescan.missions import (
    TileFacts,
    coverage_from_levels,
    encode_coverage_tile,
    encode_ortho_tile,
    read_tile,
)

N = 32
CELL = 0.1
LAT0, LON0 = 43.6532, -79.3832
RED, BLUE = (200, 30, 30), (30, 30, 200)


def put(
    store: MapStore,
    map_id: int,
    origin: tuple[float, float],
    tx: int,
    cov: np.ndarray,
    rgb: tuple[int, int, int],
) -> None:
    """One flight's coverage and orthophoto tile (tx, 0)."""
    lat, lon = origin
    f = TileFacts(map_id, "cov", tx, 0, N, CELL, lat, lon, 1)
    o = TileFacts(map_id, "ortho", tx, 0, N, CELL, lat, lon, 1)
    img = np.zeros((N, N, 3), np.uint8)
    img[...] = rgb
    assert store.put(encode_coverage_tile(cov, f)) is not None
    assert store.put(encode_ortho_tile(img, cov > 0, o, max_bytes=4000)) is not None


def two_flights(folder: Path) -> tuple[MapStore, float, float]:
    """Flight 1 saw east 0-2.4 m (coverage 0.5, red ground); flight 2, its origin 1.6 m
    east, saw only its own east 0.5-1.5 m (base 2.1-3.1 m; coverage 0.9, blue ground) and
    "not seen" over the rest of its two tiles, which lie over flight 1's."""
    store = MapStore.open(folder)
    c1 = np.zeros((N, N))
    c1[:, :24] = 0.5
    put(store, 1, (LAT0, LON0), 0, c1, RED)
    lat2, lon2 = LocalFrame(LAT0, LON0).to_geodetic(1.6, 0.0)
    origin2 = (float(lat2), float(lon2))
    c2 = np.zeros((N, N))
    c2[:, 5:15] = 0.9
    put(store, 2, origin2, 0, c2, BLUE)
    put(store, 2, origin2, -1, np.zeros((N, N)), BLUE)
    # the coverage each look carries down the link (sixteenths)
    f = TileFacts(1, "cov", 0, 0, N, CELL, 0, 0, 1)
    p1, p2 = (coverage_from_levels(read_tile(encode_coverage_tile(c, f))[1]) for c in (c1, c2))  # type: ignore[index]
    return store, float(p1[0, 0]), float(p2[0, 5])


def col(east_m: float) -> int:
    """The combined raster's column of a base-frame east (its west edge is tile 0's)."""
    return int(east_m / CELL)


def test_flights_combine_per_cell_pod_and_best_look(tmp_path: Path) -> None:
    store, p1, p2 = two_flights(tmp_path / "map")
    c = combine(store)
    assert c is not None and c.base.map_id == 1  # the first flight's grid
    assert (c.tx0, c.ty1) == (-1, 0) and c.cov.shape == (N, 3 * N)  # base tiles -1, 0, 1
    off = N  # tile 0 starts one tile east of the raster's west edge
    row = N // 2
    # flight 2 saw nothing here: flight 1's look stays
    assert abs(c.cov[row, off + col(1.05)] - p1) < 1e-9
    # both saw: probability of detection of two independent looks
    assert abs(c.cov[row, off + col(2.25)] - (1 - (1 - p1) * (1 - p2))) < 1e-9
    # flight 2 alone
    assert abs(c.cov[row, off + col(2.75)] - p2) < 1e-9
    # nobody: not seen (flight 2's tile west of flight 1's)
    assert c.cov[row, off - 5] == 0.0 and c.cov[row, off + col(3.5)] == 0.0

    # orthophoto: the better look's colour (flight 2 at 0.9 over flight 1 at 0.5)
    def near(a: np.ndarray, b: tuple[int, int, int]) -> bool:
        return bool(np.abs(a.astype(int) - b).max() < 40)

    assert near(c.rgb[row, off + col(1.05)], RED)
    assert near(c.rgb[row, off + col(2.25)], BLUE)
    assert near(c.rgb[row, off + col(2.75)], BLUE)
    assert not c.has_rgb[row, off + col(3.5)]


def test_page_gets_one_tile_per_place_and_seen_stays_green(tmp_path: Path) -> None:
    store, _, _ = two_flights(tmp_path / "map")
    doc = map_document(store, None)
    tiles = doc["tiles"]
    assert isinstance(tiles, list)
    places = [(t["layer"], t["x0"], t["y0"]) for t in tiles]
    assert len(places) == len(set(places)) == 6  # 3 places x 2 layers, whatever the flights
    cov0 = next(t for t in tiles if t["layer"] == "cov" and t["x0"] == 0.0)
    code, body, ctype = map_route(store, cov0["href"].split("?")[0])  # type: ignore[misc]
    assert code == 200 and ctype == "image/png"
    bgra = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_UNCHANGED)
    assert bgra is not None
    view = bgra[..., [2, 1, 0, 3]]
    green, red = (46, 125, 50, 45), (211, 47, 47, 110)
    assert tuple(view[N // 2, col(1.05)]) == green  # flight 2's "not seen" did not hide it
    assert tuple(view[N // 2, col(2.75)]) == green
    assert tuple(view[N // 2, col(3.15)]) == red  # nobody saw it
    # a tile arriving later changes the ?v= of its place only
    before = {t["href"] for t in tiles}
    put(store, 2, (LAT0, LON0), 5, np.full((N, N), 0.3), BLUE)
    after = {t["href"] for t in map_document(store, None)["tiles"]}  # type: ignore[attr-defined]
    assert before <= after and len(after - before) == 2


def test_map_served_only_past_the_guard(tmp_path: Path) -> None:
    state = StationState.open(tmp_path / "station")
    store, _, _ = two_flights(tmp_path / "station" / "map")
    with StationWeb(state, port=0, map_store=store, names=()) as web:
        with urllib.request.urlopen(web.url + "map.json", timeout=5) as r:
            assert len(json.loads(r.read())["tiles"]) == 6
        with urllib.request.urlopen(web.url + "map/all/cov-0_0.png", timeout=5) as r:
            assert r.headers["Content-Type"] == "image/png"
            assert r.headers["X-Content-Type-Options"] == "nosniff"
        for path, headers, code in (
            ("/map.json", {"Host": "evil.example"}, 403),  # DNS rebinding
            ("/map/all/cov-0_0.png", {"Origin": "http://evil.example"}, 403),
            ("/map/all/cov-9_9.png", {}, 404),
            ("/map/all/cov-0_0.png/../../station.json", {}, 404),
        ):
            conn = http.client.HTTPConnection("127.0.0.1", web.port, timeout=5)
            conn.request("GET", path, headers=headers)
            assert conn.getresponse().status == code, path
            conn.close()
