"""``holescan ground`` against the real vehicle-side server over loopback UDP.

The vehicle is :class:`missions.HoleMissionServer` (STATUSTEXT, cards under the byte
budget, the hole mission of component 191); the station collects, writes its files,
publishes CoT with pytak, received by a real pytak client and parsed by takproto (TAK
protocol v1) and by @tak-ps/node-cot (CoT XML) under node. A UDP relay in between cuts the
link for 10 s. Restarts resume from the state file.
"""

from __future__ import annotations

import asyncio
import configparser
import contextlib
import json
import shutil
import socket
import subprocess
import threading
import time
import urllib.request
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import gpxpy
import numpy as np
import pytest

from holescan import cli
from holescan.geotag import Hole
from holescan.ground import GroundOptions, GroundStation, StationState, state_document
from holescan.link import mavlink
from holescan.missions import HoleMissionServer
from tests._support import free_udp_port

NODE_COT = Path(__file__).parents[1] / "cot"  # tests/ground/cot: the node parser
HOME = (43.6532, -79.3832)


def hole(hid: int, score: float = 0.88, sigma: float = 0.3, p_hole: float = 0.95) -> Hole:
    lat, lon = HOME[0] + hid * 2e-5, HOME[1] + hid * 1e-5
    return Hole(
        hid, lat, lon, 121.0, sigma, score, 9, 10**9, 3 * 10**9, 4, (1, 2, 30, 20), 1.1, 0.7,
        p_hole=p_hole,
    )  # fmt: skip


def picture(seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur((rng.random((72, 96, 3)) * 255).astype(np.uint8), (7, 7), 3)
    return cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 60])[1].tobytes()


def wait_for(cond: Callable[[], bool], timeout_s: float, what: str) -> float:
    """Poll ``cond`` until true; return the seconds it took.

    Every timeout given is a liveness bound, 10x or more what the wait takes on an idle
    machine (a STATUSTEXT ~0.05 s, a card and the mission ~2-5 s): reaching it means the
    thing never came, not that it was slow. How fast is measured by benchmarks/.
    """
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if cond():
            return time.monotonic() - t0
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


