"""Pan and zoom on the live page, with real input in headless Chromium (DevTools
``Input.dispatchMouseEvent`` / ``Input.dispatchTouchEvent``: the browser makes the wheel,
pointer and touch events a person's mouse or fingers would):

* the mouse wheel zooms about the pointer (the point under it stays put), a drag pans;
* two fingers pinch to zoom about their middle, one finger pans (phone width, touch);
* the buttons: + and - zoom about the middle, "fit" shows everything again;
* fitted, the view follows the flight (a new far hole is brought in); once moved, it stays
  where the operator put it;
* the buttons are 44 px touch targets clear of the layer box, the north arrow and the
  legend.

Screenshots go to ``HOLESCAN_ARTEFACTS`` (else the test's folder).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from test_station import wait_for
from test_station_layout import open_page, overlap, page_box, small_targets
from test_station_review import CHROMIUM, Browser, Page, review_station

from holescan.ground.station.web import StationWeb

pytestmark = [
    pytest.mark.timeout(180),
    pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)"),
]


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Browser]:
    b = Browser(tmp_path / "profile")
    try:
        yield b
    finally:
        b.close()


def _scale(page: Page) -> float:
    return float(page.js("MapView.state().last.s"))


def _holes(page: Page) -> dict[int, tuple[float, float]]:
    """Each hole's centre on the screen (client px)."""
    got = page.js(
        "[...document.querySelectorAll('g[data-hole]')].map(g => { const r = "
        "g.querySelectorAll('circle')[1].getBoundingClientRect();"
        " return [Number(g.dataset.hole), r.x + r.width / 2, r.y + r.height / 2]; })"
    )
    return {int(h): (float(x), float(y)) for h, x, y in got}


def _near(a: tuple[float, float], b: tuple[float, float], tol: float = 1.0) -> bool:
    return math.dist(a, b) <= tol


def _mouse(page: Page, kind: str, x: float, y: float, **more: Any) -> None:
    page.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, **more)


def _drag(page: Page, start: tuple[float, float], by: tuple[float, float]) -> None:
    x, y = start
    _mouse(page, "mousePressed", x, y, button="left", buttons=1, clickCount=1)
    for k in range(1, 6):
        _mouse(page, "mouseMoved", x + by[0] * k / 5, y + by[1] * k / 5, button="left", buttons=1)
    _mouse(page, "mouseReleased", x + by[0], y + by[1], button="left", buttons=0, clickCount=1)


def _click(page: Page, selector: str) -> None:
    b = page_box(page, selector)
    x, y = (b["left"] + b["right"]) / 2, (b["top"] + b["bottom"]) / 2
    _mouse(page, "mousePressed", x, y, button="left", buttons=1, clickCount=1)
    _mouse(page, "mouseReleased", x, y, button="left", buttons=0, clickCount=1)


def _touch(page: Page, kind: str, points: list[tuple[float, float]]) -> None:
    page.call(
        "Input.dispatchTouchEvent",
        type=kind,
        touchPoints=[{"x": x, "y": y, "id": i} for i, (x, y) in enumerate(points)],
    )


