"""The review flow on the live page, in headless Chromium (issue 21, item 5).

One Chromium, three separate browser contexts (their own storage, as three browsers):
operators Ana and Bea, each paired by a pairing link of their own (the station names
them), and a viewer without one. Holes 2 and 3 are "for review" (the vehicle's tier), 1 and 4
announced. Checked: the queue order (review first by confidence), the large picture and
the "why" line of the current hole, keyboard shortcuts (c, x, j) sent as real key events,
each operator seeing the other's mark without a reload, a rejected hole kept and shown as
rejected, the audit trail with both names, and the viewer unable to mark.
"""

from __future__ import annotations

import base64
import json
import os
import subprocess
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from devtools import CHROMIUM, Tab, start_chromium
from test_station import picture, wait_for

from holescan.ground import StationState
from holescan.ground.station.audit import AuditTrail
from holescan.ground.station.web import StationWeb


class Page(Tab):
    context: str = ""  # the DevTools browser context it was opened in
    """One tab of the review page."""

    def ids(self) -> list[int]:
        return [
            int(x)
            for x in self.js("[...document.querySelectorAll('.hole')].map(e => e.dataset.id)")
        ]


class Browser:
    """Headless Chromium; :meth:`page` opens a tab in a new browser context (own storage)."""

    def __init__(self, profile: Path) -> None:
        import websocket

        self.proc, self.port = start_chromium(profile)
        with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/json/version", timeout=20) as r:
            version: dict[str, Any] = json.loads(r.read())
        self.browser = websocket.create_connection(version["webSocketDebuggerUrl"], timeout=20)
        self._id = 0
        self.pages: list[Page] = []

    def _call(self, method: str, **params: Any) -> dict[str, Any]:
        self._id += 1
        self.browser.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.browser.recv())
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise AssertionError(msg["error"])
                return dict(msg["result"])

    def page(self, url: str) -> Page:
        ctx = self._call("Target.createBrowserContext")["browserContextId"]
        target = self._call("Target.createTarget", url=url, browserContextId=ctx)["targetId"]
        p = Page(f"ws://127.0.0.1:{self.port}/devtools/page/{target}")
        p.context = ctx
        self.pages.append(p)
        wait_for(lambda: p.js("document.readyState") == "complete", 20.0, "page load")
        return p

    def close_page(self, p: Page) -> None:
        """Close a page and its browser context (its connections with it), as a person
        closing the tab does."""
        p.close()
        self.pages.remove(p)
        self._call("Target.disposeBrowserContext", browserContextId=p.context)

    def close(self) -> None:
        for p in self.pages:
            p.close()
        self.browser.close()
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def review_station(folder: Path) -> StationState:
    state = StationState.open(folder)
    holes = {1: 0.91, 2: 0.52, 3: 0.74, 4: 0.63}  # id -> score
    for hid, score in holes.items():
        facts = {
            "id": hid,
            "rev": 1,
            "lat": 43.65331 + hid * 2e-5,
            "lon": -79.38312 + hid * 1e-5,
            "score": score,
            "sigma": 0.3,
            "n": 5 + hid,
            "major": 1.1,
            "minor": 0.7,
            "why": f"why-{hid}: dark opening, rim seen on 3 sides",
        }
        state.on_card(facts, picture(hid))
    # what the vehicle's tier will set (from its wire format; nothing is serving yet)
    state.holes[2].vehicle_tier = "review"
    state.holes[3].vehicle_tier = "review"
    state.on_statustext("HOLE 4 0.63 43.6533900 -79.3830800")  # a change: saved, told
    return state


@pytest.fixture
def site(tmp_path: Path) -> Iterator[tuple[StationState, StationWeb]]:
    state = review_station(tmp_path / "st")
    with StationWeb(state, "127.0.0.1", 0) as web:
        yield state, web


