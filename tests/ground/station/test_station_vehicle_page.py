"""The vehicle and a hole's location on the live page, from the station's own link.

A pymavlink autopilot (system 1, component 1) on loopback sends what ArduPilot sends a
ground station (HEARTBEAT GUIDED armed, GLOBAL_POSITION_INT, ATTITUDE, HOME_POSITION,
RADIO_STATUS), with a gap in its sequence numbers, and no SYS_STATUS until asked for it:
the station (:class:`ground.station.link.VehicleLink`, no MAVProxy) must ask for that
message only, and then show the battery. A bad value (an ATTITUDE with roll NaN) is
refused and counted. In headless Chromium at 1280 px and at 412 px (a phone): the vehicle
drawn with its heading and the camera's footprint now, its panel (mode, armed, battery,
link loss); a hole's lat/lon and MGRS (as :func:`mgrs_text` gives it) with a working copy
button, its distance and bearing from home and from the vehicle (as
:func:`range_bearing`), from this device after a click on "from me" (a geolocation the
browser is given), the 95 % circle explained, its age. Screenshots go to
``$HOLESCAN_ARTEFACTS`` (the docs' PNGs are from there), else the test's folder.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from test_station import picture, wait_for
from test_station_review import CHROMIUM, Browser, Page

from holescan.ground import StationState
from holescan.ground.station.link import VehicleLink
from holescan.ground.station.locate import mgrs_text, range_bearing
from holescan.ground.station.web import StationWeb
from holescan.link import mavlink, open_link
from tests._support import free_udp_port

pytestmark = [
    pytest.mark.timeout(180),
    pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)"),
]
HOME = (43.6532, -79.3832, 120.0)
OPERATOR = (43.6530, -79.3834)


class Autopilot:
    """An ArduCopter-like peer: telemetry at 4 Hz, SYS_STATUS only once asked for."""

    def __init__(self, port: int) -> None:
        self.conn = open_link(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
        self.asked: list[int] = []
        self.bad_roll = False
        self.skip = 0  # sequence numbers to skip once (packets "lost on the way")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        mav = self.conn.mav
        t0 = time.monotonic()
        k = 0
        while not self._stop.wait(0.25):
            t = time.monotonic() - t0
            ms = int(t * 1000)
            lat = HOME[0] + 2e-5 + 0.3e-5 * math.sin(t / 5)
            lon = HOME[1] + 3e-5
            if k % 4 == 0:
                base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
                mav.heartbeat_send(
                    mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, 4, 4
                )
                mav.home_position_send(
                    int(HOME[0] * 1e7), int(HOME[1] * 1e7), int(HOME[2] * 1000), 0, 0, 0,
                    [1, 0, 0, 0], 0, 0, 0,
                )  # fmt: skip
                mav.radio_status_send(180, 170, 80, 40, 38, 0, 0)
            if self.skip:  # set by the test once the station hears the vehicle
                mav.seq = (mav.seq + self.skip) % 256
                self.skip = 0
            roll = math.nan if self.bad_roll else 0.05
            mav.attitude_send(ms, roll, 0.0, math.radians(60), 0.0, 0.0, 0.0)
            mav.global_position_int_send(
                ms, int(lat * 1e7), int(lon * 1e7), int((HOME[2] + 3) * 1000), 3000, 50, 20, 0,
                6000,
            )  # fmt: skip
            if mavlink.MAVLINK_MSG_ID_SYS_STATUS in self.asked:
                mav.sys_status_send(0, 0, 0, 500, 15800, 1230, 76, 0, 0, 0, 0, 0, 0)
            while (msg := self.conn.recv_match(blocking=False)) is not None:
                if msg.get_type() == "COMMAND_LONG" and msg.target_system == 1:
                    self.asked.append(int(msg.param1))
            k += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.conn.close()


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Browser]:
    b = Browser(tmp_path / "profile")
    yield b
    b.close()


def _page(browser: Browser, url: str, width: int) -> Page:
    """A tab ``width`` CSS px wide (a phone at 412: touch, 2x pixels) allowed the clipboard
    and a position."""
    ctx = browser._call("Target.createBrowserContext")["browserContextId"]
    origin = url.rstrip("/")
    browser._call(
        "Browser.grantPermissions",
        origin=origin,
        browserContextId=ctx,
        permissions=["geolocation", "clipboardReadWrite", "clipboardSanitizedWrite"],
    )
    target = browser._call("Target.createTarget", url="about:blank", browserContextId=ctx)
    p = Page(f"ws://127.0.0.1:{browser.port}/devtools/page/{target['targetId']}")
    browser.pages.append(p)
    phone = width < 600
    p.call(
        "Emulation.setDeviceMetricsOverride",
        width=width,
        height=915 if phone else 800,
        deviceScaleFactor=1,
        mobile=phone,
    )
    p.call("Emulation.setGeolocationOverride", latitude=OPERATOR[0], longitude=OPERATOR[1],
           accuracy=5)  # fmt: skip
    p.call("Page.navigate", url=url)
    wait_for(lambda: p.js("document.readyState") == "complete", 20.0, "page load")
    return p


def _text(page: Page, el: str) -> str:
    return str(page.js(f"(document.getElementById('{el}') || {{}}).textContent || ''"))


def _distance(text: str) -> float:
    return float(text.split(" m ", 1)[0].split()[-1])


@pytest.mark.parametrize("width", [1280, 412])
def test_vehicle_and_hole_location_on_the_page(
    tmp_path: Path, browser: Browser, width: int
) -> None:
    state = StationState.open(tmp_path / "st")
    facts: dict[str, Any] = {
        "id": 4, "rev": 1, "lat": HOME[0] + 5e-5, "lon": HOME[1] + 6e-5, "score": 0.8,
        "sigma": 0.4, "n": 9, "major": 1.1, "minor": 0.7, "why": "dark opening, rim on 3 sides",
    }  # fmt: skip
    port = free_udp_port()
    ap: Autopilot | None = None
    with (
        StationWeb(state, "127.0.0.1", 0) as web,
        VehicleLink(f"udpin:127.0.0.1:{port}", state, streams_after_s=1.0) as link,
    ):
        try:
            ap = Autopilot(port)
            wait_for(lambda: 1 in state.vehicles, 20.0, "the vehicle heard")
            ap.skip = 5  # five packets lost on the way
            state.on_card(facts, picture(4), sysid=1)
            # politely: only what does not come is asked for, and then it comes
            wait_for(lambda: state.vehicles[1].battery_pct == 76, 30.0, "the battery")
            assert set(ap.asked) == {mavlink.MAVLINK_MSG_ID_SYS_STATUS}
            assert link.streams_requested == [(1, "SYS_STATUS")]
            v = state.vehicles[1]
            wait_for(lambda: v.quality.lost > 0, 10.0, "the gap seen")
            assert v.quality.lost == 5 and v.mode == "GUIDED" and v.armed is True
            assert v.home == pytest.approx(HOME)
            # a NaN roll is refused and counted; nothing of its ATTITUDE kept
            before = state.rejected
            ap.bad_roll = True
            wait_for(lambda: state.rejected > before, 10.0, "the NaN refused")
            assert state.vehicles[1].roll == pytest.approx(0.05)
            ap.bad_roll = False
            page = _page(browser, web.url, width)
            wait_for(lambda: page.ids() == [4], 20.0, "the hole")
            wait_for(lambda: "GUIDED" in _text(page, "vehicles"), 10.0, "the vehicle panel")
            panel = _text(page, "vehicles")
            assert "ARMED" in panel and "15.8 V 76 %" in panel and "rssi 180/170" in panel
            assert "loss" in panel
            assert page.js("document.querySelectorAll('g.vehicle[data-sysid=\"1\"]').length") == 1
            assert page.js("document.querySelectorAll('polygon.footprint-now').length") == 1
            assert page.js("document.querySelectorAll('g.home').length") == 1
            # the hole's location panel
            page.js("Review.select(4)")
            h = state.holes[4]
            want = mgrs_text(h.lat_deg, h.lon_deg)
            assert want is not None
            wait_for(lambda: _text(page, "loc-mgrs") == want, 10.0, "the grid reference")
            assert _text(page, "loc-latlon") == f"{h.lat_deg:.7f}, {h.lon_deg:.7f}"
            d_home, b_home = range_bearing(HOME[0], HOME[1], h.lat_deg, h.lon_deg)
            home_text = _text(page, "loc-home")
            assert _distance(home_text) == pytest.approx(d_home, abs=0.06)
            assert f"bearing {round(b_home):03d}" in home_text and "home position" in home_text
            assert "from vehicle 1" in _text(page, "locate")
            assert "95 % probability" in _text(page, "locate")
            assert "first seen" in _text(page, "loc-age") and "ago" in _text(page, "loc-age")
            assert "vehicle 1 (its hole 4)" in _text(page, "loc-vehicles")
            # copy: the grid reference reaches the clipboard
            page.js("document.querySelector('#locate tr:nth-child(2) button.copy').click()")
            wait_for(lambda: page.js("navigator.clipboard.readText()") == want, 10.0, "copied")
            # from me: the browser's position, asked on the click only
            assert "from me" in _text(page, "loc-me")
            page.js("document.getElementById('from-me').click()")
            wait_for(lambda: "this device" in _text(page, "loc-me"), 10.0, "the operator")
            d_me, _ = range_bearing(OPERATOR[0], OPERATOR[1], h.lat_deg, h.lon_deg)
            assert _distance(_text(page, "loc-me")) == pytest.approx(d_me, abs=0.06)
            # the legend explains the circle (the phone's stacked layout is the page's
            # layout's: docs/ground-station.md; here the panel's content at both widths)
            assert "95 %" in _text(page, "legend")
            assert page.js("document.getElementById('locate').getBoundingClientRect().height") > 50
            art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))  # docs/ PNGs from here
            art.mkdir(parents=True, exist_ok=True)
            page.screenshot(art / f"ground-station-vehicle-{width}.png")
        finally:
            if ap is not None:
                ap.close()
