"""A simulated flight to the ground crew with real parts in between.

``holescan fly --sensor sim --gcs udpout:...`` (simulated autopilot, Xtion, daemon, hole
server) -> :class:`AutopilotRouter` (the autopilot's routing, as ArduPilot forwards its
companion's TELEM2 on the radio: the companion's packets and the autopilot's own
HEARTBEAT, GLOBAL_POSITION_INT and ATTITUDE on one link; without it MAVProxy hears no
autopilot and the page's track stays empty) -> the real MAVProxy (``--master udpin``
``--out udpout``) -> a UDP relay that cuts the link for 10 s mid-flight -> ``holescan
ground`` (a separate process) -> CoT over UDP to a real pytak client (TAK protocol v1,
decoded by takproto) and the live page in headless Chromium (driven over the DevTools
protocol: it must show a new hole within 2 s of the vehicle's announcement; a click on
"confirmed" in the browser paired with the station's token must reach the state, TAK and
the KML; the autopilot's track and the camera's footprints must reach the page).

The screenshot is kept (``HOLESCAN_ARTEFACTS`` folder if set, else the test's tmp dir).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import pytest
from devtools import CHROMIUM, Tab, start_chromium
from test_station import PytakReceiver, Relay, parse_tak, wait_for

from holescan.link import mavlink
from tests._support import SIM_TOML, free_tcp_port, free_udp_port

ROOT = Path(__file__).resolve().parents[3]


class AutopilotRouter:
    """The radio link as the autopilot makes it: the companion's packets (``port``) go on
    to MAVProxy and back, and the autopilot (system 1, component 1) adds its own
    telemetry: HEARTBEAT at 1 Hz, GLOBAL_POSITION_INT and ATTITUDE at 4 Hz, flying a
    line north-east at 3 m over the simulator's home."""

    def __init__(self, mavproxy_port: int) -> None:
        self.to = ("127.0.0.1", mavproxy_port)
        self.inp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.inp.bind(("127.0.0.1", 0))
        self.inp.settimeout(0.1)
        self.port = int(self.inp.getsockname()[1])
        self.out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.out.bind(("127.0.0.1", 0))
        self.out.settimeout(0.1)
        self.companion: tuple[str, int] | None = None
        self.sent_positions = 0
        self._mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._up, daemon=True),
            threading.Thread(target=self._down, daemon=True),
            threading.Thread(target=self._telemetry, daemon=True),
        ]
        for t in self._threads:
            t.start()

    def _up(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.inp.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            self.companion = addr
            self.out.sendto(data, self.to)

    def _down(self) -> None:
        while not self._stop.is_set():
            try:
                data, _ = self.out.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            if self.companion is not None:
                self.inp.sendto(data, self.companion)

    def _telemetry(self) -> None:
        t0 = time.monotonic()
        k = 0
        while not self._stop.wait(0.25):
            t = time.monotonic() - t0
            ms = int(t * 1000)
            msgs = [
                self._mav.attitude_encode(ms, 0.0, 0.0, 0.785, 0.0, 0.0, 0.0),
                self._mav.global_position_int_encode(
                    ms,
                    int((43.6532 + 0.2e-5 * t) * 1e7),
                    int((-79.3832 + 0.3e-5 * t) * 1e7),
                    123_000,
                    3_000,
                    20,
                    20,
                    0,
                    4500,
                ),
            ]
            if k % 4 == 0:
                msgs.append(
                    self._mav.heartbeat_encode(
                        mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4
                    )
                )
            k += 1
            for m in msgs:
                try:
                    self.out.sendto(m.pack(self._mav), self.to)
                except OSError:
                    return
            self.sent_positions += 1

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self.inp.close()
        self.out.close()


def holescan(*args: str, log: Path) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "holescan.cli", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=open(log, "w"),
        text=True,
    )


