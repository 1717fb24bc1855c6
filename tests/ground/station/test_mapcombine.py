"""Several flights on one station: their tiles combined per cell (a second sortie's "not
seen" never hides what the first saw), and the map served only past the page's guard."""

from __future__ import annotations

import http.client
import json
import urllib.request
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from holescan.geotag import LocalFrame
from holescan.ground.station import StationState, StationWeb, TrackPoint
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


def _square(seen_inside: bool) -> np.ndarray:
    """Coverage 0.9 inside the 1.2 m square [10:22, 10:22] of a tile and 0 outside it, or
    the other way round."""
    inside = np.zeros((N, N), bool)
    inside[10:22, 10:22] = True
    return np.where(inside == seen_inside, 0.9, 0.0)


def two_drones(folder: Path) -> MapStore:
    """Drone 1 searched tile (0, 0) but a 1.2 m square; drone 2 searched only that square.
    Both maps have the same map id (their tiles are told apart by the vehicle)."""
    store = MapStore.open(folder)
    for sysid, inside in ((1, False), (2, True)):
        f = TileFacts(7, "cov", 0, 0, N, CELL, LAT0, LON0, 1)
        assert store.put(encode_coverage_tile(_square(inside), f), sysid) is not None
    return store


def test_each_drone_has_its_own_coverage_and_gaps_are_where_none_searched(
    tmp_path: Path,
) -> None:
    from holescan.ground.searchmap import find_gaps
    from holescan.ground.station.feeds import GapsCache, combined_layers
    from holescan.ground.station.mapcombine import CombinedCache

    store = two_drones(tmp_path / "map")
    names = sorted(t.name for t in store.tiles())
    assert names == ["v1-m7-cov-0_0.png", "v2-m7-cov-0_0.png"]
    again = MapStore.open(tmp_path / "map")  # a restart keeps whose tile is whose
    assert [(t.name, t.sysid) for t in again.tiles()] == [(names[0], 1), (names[1], 2)]
    assert again.vehicles() == [1, 2]
    inside = _square(True) > 0
    one, two, both = combine(again, 1), combine(again, 2), combine(again)
    assert one is not None and two is not None and both is not None
    assert ((one.cov > 0) == ~inside).all() and ((two.cov > 0) == inside).all()
    assert (both.cov > 0).all()  # searched by one drone or the other: everywhere
    # the live gaps: where no drone searched (none here); drone 1 alone left the square
    gaps = json.loads(GapsCache(CombinedCache(again)).get())
    assert [f["properties"]["kind"] for f in gaps["features"]] == ["surveyed area"]
    alone = find_gaps(combined_layers(one))
    assert len(alone.gaps) == 1 and abs(alone.gaps[0].area - 1.44) < 0.15
    # the page: each drone's tiles and colour; its tile in its colour, the rest grey
    colours = {1: "#1565c0", 2: "#e65100"}
    doc = map_document(again, None, colours)
    layers: list[dict[str, Any]] = doc["vehicles"]  # type: ignore[assignment]
    assert [(v["sysid"], v["colour"]) for v in layers] == [(1, colours[1]), (2, colours[2])]
    assert layers[1]["tiles"][0]["href"].startswith("/map/v2/cov-0_0.png")
    for sysid, searched in ((1, ~inside), (2, inside)):
        code, body, ctype = map_route(again, f"/map/v{sysid}/cov-0_0.png")  # type: ignore[misc]
        assert code == 200 and ctype == "image/png"
        bgra = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_UNCHANGED)
        grey = (bgra[..., :3] == 97).all(axis=-1)
        assert (grey == ~searched).all()  # the default colour (no page) is not grey
    for bad in (
        *("/map/v3/cov-0_0.png", "/map/v1/cov-1_0.png", "/map/v0/cov-0_0.png"),
        *("/map/v9999/cov-0_0.png", "/map/v1/ortho-0_0.png", "/map/v1/../all/cov-0_0.png"),
    ):
        assert map_route(again, bad)[0] == 404, bad  # type: ignore[index]
    assert map_route(again, "/map/v2-m7-cov-0_0.png")[0] == 200  # type: ignore[index]