class PytakReceiver:
    """A real pytak client (``udp+ro://``) collecting datagrams on its own asyncio loop."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.got: list[bytes] = []
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        assert self._ready.wait(5.0)

    def _run(self) -> None:
        import pytak

        async def main() -> None:
            parser = configparser.ConfigParser()
            parser["rx"] = {"COT_URL": self.url}
            reader, _ = await pytak.protocol_factory(parser["rx"])
            self._ready.set()
            while True:
                data, _addr = await reader.recv()
                self.got.append(bytes(data))

        self._task = self._loop.create_task(main())
        self._loop.run_until_complete(asyncio.sleep(0))
        with contextlib.suppress(asyncio.CancelledError, RuntimeError):
            self._loop.run_until_complete(self._task)

    def close(self) -> None:
        self._loop.call_soon_threadsafe(self._task.cancel)
        self._thread.join(timeout=5.0)


class Relay:
    """UDP relay vehicle <-> station that can be cut (drops both ways while cut)."""

    def __init__(self, to_port: int) -> None:
        self.port = free_udp_port()
        self.to = ("127.0.0.1", to_port)
        self.cut = False
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", self.port))
        self.sock.settimeout(0.1)
        self.out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.out.bind(("127.0.0.1", 0))
        self.out.settimeout(0.1)
        self.vehicle: tuple[str, int] | None = None
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._pump, args=(self.sock, True), daemon=True),
            threading.Thread(target=self._pump, args=(self.out, False), daemon=True),
        ]
        for t in self._threads:
            t.start()

    def _pump(self, sock: socket.socket, from_vehicle: bool) -> None:
        while not self._stop.is_set():
            try:
                data, addr = sock.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            if self.cut:
                continue
            if from_vehicle:
                self.vehicle = addr
                self.out.sendto(data, self.to)
            elif self.vehicle is not None:
                self.sock.sendto(data, self.vehicle)

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self.sock.close()
        self.out.close()


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[dict[str, Any]]:
    """Vehicle server -> relay -> station; CoT (TAK protocol v1) to a pytak receiver."""
    station_port, cot_port = free_udp_port(), free_udp_port()
    relay = Relay(station_port)
    rx = PytakReceiver(f"udp+ro://127.0.0.1:{cot_port}")
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{station_port}",
        out=tmp_path / "station",
        http_port=0,
        cot_url=f"udp+wo://127.0.0.1:{cot_port}",
        cot_proto=1,
    )
    station = GroundStation(opts).__enter__()
    server = HoleMissionServer(
        f"udpout:127.0.0.1:{relay.port}", 1, card_bytes_per_s=2000
    ).__enter__()
    try:
        yield {"station": station, "server": server, "relay": relay, "rx": rx, "opts": opts}
    finally:
        server.close()
        station.__exit__(None, None, None)
        rx.close()
        relay.close()


def announce(server: HoleMissionServer, holes: list[Hole]) -> None:
    server.update_holes(holes)
    for h in holes:
        server.announce(h)
        server.send_card(h, picture(h.id), f"score {h.score:.2f}: 1.10 x 0.70 m opening")


def complete(station: GroundStation, ids: set[int]) -> Callable[[], bool]:
    def ok() -> bool:
        _, holes, _ = station.state.snapshot()
        got = {h.id for h in holes if h.has_picture and h.seq is not None}
        return ids <= got

    return ok


def parse_tak(data: list[bytes]) -> list[Any]:
    import takproto

    out = []
    for d in data:
        msg = takproto.parse_proto(bytearray(d))
        assert msg is not None, d[:40]
        out.append(msg.cotEvent)
    return out


def test_holes_pictures_files_and_cot(rig: dict[str, Any]) -> None:
    station, server, rx = rig["station"], rig["server"], rig["rx"]
    holes = [hole(1), hole(2, score=0.71, sigma=0.5)]
    first_rev: dict[int, int] = {}  # hole id -> its card revision when the ground first had it

    def on_change(_version: int) -> None:
        for g in station.state.snapshot()[1]:
            first_rev.setdefault(g.id, g.card_rev)

    station.state.listeners.append(on_change)
    # A STATUSTEXT sent before the station hears the vehicle is lost (UDP); the hole then
    # comes with the cards the station asks for at link-up: wait for the link first.
    wait_for(lambda: station.link.link_up, 20.0, "the vehicle link")
    announce(server, holes)
    # Liveness only (the latency is benchmarks/bench_station.py's: ~5 ms over loopback):
    # 20 s is far beyond it, and the holes must come from the STATUSTEXTs, ahead of any card.
    wait_for(lambda: len(first_rev) == 2, 20.0, "both STATUSTEXTs")
    assert first_rev == {1: 0, 2: 0}
    wait_for(complete(station, {1, 2}), 30.0, "pictures and the hole mission")
    _, got, _ = station.state.snapshot()
    for g, h in zip(got, holes, strict=True):
        assert (g.id, g.lat_deg, g.lon_deg) == (h.id, round(h.lat_deg, 7), round(h.lon_deg, 7))
        assert g.sigma_h_m == h.sigma_h_m and g.sightings == 9 and g.why.startswith("score")
        assert station.state.card_path(h.id).read_bytes().startswith(b"\xff\xd8\xff\xfe")
    assert {g.seq for g in got} == {1, 2}  # hole 1 (higher score) is waypoint 1
    out = rig["opts"].out
    wait_for(lambda: (out / "holes.kml").read_text().count("<Placemark>") == 2, 5.0, "KML")
    gj = json.loads((out / "holes.geojson").read_text())
    assert sorted(f["properties"]["hole_id"] for f in gj["features"]) == [1, 2]
    gpx = gpxpy.parse((out / "holes.gpx").read_text())
    assert len(gpx.waypoints) == 2
    live = ET.parse(out / "holes_live.kml").getroot()
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    assert live.findtext(".//k:href", namespaces=ns) == "holes.kml"
    assert live.findtext(".//k:refreshMode", namespaces=ns) == "onInterval"
    # CoT: the newest event of each uid, decoded by takproto (TAK protocol v1 mesh)
    wait_for(lambda: {e.uid for e in parse_tak(rx.got)} >= {"holescan-ground-hole-1"}, 5.0, "CoT")
    events = {e.uid: e for e in parse_tak(rx.got)}
    e1 = events["holescan-ground-hole-1"]
    assert e1.type == "b-m-p-s-p-i" and e1.how == "m-g"
    assert e1.lat == pytest.approx(holes[0].lat_deg, abs=1e-7)
    assert e1.lon == pytest.approx(holes[0].lon_deg, abs=1e-7)
    assert e1.ce == pytest.approx(1.6215 * 0.3, abs=0.01)
    assert e1.staleTime - e1.sendTime == pytest.approx(3600_000, abs=2000)
    assert "score 0.88" in e1.detail.xmlDetail and "opening 1.10 x 0.70 m" in e1.detail.xmlDetail
    assert e1.detail.contact.callsign == "HOLE 1"
    # the operator rejects hole 2 on the page: withdrawn from TAK and the files
    n0 = len(rx.got)
    (_, token), *_ = station.new_pairings  # the one issued at start ("operator 1")
    req = urllib.request.Request(
        f"{station.web.url}holes/2/mark",
        data=json.dumps({"mark": "rejected"}).encode(),
        headers={
            "Authorization": f"Bearer {token}",
            "Content-Type": "application/json",
        },
        method="POST",
    )
    with urllib.request.urlopen(req, timeout=5) as resp:
        assert json.loads(resp.read()) == {"id": 2, "mark": "rejected", "tier": "rejected"}
    wait_for(lambda: len(rx.got) >= n0 + 2, 5.0, "the withdrawal")
    tail = parse_tak(rx.got[n0:])
    assert tail[0].uid == "holescan-ground-hole-2" and tail[0].staleTime <= tail[0].sendTime
    assert tail[1].type == "t-x-d-d" and 'uid="holescan-ground-hole-2"' in tail[1].detail.xmlDetail
    assert (out / "holes.kml").read_text().count("<Placemark>") == 1
    # the budget held: cards bytes over the time they took
    assert server.cards.bytes_sent > 0


def test_track_and_footprints_from_the_autopilot(rig: dict[str, Any]) -> None:
    """GLOBAL_POSITION_INT/ATTITUDE of the autopilot (component 1) draw the track."""
    station, server = rig["station"], rig["server"]
    announce(server, [hole(1)])
    wait_for(lambda: 1 in station.state.holes, 5.0, "hole 1")
    autopilot = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)

    def send(msg: Any) -> None:
        server.send_with(lambda mav: mav.file.write(msg.pack(autopilot)))

    for k in range(4):
        lat, lon = int((HOME[0] + k * 1e-5) * 1e7), int(HOME[1] * 1e7)
        send(autopilot.attitude_encode(k * 1000, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0))
        send(autopilot.global_position_int_encode(k * 1000, lat, lon, 123_000, 3_000, 0, 0, 0, 0))
        time.sleep(1.1)
    wait_for(lambda: len(station.state.track) >= 3, 5.0, "the track")
    doc = state_document(station.state, footprint_every=1)
    assert len(doc["track"]) >= 3 and len(doc["footprints"]) >= 3
    (x0, y0), (x1, y1) = doc["track"][0], doc["track"][1]
    assert y1 - y0 == pytest.approx(1.113, abs=0.01) and abs(x1 - x0) < 0.01  # metres north
    fp = np.array(doc["footprints"][0])
    w = np.linalg.norm(fp[1] - fp[0])  # across track at 3 m: 2 * 3 tan(29 deg)
    assert w == pytest.approx(2 * 3.0 * np.tan(np.radians(29.0)), abs=0.02)


@pytest.mark.slow
def test_link_cut_for_10_s_loses_no_hole(rig: dict[str, Any]) -> None:
    station, server, relay = rig["station"], rig["server"], rig["relay"]
    announce(server, [hole(1)])
    wait_for(complete(station, {1}), 20.0, "hole 1")
    relay.cut = True
    announce(server, [hole(1), hole(2), hole(3, score=0.65)])  # announced into the void
    time.sleep(10.0)
    assert set(station.state.holes) == {1}
    relay.cut = False
    wait_for(complete(station, {1, 2, 3}), 60.0, "holes 2 and 3 after the cut")
    assert station.link is not None and station.link.resync_requests >= 1


def test_restart_resumes_ids_marks_and_pictures(tmp_path: Path) -> None:
    port = free_udp_port()
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{port}", out=tmp_path / "st", http_port=None, cot_url=None
    )
    with GroundStation(opts) as station, HoleMissionServer(f"udpout:127.0.0.1:{port}", 1) as srv:
        announce(srv, [hole(4), hole(5)])
        wait_for(complete(station, {4, 5}), 60.0, "holes 4, 5")
        station.mark(4, "visited")
    state = StationState.open(tmp_path / "st")
    assert {h.id: h.mark for h in state.holes.values()} == {4: "visited", 5: "new"}
    assert all(h.has_picture for h in state.holes.values())
    # second sortie: a new hole 6 joins, the old ones stay with their marks
    with GroundStation(opts) as station, HoleMissionServer(f"udpout:127.0.0.1:{port}", 1) as srv:
        announce(srv, [hole(6)])
        wait_for(complete(station, {6}), 30.0, "hole 6")
        marks = {h.id: h.mark for h in station.state.holes.values()}
    assert marks == {4: "visited", 5: "new", 6: "new"}


def test_bad_link_and_garbage_keep_the_station_going(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    port = free_udp_port()
    opts = GroundOptions(
        mavlink="udpin:127.0.0.1:notaport", out=tmp_path / "a", http_port=None, cot_url=None
    )
    with GroundStation(opts) as station:
        wait_for(lambda: "cannot open the MAVLink link" in caplog.text, 5.0, "the error line")
        assert station.link is not None and not station.link.link_up
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{port}", out=tmp_path / "b", http_port=None, cot_url=None
    )
    with GroundStation(opts) as station, HoleMissionServer(f"udpout:127.0.0.1:{port}", 1) as srv:
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for n in range(50):  # garbage and a truncated MAVLink frame
            junk.sendto(
                bytes(np.random.default_rng(n).integers(0, 256, 64, dtype=np.uint8)),
                ("127.0.0.1", port),
            )
        junk.sendto(b"\xfd\x09\x00\x00", ("127.0.0.1", port))
        junk.close()
        announce(srv, [hole(1)])
        srv.send_with(lambda mav: mav.statustext_send(5, b"HOLE 99 7.5 999 999"))  # nonsense
        wait_for(complete(station, {1}), 60.0, "hole 1 despite the garbage")
        assert set(station.state.holes) == {1}
    # the CLI: a bad option is one line and exit code 2
    assert (
        cli.main(
            ["ground", "--mavlink", "udpin:127.0.0.1:1", "-o", str(tmp_path / "c"), "--http", "x:y"]
        )
        == 2
    )


@pytest.mark.skipif(shutil.which("node") is None, reason="needs node")
def test_cot_xml_parsed_by_node_cot(tmp_path: Path) -> None:
    """The XML the station sends over UDP, received by pytak, parsed by @tak-ps/node-cot."""
    if not (NODE_COT / "node_modules" / "@tak-ps" / "node-cot").exists():
        pytest.skip(f"npm install --prefix {NODE_COT} (the independent CoT parser)")
    port, cot_port = free_udp_port(), free_udp_port()
    rx = PytakReceiver(f"udp+ro://127.0.0.1:{cot_port}")
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{port}",
        out=tmp_path / "st",
        http_port=None,
        cot_url=f"udp+wo://127.0.0.1:{cot_port}",
    )
    try:
        with (
            GroundStation(opts) as station,
            HoleMissionServer(f"udpout:127.0.0.1:{port}", 1) as srv,
        ):
            announce(srv, [hole(1)])
            wait_for(complete(station, {1}), 30.0, "hole 1")
            wait_for(lambda: any(b"sigma" in g for g in rx.got), 5.0, "CoT with the card's facts")
    finally:
        rx.close()
    lines = b"\n".join(g.replace(b"\n", b" ") for g in rx.got)
    res = subprocess.run(
        ["node", str(NODE_COT / "parse.mjs")],
        input=lines,
        capture_output=True,
        timeout=60,
        check=False,
    )
    assert res.returncode == 0, res.stderr.decode()[-2000:]
    parsed = json.loads(res.stdout)
    last = parsed[-1]
    assert last["raw"]["uid"] == "holescan-ground-hole-1" and last["raw"]["type"] == "b-m-p-s-p-i"
    lon, lat = last["geojson"]["geometry"]["coordinates"][:2]
    h = hole(1)
    assert (lat, lon) == pytest.approx((h.lat_deg, h.lon_deg), abs=1e-7)
    assert float(last["point"]["ce"]) == pytest.approx(1.6215 * 0.3, abs=0.01)
    assert "score 0.88" in last["geojson"]["properties"]["remarks"]
    assert last["geojson"]["properties"]["callsign"] == "HOLE 1"