class Chromium(Tab):
    """Headless Chromium driven over the DevTools protocol: its first tab."""

    def __init__(self, url: str, profile: Path) -> None:
        self.proc, port = start_chromium(profile, url)
        targets: list[dict[str, Any]] = []

        def page_up() -> bool:
            nonlocal targets
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=20) as r:
                targets = [t for t in json.loads(r.read()) if t.get("type") == "page"]
            return bool(targets)

        wait_for(page_up, 60.0, "Chromium's first tab")
        super().__init__(targets[0]["webSocketDebuggerUrl"])

    def close(self) -> None:
        super().close()
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def announced_at(log: Path, words: str = "HOLE") -> dict[int, float]:
    """Hole id -> wall time (unix s) of its first announcement, from the flight's log
    (``words="HOLE|REVIEW"``: holes for review too: they reach the page as well)."""
    out: dict[int, float] = {}
    pat = re.compile(
        rf"^(\d{{4}}-\d\d-\d\d \d\d:\d\d:\d\d),(\d{{3}}) .*announced (?:{words}) (\d+) "
    )
    for line in log.read_text().splitlines():
        m = pat.match(line)
        if m and int(m[3]) not in out:
            t = dt.datetime.strptime(m[1], "%Y-%m-%d %H:%M:%S").timestamp() + int(m[2]) / 1000
            out[int(m[3])] = t
    return out


def stop(proc: subprocess.Popen[str], sig: int = signal.SIGINT, timeout: float = 60.0) -> str:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out or ""


