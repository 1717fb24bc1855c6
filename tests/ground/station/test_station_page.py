"""The live page cannot be poisoned or starved, in headless Chromium.

* a pairing link whose token is not valid (``/?token=%E2%82%AC``, a plausible wrong one)
  says so on the page, which still shows the holes read-only (never a stuck "waiting for
  the vehicle", never read-only in silence);
* a good link pairs the browser: the token leaves the address bar and the tab's history at
  once, the page's script never holds it (an HttpOnly cookie), a reload stays paired;
* the page runs under its CSP without one violation (no inline script or style);
* event streams refused (all of its address's slots held by another client) or ended by
  the station: the page reconnects on its own and shows changes without a reload.
"""

from __future__ import annotations

import re
import socket
from collections.abc import Iterator
from html.parser import HTMLParser
from importlib import resources
from pathlib import Path

import pytest
from test_station import wait_for
from test_station_review import CHROMIUM, Browser, Page, review_station

from holescan.ground.station.guard import Limits
from holescan.ground.station.web import StationWeb

pytestmark = [
    pytest.mark.timeout(180),
    pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)"),
]

_CSP_WATCH = """
window.__csp = [];
document.addEventListener("securitypolicyviolation",
  e => window.__csp.push(e.violatedDirective + " " + e.blockedURI));
"""


@pytest.fixture(scope="module")
def chromium(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Browser]:
    """One Chromium for the module: one start, not one per test (each start takes tens of
    seconds on a loaded machine)."""
    b = Browser(tmp_path_factory.mktemp("chromium") / "profile")
    yield b
    b.close()


@pytest.fixture
def browser(chromium: Browser) -> Iterator[Browser]:
    """The module's Chromium; the test's tabs (each in a browser context of its own: own
    cookies and storage, as a separate browser) are closed after it, so no page of one test
    reconnects to the next one's station."""
    yield chromium
    for p in list(chromium.pages):
        chromium.close_page(p)


def _open(browser: Browser, url: str) -> Page:
    """A new tab (own storage) that records CSP violations from its first script on."""
    page = browser.page("about:blank")
    page.call("Page.enable")
    page.call("Page.addScriptToEvaluateOnNewDocument", source=_CSP_WATCH)
    page.call("Page.navigate", url=url)
    wait_for(
        lambda: (
            page.js("location.protocol") == "http:" and page.js("document.readyState") == "complete"
        ),
        20.0,
        "page load",
    )
    return page


def _text(page: Page, el: str) -> str:
    return str(page.js(f"document.getElementById('{el}').textContent"))


def test_bad_pairing_links_say_so_and_the_page_still_works(
    tmp_path: Path, browser: Browser
) -> None:
    state = review_station(tmp_path / "st")
    with StationWeb(state, "127.0.0.1", 0) as web:
        for query in ("?token=%E2%82%AC", "?token=" + "Q" * 43, "?token="):
            page = _open(browser, web.url + query)
            wait_for(lambda p=page: len(p.ids()) == 4, 60.0, "the queue")
            wait_for(lambda p=page: "not valid" in _text(p, "notice"), 30.0, "the notice")
            assert page.js("document.getElementById('notice').className") == "error"
            assert page.js("document.body.dataset.canMark") == "no"
            assert "read-only" in _text(page, "pairing")
            assert "waiting" not in _text(page, "status")  # the holes are there
            assert "token" not in page.js("location.href")
            assert page.js("window.__csp") == []
            browser.close_page(page)  # as a person closes the tab


def test_a_good_link_pairs_without_leaving_the_token_behind(
    tmp_path: Path, browser: Browser
) -> None:
    state = review_station(tmp_path / "st")
    with StationWeb(state, "127.0.0.1", 0) as web:
        _, token = web.pairings.issue("Ana")
        page = _open(browser, web.pair_url(token))
        wait_for(lambda: page.js("document.body.dataset.canMark") == "yes", 60.0, "pairing")
        assert "as Ana (p1)" in _text(page, "notice")
        assert _text(page, "pairing") == "paired as Ana (p1)"
        # not in the address bar, nor in the tab's history, nor anywhere the script reads
        assert token not in page.js("location.href")
        entries = page.call("Page.getNavigationHistory")["entries"]
        assert entries and not any(token in e["url"] for e in entries)
        assert page.js("document.cookie") == ""  # HttpOnly: not the script's to read
        assert page.js("JSON.stringify(localStorage) + JSON.stringify(sessionStorage)") == "{}{}"
        cookies = page.call("Network.getCookies", urls=[web.url])["cookies"]
        (c,) = cookies
        assert c["httpOnly"] and c["sameSite"] == "Strict" and c["session"]
        # a reload stays paired (the cookie), with no link in sight
        page.call("Page.reload")
        wait_for(lambda: page.js("document.body.dataset.canMark") == "yes", 60.0, "reload")
        assert page.js("document.getElementById('notice').hidden") is True
        # a mark from the page is audited under the pairing
        page.js("Review.select(1)")
        page.key("c")
        wait_for(lambda: state.holes[1].mark == "confirmed", 30.0, "the mark")
        assert page.js("window.__csp") == []
        # the watch is real: an inline style is refused and reported
        page.js("document.body.insertAdjacentHTML('beforeend', '<b style=\"color:red\">x</b>')")
        wait_for(lambda: page.js("window.__csp.length") == 1, 15.0, "the violation seen")


def test_the_page_reconnects_its_event_stream_on_its_own(tmp_path: Path, browser: Browser) -> None:
    state = review_station(tmp_path / "st")
    limits = Limits(max_events_per_client=2, events_s=3.0)
    with StationWeb(state, "127.0.0.1", 0, limits=limits) as web:
        # another client on the same address holds both of its event slots
        held = []
        for _ in range(2):
            s = socket.create_connection(("127.0.0.1", web.port), timeout=10)
            s.sendall(f"GET /events HTTP/1.1\r\nHost: 127.0.0.1:{web.port}\r\n\r\n".encode())
            assert s.recv(4096).startswith(b"HTTP/1.1 200")
            held.append(s)
        page = _open(browser, web.url)
        wait_for(lambda: len(page.ids()) == 4, 60.0, "the queue (read once)")
        wait_for(lambda: web.events.refused >= 1, 30.0, "the page's stream refused")
        assert page.js("document.body.dataset.live") == "no"
        for s in held:
            s.close()
        wait_for(lambda: page.js("document.body.dataset.live") == "yes", 60.0, "reconnected")
        # the station ends each stream after 3 s; the page keeps up across them
        served = web.events.served
        wait_for(lambda: web.events.served >= served + 2, 60.0, "streams renewed")
        state.on_statustext("HOLE 5 0.93 43.6534100 -79.3830500")
        wait_for(lambda: 5 in page.ids(), 45.0, "the new hole without a reload")
        assert page.js("window.__csp") == []


def test_the_page_has_no_inline_script_or_style() -> None:
    static = resources.files("holescan.ground.station").joinpath("static")
    found: list[str] = []

    class Inline(HTMLParser):
        def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
            names = {k for k, _ in attrs}
            if tag == "style" or (tag == "script" and "src" not in names):
                found.append(tag)
            found.extend(k for k in names if k == "style" or k.startswith("on"))

    Inline().feed(static.joinpath("station.html").read_text())
    assert found == []
    for name in ("station.js", "review.js", "maplayers.js", "locate.js", "mapview.js"):
        js = static.joinpath(name).read_text()
        assert not re.search(r"style=|\.style\b|\bon[a-z]+=\"", js), name  # no inline style
        assert "eval(" not in js and "new Function" not in js, name
