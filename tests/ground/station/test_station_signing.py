"""A MAVLink-signed link vehicle -> the real MAVProxy -> ``holescan ground``, and forgers.

The vehicle is :class:`missions.HoleMissionServer` with the key; MAVProxy holds the same
passphrase (``signing key``, ``set mavfwd_signing False``) and routes the radio side to the
station (``--out udpout``) and to a second ground port (``--out udpin``); ``holescan
ground --mavlink-key-file`` runs as its own process. Three forgers, all unsigned and all
speaking as the vehicle's hole server (system 1, component 191, the project's own server
code without the key) or as a ground station:

* on the radio side (into MAVProxy's master port): HOLE 99, its card and mission;
* straight at the station's port: HOLE 98, its card and mission;
* on MAVProxy's second ground port: a reboot command, a mission clear and an upload
  addressed to the vehicle's hole server.

The signed holes arrive with their pictures and the hole mission (requests signed by the
station, answered by the vehicle, both through MAVProxy); nothing of the forgers does.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from test_station import hole, picture, wait_for

from holescan.link import SigningKey, open_link
from holescan.missions import HoleMissionServer
from tests._support import free_udp_port

ROOT = Path(__file__).resolve().parents[3]
PASSPHRASE = "rubble-sortie-7"
KEY = SigningKey.from_passphrase(PASSPHRASE)


class RecordingServer(HoleMissionServer):
    """The hole server noting who sent each message it acted on (mission ones aside)."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.heard: list[tuple[int, str, int | None]] = []

    def on_message(self, msg: Any) -> None:
        self.heard.append((msg.get_srcSystem(), msg.get_type(), getattr(msg, "command", None)))
        super().on_message(msg)


def _announce(server: HoleMissionServer, ids: list[int]) -> None:
    holes = [hole(i) for i in ids]
    server.update_holes(holes)
    for h in holes:
        server.announce(h)
        server.send_card(h, picture(h.id), f"score {h.score:.2f}: forged or not")


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_signed_link_through_mavproxy_and_forgers_refused(tmp_path: Path) -> None:
    mavproxy = shutil.which("mavproxy.py")
    if mavproxy is None:
        pytest.skip("MAVProxy is not installed (a test dependency)")
    key_file = tmp_path / "mavlink.key"
    key_file.write_text(PASSPHRASE + "\n")
    key_file.chmod(0o600)
    radio, ground_port, side = free_udp_port(), free_udp_port(), free_udp_port()
    station_dir = tmp_path / "station"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MAVLINK20": "1"}
    log = tmp_path / "ground.log"
    args = ["ground", "--mavlink", f"udpin:127.0.0.1:{ground_port}", "-o", str(station_dir)]
    args += ["--http", "off", "--cot", "off", "--mavlink-key-file", str(key_file)]
    with open(log, "w") as err:
        ground = subprocess.Popen(
            [sys.executable, "-m", "holescan.cli", *args],
            cwd=ROOT,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=err,
        )
    mav = subprocess.Popen(
        [
            mavproxy,
            f"--master=udpin:127.0.0.1:{radio}",
            f"--out=udpout:127.0.0.1:{ground_port}",
            f"--out=udpin:127.0.0.1:{side}",
            "--daemon",
            "--streamrate=-1",
            f"--state-basedir={tmp_path}",
            "--target-system",
            "1",
            "--target-component",
            "191",
            "--cmd",
            f"signing key {PASSPHRASE}; set mavfwd_signing False",
        ],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        stdin=subprocess.DEVNULL,
    )
    servers: list[HoleMissionServer] = []
    links = []
    try:
        vehicle = RecordingServer(
            f"udpout:127.0.0.1:{radio}", 1, card_bytes_per_s=4000, signing=KEY
        ).__enter__()
        servers.append(vehicle)
        _announce(vehicle, [1, 2])
        forgers = [
            HoleMissionServer(f"udpout:127.0.0.1:{port}", 1, card_bytes_per_s=4000)
            for port in (radio, ground_port)
        ]
        for f, hid in zip(forgers, (99, 98), strict=True):
            servers.append(f.__enter__())
            _announce(f, [hid])
        state = station_dir / "station.json"

        def holes() -> dict[int, dict[str, object]]:
            try:
                return {h["id"]: h for h in json.loads(state.read_text())["holes"]}
            except (OSError, ValueError):
                return {}

        def signed_holes_complete() -> bool:
            got = holes()
            return all(i in got and got[i]["has_picture"] and got[i]["seq"] for i in (1, 2))

        # liveness bound (a card at 4000 B/s ~1 s, the mission download a few s)
        wait_for(signed_holes_complete, 60.0, "the signed holes, pictures and mission")
        for f in forgers:  # the forgers said everything they had, more than once
            assert f.flush_cards(30.0)
            _announce(f, [99 if f is forgers[0] else 98])
            assert f.flush_cards(30.0)
        # the forger on MAVProxy's ground side, then a signed peer there as the control
        forger = open_link(f"udpout:127.0.0.1:{side}", source_system=200, source_component=190)
        friend = open_link(
            f"udpout:127.0.0.1:{side}", source_system=253, source_component=190, signing=KEY
        )
        links += [forger, friend]
        forger.mav.heartbeat_send(6, 8, 0, 0, 4)
        forger.mav.command_long_send(1, 191, 246, 0, 1, 0, 0, 0, 0, 0, 0)  # reboot
        forger.mav.mission_clear_all_send(1, 191)
        forger.mav.mission_count_send(1, 191, 1)
        time.sleep(0.5)
        friend.mav.heartbeat_send(6, 8, 0, 0, 4)
        friend.mav.command_long_send(1, 191, 246, 0, 1, 0, 0, 0, 0, 0, 0)
        wait_for(lambda: (253, "COMMAND_LONG", 246) in vehicle.heard, 20.0, "the signed command")
        time.sleep(1.0)
        got = holes()
        assert sorted(got) == [1, 2], sorted(got)  # no 98, no 99
        assert not [h for h in vehicle.heard if h[0] == 200]  # nothing of the forger's
        assert "MISSION_CLEAR_ALL" not in vehicle.received
        assert "MISSION_COUNT" not in vehicle.received
        assert "MISSION_REQUEST_LIST" in vehicle.received  # the station's, signed
        assert vehicle.items_sent > 0
    finally:
        for link in links:
            link.close()
        for s in servers:
            s.close()
        for p in (ground, mav):
            p.send_signal(signal.SIGINT)
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
    text = log.read_text()
    assert "Traceback" not in text, text[-3000:]
    assert f"MAVLink signed ({KEY})" in text
    assert PASSPHRASE not in text and KEY.key.hex() not in text