@pytest.mark.slow
@pytest.mark.timeout(420)
@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian chromium (/usr/bin/chromium)")
def test_flight_mavproxy_ground_page_tak(tmp_path: Path) -> None:
    mavproxy = shutil.which("mavproxy.py")
    if mavproxy is None:
        pytest.skip("MAVProxy is not installed (a test dependency)")
    art = Path(os.environ.get("HOLESCAN_ARTEFACTS", tmp_path))
    art.mkdir(parents=True, exist_ok=True)
    gcs, ground_port = free_udp_port(), free_udp_port()
    http, cot = free_tcp_port(), free_udp_port()  # the page is TCP, CoT UDP
    relay = Relay(ground_port)
    relay_in = relay.port
    rx = PytakReceiver(f"udp+ro://127.0.0.1:{cot}")
    router = AutopilotRouter(gcs)
    station_dir = tmp_path / "station"
    ground = holescan(
        "ground",
        "--mavlink",
        f"udpin:127.0.0.1:{ground_port}",
        "-o",
        str(station_dir),
        "--http",
        f"127.0.0.1:{http}",
        "--cot",
        f"udp+wo://127.0.0.1:{cot}",
        "--cot-proto",
        "1",
        log=tmp_path / "ground.log",
    )
    mav = subprocess.Popen(
        [
            mavproxy,
            f"--master=udpin:127.0.0.1:{gcs}",
            f"--out=udpout:127.0.0.1:{relay_in}",
            "--daemon",
            "--streamrate=-1",
            f"--state-basedir={tmp_path}",
            "--target-system",
            "1",
            "--target-component",
            "191",
        ],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        stdin=subprocess.DEVNULL,
    )
    cfg = tmp_path / "fly.toml"
    cfg.write_text(SIM_TOML)
    browser: Chromium | None = None
    fly: subprocess.Popen[str] | None = None
    try:
        page = f"http://127.0.0.1:{http}/"
        wait_for(lambda: _up(page), 120.0, "the ground station's page")
        # the operator's pairing link, issued while the station runs (never in its log)
        pair = subprocess.run(
            [
                *(sys.executable, "-m", "holescan.cli", "pair", "-o", str(station_dir)),
                *("flight test", "--http", f"127.0.0.1:{http}"),
            ],
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            capture_output=True,
            text=True,
            check=True,
        )
        link = pair.stdout.strip().split(": ", 1)[1]
        assert link.startswith(f"{page}?token=")
        browser = Chromium(link, tmp_path / "profile")
        wait_for(lambda: browser.js("document.readyState") == "complete", 60.0, "page load")
        fly = holescan(
            "fly",
            "--config",
            str(cfg),
            "--log-dir",
            str(tmp_path / "logs"),
            "--gcs",
            f"udpout:127.0.0.1:{router.port}",
            "--duration",
            "75",
            log=tmp_path / "fly.log",
        )
        # the first hole appears on the page without a reload
        wait_for(lambda: browser.js("document.querySelectorAll('.hole').length") > 0, 200, "hole")
        t_seen = time.time()
        first = announced_at(tmp_path / "fly.log", "HOLE|REVIEW")
        assert first, (tmp_path / "fly.log").read_text()[-3000:]
        latency = t_seen - min(first.values())
        # reported, not asserted: the 2 s goal is benchmarks/bench_station.py's (a wall-clock
        # bound fails on a loaded machine); the wait above is the liveness check
        print(f"page showed the first hole {latency:.2f} s after the vehicle announced it")
        # cut the link for 10 s mid-flight
        relay.cut = True
        time.sleep(10.0)
        relay.cut = False
        fly_out, _ = fly.communicate(timeout=200)
        code = fly.returncode
        assert code == 0, (tmp_path / "fly.log").read_text()[-3000:]
        announced = announced_at(tmp_path / "fly.log")
        state_path = station_dir / "station.json"

        def all_there() -> bool:
            doc = json.loads(state_path.read_text())
            got = {h["id"]: h for h in doc["holes"]}
            return all(i in got and got[i]["has_picture"] for i in announced)

        wait_for(all_there, 60.0, f"every announced hole {sorted(announced)} with its picture")
        n = browser.js("document.querySelectorAll('.hole').length")
        assert n == len(json.loads(state_path.read_text())["holes"]) >= len(announced)
        # the operator confirms the first hole with a click on the page
        hid = min(announced)
        n_cot = len(rx.got)
        wait_for(lambda: browser.js("document.body.dataset.canMark") == "yes", 30.0, "paired")
        browser.js(
            f'document.querySelector(\'button[data-id="{hid}"][data-mark="confirmed"]\').click()'
        )
        wait_for(
            lambda: any(
                h["id"] == hid and h["mark"] == "confirmed"
                for h in json.loads(state_path.read_text())["holes"]
            ),
            30.0,
            "the mark in the state file",
        )
        audit = [json.loads(x) for x in (station_dir / "audit.jsonl").read_text().splitlines()]
        assert audit[-1]["operator"] == "flight test" and audit[-1]["hole"] == hid
        assert audit[-1]["pairing"] == "p2"  # p1: "operator 1", issued at the station's start
        token = link.split("?token=", 1)[1]
        assert token not in (tmp_path / "ground.log").read_text()
        wait_for(lambda: len(rx.got) > n_cot, 30.0, "CoT after the click")
        ev = [e for e in parse_tak(rx.got[n_cot:]) if e.uid == f"holescan-ground-hole-{hid}"][-1]
        assert "operator: confirmed" in ev.detail.xmlDetail
        kml = (station_dir / "holes.kml").read_text()
        assert f"hole {hid} (confirmed)" in kml
        wait_for(
            lambda: (
                browser.js(f"document.getElementById('hole-{hid}').dataset.mark") == "confirmed"
            ),
            30.0,
            "the page to show the mark",
        )
        # the autopilot's telemetry through MAVProxy: the track and the camera's footprints
        with urllib.request.urlopen(page + "state.json", timeout=5) as r:
            doc = json.loads(r.read())
        assert router.sent_positions > 100
        assert len(doc["track"]) >= 20 and len(doc["footprints"]) >= 5, len(doc["track"])
        print("track points on the page:", len(doc["track"]), "footprints:", len(doc["footprints"]))
        browser.screenshot(art / "ground-station.png")
        assert (art / "ground-station.png").stat().st_size > 10_000
        # the pictures stayed inside the byte budget
        m = re.search(r"hole pictures: (\d+) sent, (\d+) B \((\d+) B/s", fly_out)
        assert m is not None, fly_out[-2000:]
        print("fly:", m[0], "announced", sorted(announced))
        assert int(m[3]) <= 1000
    finally:
        if browser is not None:
            browser.close()
        if fly is not None and fly.poll() is None:
            stop(fly)
        stop(ground)
        mav.send_signal(signal.SIGINT)
        try:
            mav.wait(timeout=15)
        except subprocess.TimeoutExpired:
            mav.kill()
        rx.close()
        relay.close()
        router.close()
    log = (tmp_path / "ground.log").read_text()
    assert "Traceback" not in log, log[-3000:]


def _up(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as r:
            return bool(r.status == 200)
    except OSError:
        return False