@pytest.mark.timeout(180)
@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)")
def test_two_operators_review_the_queue_live(
    site: tuple[StationState, StationWeb], tmp_path: Path
) -> None:
    state, web = site
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    browser = Browser(tmp_path / "profile")
    try:
        _, ana_token = web.pairings.issue("Ana")
        _, bea_token = web.pairings.issue("Bea")
        ana = browser.page(web.pair_url(ana_token))
        bea = browser.page(web.pair_url(bea_token))
        viewer = browser.page(web.url)
        for p in (ana, bea, viewer):
            wait_for(lambda p=p: len(p.ids()) == 4, 20.0, "the queue")
        assert "token" not in ana.js("location.href")  # taken out of the address bar
        # each page says who it marks as: the pairing, named by the station
        for p, who in ((ana, "Ana (p1)"), (bea, "Bea (p2)")):
            wait_for(lambda p=p: p.js("document.body.dataset.canMark") == "yes", 10.0, "pairing")
            assert p.js("document.getElementById('pairing').textContent") == f"paired as {who}"
            p.js("window.__same_page = true")  # gone if the page were reloaded
        assert "read-only" in viewer.js("document.getElementById('pairing').textContent")
        # the queue: for review first by confidence (3: 0.74, 2: 0.52), then the rest
        assert ana.ids() == [3, 2, 1, 4]
        assert ana.js("document.getElementById('current').dataset.id") == "3"
        assert ana.js("document.querySelector('#current img.big').naturalWidth") > 0
        assert "why-3: dark opening" in ana.js(
            "document.querySelector('#current .why').textContent"
        )
        assert ana.js("document.querySelector('#current .badge').textContent") == "for review"
        # Ana confirms the current hole with the keyboard: c
        ana.key("c")
        wait_for(lambda: state.holes[3].mark == "confirmed", 10.0, "Ana's mark in the state")
        # she is moved on to the next hole for review
        wait_for(lambda: ana.js("document.body.dataset.current") == "2", 10.0, "the next hole")
        # Bea's page shows it without a reload, with Ana's name
        wait_for(
            lambda: bea.js("document.getElementById('hole-3').dataset.tier") == "confirmed",
            10.0,
            "Ana's mark on Bea's page",
        )
        assert "by Ana (p1)" in bea.js("document.getElementById('hole-3').textContent")
        assert bea.js("window.__same_page") is True
        # Bea picks hole 2 on the list and rejects it: x
        bea.js("document.getElementById('hole-2').click()")
        wait_for(lambda: bea.js("document.body.dataset.current") == "2", 5.0, "Bea's pick")
        bea.key("x")
        wait_for(lambda: state.holes[2].mark == "rejected", 10.0, "Bea's mark in the state")
        wait_for(
            lambda: ana.js("document.getElementById('hole-2').dataset.tier") == "rejected",
            10.0,
            "Bea's mark on Ana's page",
        )
        # the rejected hole is kept, shown as rejected, at the end of the queue
        assert ana.ids() == [1, 4, 3, 2]
        assert "rejected" in ana.js("document.querySelector('#hole-2 .badge').textContent")
        assert ana.js("window.__same_page") is True
        # next / previous keys move the current hole along the queue
        ana.js("Review.select(1)")
        ana.key("j")
        assert ana.js("document.body.dataset.current") == "4"
        ana.key("ArrowDown")
        assert ana.js("document.body.dataset.current") == "3"
        ana.key("k")
        assert ana.js("document.body.dataset.current") == "4"
        # the viewer sees everything and can change nothing
        wait_for(lambda: viewer.ids() == [1, 4, 3, 2], 10.0, "the viewer's queue")
        assert viewer.js("document.body.dataset.canMark") == "no"
        assert viewer.js("document.querySelector('#current button[data-mark]').disabled")
        version = state.version
        viewer.key("c")
        wait_for(
            lambda: (
                "refused (401)" in viewer.js("document.getElementById('queue-head').textContent")
            ),
            10.0,
            "the refusal",
        )
        assert state.version == version and state.holes[1].mark == "new"
        # the audit trail: who, what, from which tier to which
        trail = AuditTrail(state.folder).read()
        got = [
            (e["pairing"], e["operator"], e["hole"], e["tier_from"], e["tier_to"]) for e in trail
        ]
        assert got == [
            ("p1", "Ana", 3, "review", "confirmed"),
            ("p2", "Bea", 2, "review", "rejected"),
        ]
        shot = ana.call("Page.captureScreenshot", format="png")["data"]
        (art / "ground-station-review.png").write_bytes(base64.b64decode(shot))
    finally:
        browser.close()


def test_state_json_and_file_carry_the_tiers(site: tuple[StationState, StationWeb]) -> None:
    state, _ = site
    doc = json.loads(state.path.read_text())
    tiers = {h["id"]: (h["vehicle_tier"], h["tier"]) for h in doc["holes"]}
    assert tiers == {
        1: ("announced", "announced"),
        2: ("review", "review"),
        3: ("review", "review"),
        4: ("announced", "announced"),
    }
    state.mark(2, "visited")
    state.mark(3, "rejected")
    again = StationState.open(state.folder)
    assert [(h.id, h.tier) for h in again.snapshot()[1]] == [
        (1, "announced"),
        (2, "confirmed"),  # visited: a crew stood at it
        (3, "rejected"),
        (4, "announced"),
    ]
    # a file without tiers (older stations) reads as announced
    old = json.loads(state.path.read_text())
    for h in old["holes"]:
        h.pop("vehicle_tier"), h.pop("tier")
    state.path.write_text(json.dumps(old))
    assert {h.vehicle_tier for h in StationState.open(state.folder).holes.values()} == {"announced"}