def test_a_drones_tile_takes_over_an_older_stations_file_of_its_place(tmp_path: Path) -> None:
    f = TileFacts(7, "cov", 0, 0, N, CELL, LAT0, LON0, 1)
    store = MapStore.open(tmp_path / "map")
    assert store.put(encode_coverage_tile(_square(True), f)) is not None  # vehicle unknown
    assert store.put(encode_coverage_tile(_square(False), f), 1) is None  # not newer
    newer = TileFacts(7, "cov", 0, 0, N, CELL, LAT0, LON0, 2)
    assert store.put(encode_coverage_tile(_square(False), newer), 1) is not None
    assert [(t.name, t.sysid) for t in store.tiles()] == [("v1-m7-cov-0_0.png", 1)]
    assert sorted(p.name for p in (tmp_path / "map").iterdir()) == ["v1-m7-cov-0_0.png"]
    assert store.inventory(1) is not None and store.inventory(2) is None


def test_page_switches_each_drones_coverage_in_its_colour(tmp_path: Path) -> None:
    """Headless Chromium: one check box per drone, off at first, its swatch in the colour
    the page gives the drone; switched on, the drone's own tiles are drawn over the
    combined coverage, which stays; switched off, they go."""
    import os

    from test_station import wait_for
    from test_station_flight import Chromium

    state = StationState.open(tmp_path / "station")
    for sysid in (1, 2):
        state.on_vehicle_packet(sysid, "udpin:127.0.0.1:14550", 1, 0, 0.0)
        for i in range(3):  # a few points of each over the tile
            lat, lon = LocalFrame(LAT0, LON0).to_geodetic(0.5 + i, sysid * 1.0)
            state.on_position(TrackPoint(i * 10**9, float(lat), float(lon), 3.0, 0.0, sysid), 0)
    store = two_drones(tmp_path / "station" / "map")
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    count = "document.querySelectorAll('g.maplayer[data-layer=\"%s\"] image').length"
    with StationWeb(state, port=0, map_store=store) as web:
        with urllib.request.urlopen(web.url + "state.json", timeout=10) as r:
            colours = {v["sysid"]: v["colour"] for v in json.loads(r.read())["vehicles"]}
        assert set(colours) == {1, 2} and colours[1] != colours[2]
        browser = Chromium(web.url, tmp_path / "profile")
        try:
            wait_for(lambda: browser.js(count % "cov") == 1, 20.0, "the combined coverage")
            wait_for(
                lambda: (
                    browser.js("document.querySelectorAll('#layer-vehicles input').length") == 2
                ),
                10.0,
                "a check box per drone",
            )
            assert browser.js("document.getElementById('layer-vehicles').hidden") is False
            assert browser.js(count % "cov-1") == 0 and browser.js(count % "cov-2") == 0
            swatch = "document.querySelector('#layer-cov-%d ~ .swatch rect').getAttribute('fill')"
            assert browser.js(swatch % 1) == colours[1] and browser.js(swatch % 2) == colours[2]
            browser.js(
                "document.getElementById('layer-vehicles').open = true;"
                "document.getElementById('layer-cov-2').click()"
            )
            wait_for(lambda: browser.js(count % "cov-2") == 1, 5.0, "drone 2's coverage")
            assert browser.js(count % "cov-1") == 0 and browser.js(count % "cov") == 1
            href = browser.js(
                "document.querySelector('g.maplayer[data-layer=\"cov-2\"] image').href.baseVal"
            )
            assert href.startswith("/map/v2/cov-0_0.png")
            # the tile the page draws: drone 2's colour where it searched
            with urllib.request.urlopen(web.url + href.lstrip("/"), timeout=10) as r:
                bgra = cv2.imdecode(np.frombuffer(r.read(), np.uint8), cv2.IMREAD_UNCHANGED)
            want = [int(colours[2][i : i + 2], 16) for i in (5, 3, 1)]
            assert bgra[16, 16, :3].tolist() == want and bgra[0, 0, :3].tolist() == [97] * 3
            browser.js("document.getElementById('layer-cov-1').click()")
            wait_for(lambda: browser.js(count % "cov-1") == 1, 5.0, "drone 1's coverage")
            browser.screenshot(art / "live-map-each-drone.png")
            browser.js("document.getElementById('layer-cov-2').click()")
            wait_for(lambda: browser.js(count % "cov-2") == 0, 5.0, "drone 2's hidden")
            assert browser.js(count % "cov-1") == 1 and browser.js(count % "cov") == 1
        finally:
            browser.close()
