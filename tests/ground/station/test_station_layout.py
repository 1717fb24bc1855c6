"""The live page on a phone (412 px wide) and on a laptop (1280 px), in headless Chromium.

At each width: map and queue side by side (laptop) or stacked (phone), nothing overlapping
(the layer box clear of the north arrow and the scale bar, the map clear of the queue),
touch targets of at least 44 px on the phone, the current hole's "why" shown once, and
the team's offline basemap (an MBTiles file) drawn under the drone's layers and switched
off from the layer box. Screenshots go to ``$HOLESCAN_ARTEFACTS`` (docs/station-phone.png
and docs/station-desktop.png are from here).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from test_basemap import make_mbtiles
from test_maplayers import tile_pair
from test_station import wait_for
from test_station_review import CHROMIUM, Browser, Page, review_station

from holescan.ground.station.basemap import open_basemap
from holescan.ground.station.mapstore import MapStore
from holescan.ground.station.web import StationWeb

pytestmark = [
    pytest.mark.timeout(180),
    pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)"),
]

Box = dict[str, float]


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Browser]:
    b = Browser(tmp_path / "profile")
    yield b
    b.close()


def page_box(page: Page, selector: str) -> Box:
    got = page.js(
        f"(() => {{ const r = document.querySelector('{selector}').getBoundingClientRect();"
        " return {left: r.left, top: r.top, right: r.right, bottom: r.bottom}; })()"
    )
    assert isinstance(got, dict), selector
    return {k: float(v) for k, v in got.items()}


def overlap(a: Box, b: Box) -> bool:
    return (
        a["left"] < b["right"]
        and b["left"] < a["right"]
        and a["top"] < b["bottom"]
        and (b["top"] < a["bottom"])
    )


def open_page(browser: Browser, url: str, width: int, height: int, mobile: bool) -> Page:
    page = browser.page("about:blank")
    page.call(
        "Emulation.setDeviceMetricsOverride",
        width=width,
        height=height,
        deviceScaleFactor=1,
        mobile=mobile,
    )
    if mobile:
        page.call("Emulation.setTouchEmulationEnabled", enabled=True, maxTouchPoints=5)
    page.call("Page.navigate", url=url)
    wait_for(lambda: len(page.ids()) == 4, 20.0, "the queue")
    return page


def small_targets(page: Page) -> list[Any]:
    """Visible buttons, selects and layer-box labels smaller than 44 px either way."""
    return list(
        page.js(
            "[...document.querySelectorAll('button, select, #maplayers label')]"
            ".map(e => [e.id || e.textContent.trim().slice(0, 20), e.getBoundingClientRect()])"
            ".filter(([, r]) => r.width > 0 && (r.height < 44 || r.width < 44))"
            ".map(([n, r]) => [n, Math.round(r.width), Math.round(r.height)])"
        )
    )


@pytest.mark.parametrize(
    ("name", "width", "height", "mobile"),
    [("phone", 412, 915, True), ("desktop", 1280, 800, False)],
)
def test_page_fits_phone_and_laptop(
    tmp_path: Path, browser: Browser, name: str, width: int, height: int, mobile: bool
) -> None:
    state = review_station(tmp_path / "st")
    store = MapStore.open(tmp_path / "st" / "map")
    for data in tile_pair(0, 0):
        store.put(data)
    make_mbtiles(tmp_path / "plan.mbtiles", range(16, 20))
    basemap = open_basemap(tmp_path / "plan.mbtiles")
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    with StationWeb(state, "127.0.0.1", 0, map_store=store, basemaps=[basemap]) as web:
        page = open_page(browser, web.url, width, height, mobile)
        images = "document.querySelectorAll('g.maplayer[data-layer=\"basemap\"] image').length"
        wait_for(lambda: page.js(images) >= 1, 20.0, "the basemap drawn")
        served = (
            "Promise.all([...document.querySelectorAll('g.maplayer[data-layer=\"%s\"] image')]"
            ".map(i => fetch(i.href.baseVal).then(r => r.ok)))"
        )
        wait_for(lambda: all(page.js(served % "cov")), 10.0, "the coverage tiles served")
        # the file holds two tiles a zoom: the others of the view are 404s, drawn as nothing
        wait_for(lambda: any(page.js(served % "basemap")), 10.0, "the basemap's tiles served")
        assert page.js("document.querySelector('#svg').firstElementChild.dataset.layer") == (
            "basemap"  # under the drone's orthophoto and coverage
        )
        page_map, side = page_box(page, "#map"), page_box(page, "#side")
        layers, north = page_box(page, "#maplayers"), page_box(page, "#north")
        scale = page_box(page, "#scalebar")
        assert not overlap(page_map, side)
        assert not overlap(layers, north), (layers, north)
        assert not overlap(layers, scale), (layers, scale)
        assert north["right"] <= page_map["right"] and north["top"] >= page_map["top"]
        if mobile:
            assert side["top"] >= page_map["bottom"] - 0.5  # stacked: map above the queue
            assert page_map["right"] - page_map["left"] >= width - 1
            assert page_map["bottom"] - page_map["top"] >= 0.5 * height
            assert small_targets(page) == []
            assert page.js("document.documentElement.scrollWidth") <= width  # no sideways
        else:
            assert side["left"] >= page_map["right"] - 0.5  # side by side
            assert page_map["right"] - page_map["left"] >= 800
        # the current hole's "why" appears once on the page
        current = page.js("document.getElementById('current').dataset.id")
        why = f"why-{current}:"
        assert page.js(f"document.body.innerText.split({why!r}).length - 1") == 1
        page.screenshot(art / f"station-{name}.png")
        # the basemap switched off from the layer box; the drone's layers stay
        page.js(
            "(() => { const s = document.getElementById('layer-basemap'); s.value = '-1';"
            " s.dispatchEvent(new Event('change')); })()"
        )
        wait_for(lambda: page.js(images) == 0, 5.0, "the basemap hidden")
        assert page.js("document.querySelectorAll('g.maplayer[data-layer=\"cov\"] image').length")
    basemap.close()
