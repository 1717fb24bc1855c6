"""The station's live layers for the crew's other tools, read by real clients.

* GDAL (OGR's GeoJSON driver in pyogrio's wheel, over HTTP as QGIS polls it) reads
  ``/holes.geojson`` (``hole_id``, ``tier``, ``p_hole``, ``vehicles``, the picture at the
  public URL; rejected holes left out) and ``/gaps.geojson`` (gap polygons of the live map);
* ``/holes_live.kml`` is a KML 2.2 NetworkLink (``Link`` with ``href`` at the public URL,
  ``refreshMode onInterval``), ``/holes.kml`` KML 2.2 placemarks with their pictures;
* the feeds pass the station's guard (Host, cross-site, rate) like the page;
* CoT picture links carry the station's LAN address (``--public-url``, or the address the
  page is bound to), never the loopback.
"""

from __future__ import annotations

import json
import socket
import subprocess
import urllib.request
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pyogrio
import pytest
from test_maplayers import CELL, LAT0, LON0, N
from test_station import NODE_COT, PytakReceiver, picture, wait_for
from test_station_review import review_station

from holescan import cli
from holescan.ground import GroundOptions, GroundStation
from holescan.ground.station.cot import hole_cot
from holescan.ground.station.guard import Limits
from holescan.ground.station.mapstore import MapStore
from holescan.ground.station.state import StationState
from holescan.ground.station.tak import CotPublisher
from holescan.ground.station.web import StationWeb
from holescan.missions import TileFacts, encode_coverage_tile
from tests._support import free_udp_port

pytestmark = pytest.mark.timeout(120)

KML = "{http://www.opengis.net/kml/2.2}"
PUBLIC = "http://192.168.1.10:8080/"


def _get(url: str, headers: dict[str, str] | None = None) -> tuple[int, bytes, str]:
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read(), r.headers.get("Content-Type", "")
    except urllib.error.HTTPError as err:
        return err.code, err.read(), ""


