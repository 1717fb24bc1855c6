"""Two simulated drones, one station, one picture.

Two ``holescan fly --sensor sim --sysid N --gcs udpout:...`` processes (system ids 1 and
2, the same simulated world, each its own simulated autopilot; the hole server of each is
component 191 of its system id and relays its autopilot's position, attitude and
heartbeat on its own link) fly into one :class:`ground.GroundStation` listening on two
links (``--mavlink`` twice). Checked, on the station's state and on the page in headless
Chromium (1280 px):

* both vehicles are followed, each with its own track, drawn in two colours;
* the holes of both are on the page; every opening both reported is one hole whose
  ``vehicles`` name both, with each one's own id; the station's ids are those the
  class docstring of :class:`ground.StationState` gives (the first reporting vehicle's
  ids; the other's first-found holes ``sysid * 1000000 + its id``);
* no two station holes of different vehicles lie at one opening by the campaign's rule;
* the shared hole's KML description, GeoJSON properties and CoT remarks name both
  drones, the first and the last (GDAL reads the KML and GeoJSON);
* each drone's coverage tiles are kept as its own (``/map.json``'s ``vehicles``, in the
  drone's colour) and drawn when switched on.

The screenshot goes to ``HOLESCAN_ARTEFACTS`` (else the test's folder).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
import xml.etree.ElementTree as ET
from pathlib import Path

import pyogrio
import pytest
from test_station import wait_for
from test_station_review import CHROMIUM, Browser

from holescan.geotag import carry_ids
from holescan.ground import GroundOptions, GroundStation
from holescan.ground.station.cot import hole_cot
from tests._support import free_udp_port

ROOT = Path(__file__).resolve().parents[3]
SIM_TOML = """
sensor = "sim"
[capture]
startup_sync_s = 3.0
[sim]
size_m = [4.0, 4.0]
world_seed = 15
n_access_holes = 2
fps = 8.0
"""
FLY_S = 240
"""The flights' longest: they are ended (SIGINT) once the station holds a hole of both
(about 20 s of flight on an idle machine); reaching it means it never came."""


def _fly(cfg: Path, sysid: int, port: int, logs: Path, log: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [
            *(sys.executable, "-m", "holescan.cli", "fly", "--config", str(cfg)),
            *("--sysid", str(sysid), "--gcs", f"udpout:127.0.0.1:{port}"),
            *("--log-dir", str(logs), "--duration", str(FLY_S), "--bench"),
        ],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE,
        stderr=open(log, "w"),
        text=True,
    )


@pytest.mark.slow
@pytest.mark.timeout(480)
@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)")
def test_two_drones_one_station(tmp_path: Path) -> None:
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    ports = free_udp_port(), free_udp_port()
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{ports[0]}",
        more_mavlink=(f"udpin:127.0.0.1:{ports[1]}",),
        out=tmp_path / "station",
        http_port=0,
        cot_url=None,
    )
    cfg = tmp_path / "fly.toml"
    cfg.write_text(SIM_TOML)
    flies: list[subprocess.Popen[str]] = []
    with GroundStation(opts) as station:
        assert station.web is not None
        try:
            for sysid, port in zip((1, 2), ports, strict=True):
                log = tmp_path / f"fly{sysid}.log"
                flies.append(_fly(cfg, sysid, port, tmp_path / f"logs{sysid}", log))

            def flown() -> bool:
                """A hole both vehicles reported, and each one's map tiles, at the station
                (how many seconds of flight that takes depends on the machine: a loaded one
                renders and detects fewer frames a second)."""
                for sysid, f in enumerate(flies, 1):
                    assert f.poll() in (None, 0), (tmp_path / f"fly{sysid}.log").read_text()
                _, holes, _ = station.state.snapshot()
                shared = any({v.sysid for v in h.vehicles} == {1, 2} for h in holes)
                assert station.map_store is not None
                return shared and station.map_store.vehicles() == [1, 2]

            wait_for(flown, FLY_S, "a hole of both vehicles and both maps at the station")
            for f in flies:  # the crew ends the flights: SIGINT, a clean end (last tiles sent)
                f.send_signal(signal.SIGINT)
            for sysid, f in enumerate(flies, 1):
                f.communicate(timeout=120)
                assert f.returncode == 0, (tmp_path / f"fly{sysid}.log").read_text()[-3000:]
        finally:
            for f in flies:
                if f.poll() is None:
                    f.send_signal(signal.SIGINT)
                    f.wait(timeout=60)
        # the flights have ended; what they sent last may still be on its way in: the
        # station's holes are read once they stay the same for 3 s
        seen: list[list[tuple[int, list[tuple[int, int]]]]] = []
        since = [time.monotonic()]

        def settled() -> bool:
            _, hs, _ = station.state.snapshot()
            now = [(h.id, [(v.sysid, v.hole_id) for v in h.vehicles]) for h in hs]
            if not seen or now != seen[-1]:
                seen.append(now)
                since[0] = time.monotonic()
            return time.monotonic() - since[0] >= 3.0

        wait_for(settled, 60.0, "the station's holes to settle")
        _, holes, track = station.state.snapshot()
        # both vehicles followed, each on its own link, each with its own track
        assert {p.sysid for p in track} == {1, 2}
        vehicles = {v.sysid: v for v in station.state.vehicle_snapshot()}
        assert set(vehicles) == {1, 2}
        assert vehicles[1].links == [opts.mavlink] and vehicles[2].links == list(opts.more_mavlink)
        assert vehicles[1].mode and vehicles[1].armed is True
        # one id per opening: the campaign's rule finds no two station holes at one opening
        # (two holes of one vehicle are two: its own tracker told them apart)
        for h in holes:
            mine = {v.sysid for v in h.vehicles}
            others = [
                o.vehicles[0].as_hole(o.id)
                for o in holes
                if o.id != h.id and not mine & {v.sysid for v in o.vehicles}
            ]
            m = carry_ids(others, [h.vehicles[0].as_hole(h.id)])
            assert not m.from_reference, f"hole {h.id} is at hole {m.ids[h.id]}'s opening"
        shared = [h for h in holes if {v.sysid for v in h.vehicles} == {1, 2}]
        assert shared, [(h.id, [(v.sysid, v.hole_id) for v in h.vehicles]) for h in holes]
        primary = station.state.primary_sysid  # the first vehicle that reported a hole
        assert primary in (1, 2)
        for h in holes:
            first = h.vehicles[0]
            own = first.hole_id
            want = own if first.sysid == primary else first.sysid * 1_000_000 + own
            assert h.id == want, (h.id, h.vehicles)
        # the crew's other tools say which drones saw the shared hole, first and last
        sh = shared[0]
        first = min(sh.vehicles, key=lambda v: v.t_first_unix_ns).sysid
        last = max(sh.vehicles, key=lambda v: v.t_last_unix_ns).sysid
        info = pyogrio.read_info(f"/vsicurl/{station.web.url}holes.kml")
        _, _, _, kfields = pyogrio.raw.read(f"/vsicurl/{station.web.url}holes.kml")
        k = dict(zip(info["fields"], kfields, strict=True))
        (desc,) = [str(d) for n, d in zip(k["Name"], k["description"], strict=True)
                   if str(n).startswith(f"hole {sh.id} ")]  # fmt: skip
        assert f"seen by vehicles {first} + {3 - first} (first {first}, last {last})" in desc
        with urllib.request.urlopen(station.web.url + "holes.geojson", timeout=5) as r:
            feats = json.loads(r.read())["features"]
        (props,) = [f["properties"] for f in feats if f["properties"]["hole_id"] == sh.id]
        assert sorted(props["vehicles"]) == [1, 2]
        assert (props["first_vehicle"], props["last_vehicle"]) == (first, last)
        remarks = ET.fromstring(hole_cot(sh)).findtext("detail/remarks") or ""
        assert f"(first {first}, last {last})" in remarks
        # the page: holes of both, each vehicle's track in its own colour
        with urllib.request.urlopen(station.web.url + "state.json", timeout=5) as r:
            doc = json.loads(r.read())
        colours = {v["sysid"]: v["colour"] for v in doc["vehicles"]}
        assert set(colours) == {1, 2} and colours[1] != colours[2]
        browser = Browser(tmp_path / "profile")
        try:
            page = browser.page(station.web.url)
            wait_for(lambda: len(page.ids()) == len(holes), 60.0, "every hole on the page")
            drawn = page.js(
                "[...document.querySelectorAll('polyline.track')]"
                ".map(e => e.dataset.sysid + ' ' + e.getAttribute('stroke'))"
            )
            assert sorted(drawn) == [f"1 {colours[1]}", f"2 {colours[2]}"]
            listed = page.js(
                "[...document.querySelectorAll('#vehicles .vehicle')].map(e => e.dataset.sysid)"
            )
            assert listed == ["1", "2"]
            sid = shared[0].id
            page.js(f"Review.select({sid})")
            wait_for(
                lambda: "vehicle 1" in page.js("document.getElementById('locate').textContent"),
                30.0,
                "the shared hole's vehicles in its panel",
            )
            text = page.js("document.getElementById('locate').textContent")
            assert "vehicle 2" in text
            # each drone's own coverage: its tiles, in its colour, switched on the page
            with urllib.request.urlopen(station.web.url + "map.json", timeout=5) as r:
                mapdoc = json.loads(r.read())
            layers = {v["sysid"]: v for v in mapdoc["vehicles"]}
            assert set(layers) == {1, 2}
            assert all(layers[s]["colour"] == colours[s] and layers[s]["tiles"] for s in (1, 2))
            assert station.map_store is not None and station.map_store.vehicles() == [1, 2]
            count = "document.querySelectorAll('g.maplayer[data-layer=\"cov-%d\"] image').length"
            wait_for(
                lambda: page.js("document.querySelectorAll('#layer-vehicles input').length") == 2,
                30.0,
                "a coverage switch per drone",
            )
            page.js(
                "document.getElementById('layer-vehicles').open = true;"
                "document.getElementById('layer-cov-1').click();"
                "document.getElementById('layer-cov-2').click()"
            )
            for s in (1, 2):
                n = len(layers[s]["tiles"])
                wait_for(lambda s=s, n=n: page.js(count % s) == n, 30.0, f"drone {s}'s coverage")
            # each switch is one line: the swatch a 12 px square, not the map's full size
            sizes = page.js(
                "[...document.querySelectorAll('#layer-vehicles label')].map(l => {"
                " const s = l.querySelector('.swatch').getBoundingClientRect();"
                " return [Math.round(s.width), Math.round(s.height),"
                " Math.round(l.getBoundingClientRect().height)]; })"
            )
            assert len(sizes) == 2 and all(w == h == 12 and lh <= 48 for w, h, lh in sizes), sizes
            page.screenshot(art / "ground-station-two-drones.png")
        finally:
            browser.close()
    print(
        "two drones:",
        len(holes),
        "holes,",
        len(shared),
        "seen by both:",
        [(h.id, [(v.sysid, v.hole_id) for v in h.vehicles]) for h in holes],
    )