def test_wheel_drag_buttons_and_fit_on_a_laptop(tmp_path: Path, browser: Browser) -> None:
    state = review_station(tmp_path / "st")
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    with StationWeb(state, "127.0.0.1", 0) as web:
        page = open_page(browser, web.url, 1280, 800, False)
        wait_for(lambda: page.js("!!document.getElementById('zoom-fit')"), 10.0, "the buttons")
        assert page.js("MapView.state().view") is None  # fitted
        s0, at0 = _scale(page), _holes(page)
        # the wheel zooms about the pointer: hole 1 stays under it, the others move away
        x1, y1 = at0[1]
        _mouse(page, "mouseWheel", x1, y1, deltaX=0, deltaY=-250)
        wait_for(lambda: _scale(page) > s0 * 1.5, 5.0, "zoomed in")
        k = _scale(page) / s0
        assert k == pytest.approx(math.exp(0.5), rel=1e-3)
        at = _holes(page)
        assert _near(at[1], at0[1]), (at[1], at0[1])
        for h in (2, 3, 4):
            assert math.dist(at[h], at[1]) == pytest.approx(k * math.dist(at0[h], at0[1]), abs=1)
        page.screenshot(art / "station-zoomed-laptop.png")
        # a drag pans: everything moves with the pointer, the scale stays
        before = at
        _drag(page, (400, 300), (60, 40))
        wait_for(
            lambda: _near(_holes(page)[1], (before[1][0] + 60, before[1][1] + 40)), 5.0, "panned"
        )
        assert _scale(page) == pytest.approx(k * s0, rel=1e-9)
        assert all(_near(_holes(page)[h], (x + 60, y + 40)) for h, (x, y) in before.items())
        # moved: a hole far away does not move the view (the operator's place is kept)
        state.on_statustext("HOLE 9 p0.90 43.6536000 -79.3826000")  # ~40 m away
        wait_for(lambda: 9 in _holes(page), 10.0, "hole 9 drawn")
        assert _scale(page) == pytest.approx(k * s0, rel=1e-9)
        # +: zoom about the middle; fit: everything again, following the flight
        _click(page, "#zoom-in")
        wait_for(lambda: _scale(page) == pytest.approx(1.5 * k * s0, rel=1e-6), 5.0, "+")
        assert page.js("document.getElementById('map').classList.contains('moved')") is True
        _click(page, "#zoom-fit")
        wait_for(lambda: page.js("MapView.state().view") is None, 5.0, "fitted again")
        assert _scale(page) < s0  # hole 9 is in the picture: a larger area
        (w, h) = page.js("[innerWidth, innerHeight]")
        assert all(0 <= x <= w and 0 <= y <= h for x, y in _holes(page).values())
        s_fit = _scale(page)
        state.on_statustext("HOLE 10 p0.90 43.6540000 -79.3820000")  # farther still
        wait_for(lambda: _scale(page) < s_fit, 10.0, "the fitted view following the flight")
        s_follow = _scale(page)
        _click(page, "#zoom-out")
        wait_for(lambda: _scale(page) == pytest.approx(s_follow / 1.5, rel=1e-6), 5.0, "-")
        assert page.js("MapView.state().view") is not None
        # a click on a hole still selects it (a click is not a drag)
        x, y = _holes(page)[2]
        _mouse(page, "mousePressed", x, y, button="left", buttons=1, clickCount=1)
        _mouse(page, "mouseReleased", x, y, button="left", buttons=0, clickCount=1)
        wait_for(lambda: page.js("Review.current()") == 2, 5.0, "hole 2 selected")


def test_pinch_and_finger_drag_on_a_phone(tmp_path: Path, browser: Browser) -> None:
    state = review_station(tmp_path / "st")
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    with StationWeb(state, "127.0.0.1", 0) as web:
        page = open_page(browser, web.url, 412, 915, True)
        wait_for(lambda: page.js("!!document.getElementById('zoom-fit')"), 10.0, "the buttons")
        zoom, layers = page_box(page, "#zoom"), page_box(page, "#maplayers")
        north, legend = page_box(page, "#north"), page_box(page, "#legend")
        for other in (layers, north, legend):
            assert not overlap(zoom, other), (zoom, other)
        assert small_targets(page) == []
        s0, at0 = _scale(page), _holes(page)
        m = page_box(page, "#svg")
        cx, cy = (m["left"] + m["right"]) / 2, (m["top"] + m["bottom"]) / 2
        # two fingers 100 px apart spread to 200 px: twice the scale about their middle
        _touch(page, "touchStart", [(cx - 50, cy), (cx + 50, cy)])
        for k in range(1, 6):
            _touch(page, "touchMove", [(cx - 50 - 10 * k, cy), (cx + 50 + 10 * k, cy)])
        _touch(page, "touchEnd", [])
        wait_for(lambda: _scale(page) > 1.9 * s0, 5.0, "pinched")
        assert _scale(page) == pytest.approx(2 * s0, rel=1e-3)
        at = _holes(page)
        for h, (x, y) in at0.items():
            assert _near(at[h], (cx + 2 * (x - cx), cy + 2 * (y - cy)), 1.5), h
        page.screenshot(art / "station-pinched-phone.png")
        # one finger pans
        _touch(page, "touchStart", [(cx, cy)])
        for k in range(1, 6):
            _touch(page, "touchMove", [(cx - 8 * k, cy + 6 * k)])
        _touch(page, "touchEnd", [])
        wait_for(lambda: _near(_holes(page)[1], (at[1][0] - 40, at[1][1] + 30)), 5.0, "panned")
        assert _scale(page) == pytest.approx(2 * s0, rel=1e-3)
        _click(page, "#zoom-fit")
        wait_for(lambda: _scale(page) == pytest.approx(s0, rel=1e-9), 5.0, "fitted again")