def _raw(port: int, path: str, host: str) -> int:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(f"GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
        return int(s.recv(200).split()[1])


def _seen_but_a_square(tx: int) -> bytes:
    """A coverage tile seen everywhere (0.9) but, on tile 0, a 1.2 m square in its middle."""
    cov = np.full((N, N), 0.9)
    if tx == 0:
        cov[10:22, 10:22] = 0.0
    return encode_coverage_tile(cov, TileFacts(9, "cov", tx, 0, N, CELL, LAT0, LON0, 1))


def test_gdal_reads_the_live_holes_and_gaps(tmp_path: Path) -> None:
    state = review_station(tmp_path / "st")
    state.mark(4, "rejected")  # left out of every feed
    store = MapStore.open(tmp_path / "st" / "map")
    for tx in (0, 1):
        assert store.put(_seen_but_a_square(tx)) is not None
    with StationWeb(
        state, "127.0.0.1", 0, map_store=store, public_url=PUBLIC, vehicles=lambda h: [1, 2]
    ) as web:
        info = pyogrio.read_info(f"{web.url}holes.geojson")
        assert info["driver"] == "GeoJSON" and info["features"] == 3
        assert info["geometry_type"] == "Point" and info["crs"] == "EPSG:4326"
        assert {"hole_id", "tier", "p_hole", "vehicles", "picture"} <= set(info["fields"])
        _, _, geometry, fields = pyogrio.raw.read(f"{web.url}holes.geojson")
        cols = dict(zip(info["fields"], fields, strict=True))
        assert sorted(cols["hole_id"].tolist()) == [1, 2, 3]
        by_id = {int(i): k for k, i in enumerate(cols["hole_id"])}
        assert cols["tier"][by_id[2]] == "review" and cols["tier"][by_id[1]] == "announced"
        assert list(cols["vehicles"][by_id[1]]) == [1, 2]  # GDAL's IntegerList
        assert cols["picture"][by_id[3]] == f"{PUBLIC}cards/hole-3.jpg"
        assert len(geometry) == 3
        # the same document as JSON, with its content type
        code, body, ctype = _get(f"{web.url}holes.geojson")
        assert code == 200 and ctype == "application/geo+json"
        doc = json.loads(body)
        (h1,) = [f for f in doc["features"] if f["properties"]["hole_id"] == 1]
        assert h1["geometry"]["coordinates"] == pytest.approx([-79.38311, 43.65333])
        # the gaps of the live map: polygons, and the surveyed area with its fraction
        gaps = pyogrio.read_info(f"{web.url}gaps.geojson")
        assert gaps["features"] == 2 and gaps["geometry_type"] == "Polygon"
        _, _, _, gfields = pyogrio.raw.read(f"{web.url}gaps.geojson")
        g = dict(zip(gaps["fields"], gfields, strict=True))
        assert g["kind"].tolist() == ["gap", "surveyed area"]
        assert g["area_m2"][0] == pytest.approx(1.44, rel=0.1)  # the 1.2 m square
        frac = 1 - g["gap_m2"][1] / g["area_m2"][1]  # the surveyed area: the hull of the seen
        assert g["searched_fraction"][1] == pytest.approx(frac, abs=0.03) and frac < 0.95
        gdoc = json.loads(_get(f"{web.url}gaps.geojson")[1])
        lon, lat = gdoc["features"][0]["geometry"]["coordinates"][0][0]
        assert abs(lat - 43.6532) < 0.001 and abs(lon + 79.3832) < 0.001


def test_networklink_and_kml_validate(tmp_path: Path) -> None:
    state = review_station(tmp_path / "st")
    with StationWeb(state, "127.0.0.1", 0, public_url=PUBLIC, kml_refresh_s=7) as web:
        code, body, ctype = _get(f"{web.url}holes_live.kml")
        assert code == 200 and ctype == "application/vnd.google-earth.kml+xml"
        root = ET.fromstring(body)
        assert root.tag == f"{KML}kml" and len(root) == 1
        (nl,) = root
        assert nl.tag == f"{KML}NetworkLink" and nl.findtext(f"{KML}name")
        (link,) = nl.findall(f"{KML}Link")
        assert [c.tag for c in link] == [f"{KML}href", f"{KML}refreshMode", f"{KML}refreshInterval"]
        assert link.findtext(f"{KML}href") == f"{PUBLIC}holes.kml"
        assert link.findtext(f"{KML}refreshMode") == "onInterval"
        assert float(link.findtext(f"{KML}refreshInterval") or "0") == 7.0
        # the document it points at (fetched at the bound address here)
        code, body, _ = _get(f"{web.url}holes.kml")
        assert code == 200
        kml = ET.fromstring(body)
        assert kml.tag == f"{KML}kml"
        (doc,) = kml.findall(f"{KML}Document")
        marks = doc.findall(f"{KML}Placemark")
        assert len(marks) == 4
        for pm in marks:
            lon, lat, _alt = (float(v) for v in pm.findtext(f".//{KML}coordinates", "").split(","))
            assert abs(lat - 43.6533) < 0.001 and abs(lon + 79.3831) < 0.001
            data = {d.get("name"): d.findtext(f"{KML}value") for d in pm.iter(f"{KML}Data")}
            hid = json.loads(data["hole_id"] or "null")
            assert f'src="{PUBLIC}cards/hole-{hid}.jpg"' in (pm.findtext(f"{KML}description") or "")
            assert json.loads(data["tier"] or "null") in ("announced", "review")


def test_feeds_are_read_only_and_guarded(tmp_path: Path) -> None:
    state = review_station(tmp_path / "st")
    limits = Limits(rate_per_s=0.5, burst=6)
    with StationWeb(state, "127.0.0.1", 0, limits=limits) as web:
        host = f"127.0.0.1:{web.port}"
        assert _raw(web.port, "/holes.geojson", host) == 200
        assert json.loads(_get(f"{web.url}gaps.geojson")[1])["features"] == []  # no map yet
        assert _raw(web.port, "/holes.geojson", f"evil.example:{web.port}") == 403  # rebinding
        code, _, _ = _get(
            f"{web.url}holes.kml",
            {"Origin": "http://evil.example", "Sec-Fetch-Site": "cross-site"},
        )
        assert code == 403  # a page of another site cannot read them
        req = urllib.request.Request(f"{web.url}holes.geojson", data=b"{}", method="POST")
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(req, timeout=10)
        assert err.value.code == 405
        codes = [_raw(web.port, "/gaps.geojson", host) for _ in range(8)]
        assert 429 in codes  # the rate limit applies to the feeds too


def test_cot_picture_links_carry_the_lan_address(tmp_path: Path) -> None:
    for public, host, want in (
        ("http://192.168.1.10:0", "127.0.0.1", "http://192.168.1.10:0/"),
        (None, "0.0.0.0", None),  # the bound address: the laptop's primary one
    ):
        cot_port = free_udp_port()
        rx = PytakReceiver(f"udp+ro://127.0.0.1:{cot_port}")
        opts = GroundOptions(
            mavlink=f"udpin:127.0.0.1:{free_udp_port()}",
            out=tmp_path / f"st-{host}",
            http_host=host,
            http_port=0,
            cot_url=f"udp+wo://127.0.0.1:{cot_port}",
            public_url=public,
        )
        try:
            with GroundStation(opts) as station:
                assert station.web is not None
                base = want or station.web.url
                assert not base.startswith(("http://127.", "http://localhost"))
                facts = {"id": 7, "rev": 1, "lat": 43.6533, "lon": -79.3831, "score": 0.9}
                station.state.on_card(facts, picture(7))
                got = rx.got
                wait_for(lambda g=got: any(b"cards/hole-7.jpg" in d for d in g), 20.0, "CoT")
                (event,) = [d for d in rx.got if b"cards/hole-7.jpg" in d][-1:]
                link = ET.fromstring(event).find("detail/link")
                assert link is not None
                assert link.get("url") == f"{base}cards/hole-7.jpg"
        finally:
            rx.close()


def test_public_url_is_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for bad in ("https://x:8080", "http://x", "http://x:8080/path", "ftp://x:1"):
        args = f"ground --mavlink udpin:127.0.0.1:1 -o {tmp_path / 's'} --public-url {bad}"
        code = cli.main(args.split())
        err = capsys.readouterr().err
        assert code != 0 and "--public-url wants http://HOST:PORT" in err
        assert "Traceback" not in err and not (tmp_path / "s").exists()
    args = f"ground --mavlink udpin:127.0.0.1:1 -o {tmp_path / 's'} --http 127.0.0.1:8080"
    code = cli.main([*args.split(), "--public-url", "http://10.0.0.5:9090"])
    assert code != 0 and "give the same port" in capsys.readouterr().err


def _seen_by_two(folder: Path) -> StationState:
    """Vehicle 1 reports its hole 5; vehicle 2 then reports its hole 3 at the same opening
    with a card whose "why" is hostile text; hole 8 is vehicle 1's alone."""
    state = StationState.open(folder)
    t = iter(range(1, 100))
    state.clock = lambda: 1_796_000_000_000_000_000 + next(t) * 1_000_000_000
    state.on_statustext("HOLE 5 p0.91 43.6533100 -79.3831200", sysid=1)
    state.on_statustext("HOLE 8 p0.80 43.6534100 -79.3830200", sysid=1)
    facts = {
        *(("id", 3), ("rev", 1), ("lat", 43.65331), ("lon", -79.38312), ("score", 0.9)),
        *(("sigma", 0.3), ("n", 6), ("major", 1.1), ("minor", 0.7), ("p", 0.93)),
        ("why", '</remarks><script>alert("x")</script> & <b>rim</b> \x07seen'),
    }
    state.on_card(dict(facts), picture(3), sysid=2)
    return state


def test_which_vehicles_saw_a_hole_in_kml_geojson_and_cot(tmp_path: Path) -> None:
    """GDAL reads the vehicles of each hole (first and last) from /holes.geojson and from
    /holes.kml (its description and ExtendedData); pytak carries the CoT to a pytak
    receiver and @tak-ps/node-cot parses the remarks and the holescan facts; the hostile
    "why" stays text everywhere."""
    state = _seen_by_two(tmp_path / "st")
    _, holes, _ = state.snapshot()
    by_id = {h.id: h for h in holes}
    assert set(by_id) == {5, 8}  # vehicle 2's hole 3 is hole 5: one id per opening
    assert by_id[5].sysids == [1, 2] and by_id[5].first_last == (1, 2)
    with StationWeb(state, "127.0.0.1", 0, public_url=PUBLIC) as web:
        info = pyogrio.read_info(f"{web.url}holes.geojson")
        _, _, _, fields = pyogrio.raw.read(f"{web.url}holes.geojson")
        cols = dict(zip(info["fields"], fields, strict=True))
        row = {int(i): k for k, i in enumerate(cols["hole_id"])}
        assert list(cols["vehicles"][row[5]]) == [1, 2] and list(cols["vehicles"][row[8]]) == [1]
        assert cols["first_vehicle"][row[5]] == 1 and cols["last_vehicle"][row[5]] == 2
        assert cols["first_vehicle"][row[8]] == 1 and cols["last_vehicle"][row[8]] == 1
        kml_info = pyogrio.read_info(f"/vsicurl/{web.url}holes.kml")
        assert kml_info["features"] == 2
        _, _, _, kfields = pyogrio.raw.read(f"/vsicurl/{web.url}holes.kml")
        k = dict(zip(kml_info["fields"], kfields, strict=True))
        desc = {str(n): str(d) for n, d in zip(k["Name"], k["description"], strict=True)}
        assert "seen by vehicles 1 + 2 (first 1, last 2)" in desc["hole 5 (new)"]
        assert "seen by vehicle 1," in desc["hole 8 (new)"]
        assert "<script>" not in desc["hole 5 (new)"]  # HTML of the text: &lt;script&gt;
        assert json.loads(k["vehicles"][0]) == [1, 2] and k["last_vehicle"].tolist() == ["2", "1"]
        code, body, _ = _get(f"{web.url}holes.kml")
        assert code == 200
        root = ET.fromstring(body)  # well-formed whatever the why held
        pm5 = [p for p in root.iter(f"{KML}Placemark") if "hole 5 " in p.findtext(f"{KML}name", "")]
        data = {d.get("name"): d.findtext(f"{KML}value") for d in pm5[0].iter(f"{KML}Data")}
        assert json.loads(data["vehicles"] or "null") == [1, 2]
        assert json.loads(data["last_vehicle"] or "null") == 2
    # CoT: published by pytak, received by pytak, parsed by node-cot
    port = free_udp_port()
    rx = PytakReceiver(f"udp+ro://127.0.0.1:{port}")
    try:
        with CotPublisher(f"udp+wo://127.0.0.1:{port}") as pub:
            events = [hole_cot(h, picture_url=f"{PUBLIC}cards/hole-{h.id}.jpg") for h in holes]
            for ev in events:
                assert b"<script>" not in ev  # escaped: text, never markup
            wait_for(lambda: pub.publish(events) is None and len(rx.got) >= 2, 20.0, "the CoT")
    finally:
        rx.close()
    if not (NODE_COT / "node_modules" / "@tak-ps" / "node-cot").exists():
        pytest.skip(f"npm install --prefix {NODE_COT} (the independent CoT parser)")
    lines = b"\n".join(g.replace(b"\n", b" ") for g in rx.got)
    res = subprocess.run(
        ["node", str(NODE_COT / "parse.mjs")], input=lines, capture_output=True, timeout=60
    )
    assert res.returncode == 0, res.stderr.decode()[-2000:]
    parsed = {p["raw"]["uid"]: p for p in json.loads(res.stdout)}
    five = parsed["holescan-ground-hole-5"]["geojson"]["properties"]
    assert "seen by vehicles 1 + 2 (first 1, last 2)" in five["remarks"]
    assert '<script>alert("x")</script>' in five["remarks"]  # the text, as text
    eight = parsed["holescan-ground-hole-8"]["geojson"]["properties"]
    assert "seen by vehicle 1," in eight["remarks"]
    facts = ET.fromstring(events[0]).find("detail/holescan")
    assert facts is not None and facts.get("vehicles") == "1 2"
    assert (facts.get("first_vehicle"), facts.get("last_vehicle")) == ("1", "2")
