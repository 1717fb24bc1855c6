"""Issue 20: the real topology, one link. With ``--mavlink`` only (no ``--gcs``) the
announcements, the hole mission and the cards go out on the companion's link to the
autopilot (which routes them to the GCS on its other port: ArduPilot SITL shows it, see
``benchmarks/sitl_sortie.py``); a SiK radio's RADIO_STATUS on the way sets the cards'
byte budget."""

from __future__ import annotations

from pathlib import Path

import pytest

from holescan.capture import FlyConfig, FlyReport, SensorSetup, fly, parse_fly_config
from holescan.link import SigningKey
from holescan.missions import radio_budget
from holescan.sim import SimAutopilot
from tests._support import free_udp_port
from tests.capture.test_daemon import CAM, ScriptedSource, hover_path


def _scripted_flight(tmp_path: Path, port: int, **top: object) -> tuple[FlyConfig, SensorSetup]:
    """150 scripted frames over the autopilot on ``port``, announcing after 3 sightings
    over 0.5 s; ``top``: more top-level fly.toml keys."""
    holes = {"announce_min_sightings": 3, "announce_min_span_s": 0.5, "announce_min_p_hole": 0.0}
    cfg = parse_fly_config(
        {**top, "holes": holes},
        {"log_dir": tmp_path, "mavlink": f"udpin:127.0.0.1:{port}", "max_frames": 150},
    )
    return cfg, SensorSetup(lambda: ScriptedSource(200), CAM, cfg.mavlink)


def test_radio_budget_follows_the_radio_buffer() -> None:
    assert radio_budget(1000.0, 1000.0, 10) == 500.0  # overrun: halve
    assert radio_budget(1000.0, 1000.0, 40) == 800.0
    assert radio_budget(800.0, 1000.0, 70) == 800.0  # comfortable: keep
    assert radio_budget(800.0, 1000.0, 95) == pytest.approx(880.0)
    assert radio_budget(990.0, 1000.0, 100) == 1000.0  # never above the configured budget
    b = 1000.0
    for _ in range(20):
        b = radio_budget(b, 1000.0, 5)
    assert b == 50.0  # a card still gets through, slowly


def _fly_one_link(tmp_path: Path, txbuf: int | None) -> tuple[FlyReport, dict[str, int]]:
    port = free_udp_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path()) as ap:
        ap.radio_txbuf = txbuf
        cfg, setup = _scripted_flight(tmp_path, port)
        report = fly(cfg, setup)
        received = dict(ap.received)
    return report, received


def test_holes_go_out_on_the_autopilot_link_without_gcs(tmp_path: Path) -> None:
    report, received = _fly_one_link(tmp_path, None)
    assert report.announced, report
    assert received.get("STATUSTEXT", 0) >= len(report.announced)
    assert received.get("DATA_TRANSMISSION_HANDSHAKE", 0) >= 1  # the card: on the same link
    assert received.get("ENCAPSULATED_DATA", 0) >= 1
    assert report.cards_sent >= 1
    # One companion on the link: its heartbeats (ONBOARD_CONTROLLER, the vehicle's id)
    # come from the telemetry alone, the mission server sends none of its own.
    assert received.get("HEARTBEAT", 0) <= report.summary.duration_s + 3


@pytest.mark.slow
def test_a_full_radio_buffer_slows_the_cards(tmp_path: Path) -> None:
    report, _ = _fly_one_link(tmp_path, 5)  # the SiK radio is overrun
    assert report.announced
    # At the 50 B/s floor a 2-3 kB card does not get through in the flight's seconds
    # (plus the 10 s flush); at the configured 1000 B/s it does (test above).
    assert report.cards_sent == 0, report
    assert 0 < report.card_bytes < 2500


def test_companion_heartbeat_is_not_a_second_vehicle() -> None:
    """A GCS behind the autopilot sees the companion's heartbeat (the vehicle's system id,
    component 191) and must not take it for a vehicle: pymavlink's (and so MAVProxy's)
    vehicle test says no; the shared-link mission server sends no heartbeat of its own."""
    import threading
    import time
    from typing import Any

    from holescan.capture import Telemetry
    from holescan.link import mavutil
    from holescan.missions import HoleMissionServer

    port = free_udp_port()
    ap = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1)
    stop = threading.Event()
    beats: list[Any] = []

    def autopilot() -> None:  # a quadrotor running ArduPilot, listening
        while not stop.is_set():
            ap.mav.heartbeat_send(2, 3, 0, 0, 4)
            msg = ap.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
            if msg is not None:
                beats.append(msg)

    thread = threading.Thread(target=autopilot, daemon=True)
    thread.start()
    with (
        Telemetry(f"udpin:127.0.0.1:{port}", rates_hz={}, timesync_hz=0) as tel,
        HoleMissionServer(None, 1, sender=tel.send_with),
    ):
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and len(beats) < 4:
            time.sleep(0.1)
    stop.set()
    thread.join(2.0)
    ap.close()
    assert len(beats) >= 2, beats
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in beats} == {(1, 191)}
    assert not any(ap.probably_vehicle_heartbeat(m) for m in beats)


def test_no_heartbeat_of_an_unknown_system_before_the_autopilot_is_heard() -> None:
    """ArduPilot SITL showed MAVProxy a vehicle 255:191: the companion's heartbeats on its
    TCP link before the autopilot's first heartbeat, when our system id is not known. The
    autopilot here (a TCP server) waits 2 s before its first heartbeat."""
    import socket
    import threading
    import time
    from typing import Any

    from holescan.capture import Telemetry
    from holescan.link import mavutil

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ap = mavutil.mavlink_connection(f"tcpin:127.0.0.1:{port}", source_system=1)
    seen: list[Any] = []
    stop = threading.Event()

    def autopilot() -> None:
        t0 = time.monotonic()
        while not stop.is_set():
            if time.monotonic() - t0 > 2.0:
                ap.mav.heartbeat_send(2, 3, 0, 0, 4)
            msg = ap.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
            if msg is not None:
                seen.append(msg)

    thread = threading.Thread(target=autopilot, daemon=True)
    thread.start()
    with Telemetry(f"tcp:127.0.0.1:{port}", rates_hz={}, timesync_hz=0):
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and len(seen) < 2:
            time.sleep(0.1)
    stop.set()
    thread.join(2.0)
    ap.close()
    assert len(seen) >= 2, seen
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in seen} == {(1, 191)}


def test_shared_link_is_signed_with_the_fly_key(tmp_path: Path) -> None:
    """Without --gcs the holes share the autopilot link: with ``mavlink_key`` configured
    that link is signed (an autopilot holding the key takes the announcements and cards),
    and an unsigned request injected on it is never answered."""
    import os
    import threading
    import time

    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import mavutil

    key = SigningKey.from_passphrase("rubble-sortie-7")
    port = free_udp_port()
    answers: list[str] = []
    done = threading.Event()
    sent = [0]

    def spoofer() -> None:  # an unsigned peer on the companion's port
        peer = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=255, source_component=190
        )
        try:
            while not done.is_set():
                peer.mav.mission_request_list_send(1, 191, mavutil.mavlink.MAV_MISSION_TYPE_MISSION)
                sent[0] += 1
                t_end = time.monotonic() + 0.3
                while time.monotonic() < t_end:
                    m = peer.recv_match(blocking=True, timeout=0.05)
                    if m is not None and m.get_type() == "MISSION_COUNT":
                        answers.append(m.get_type())
        finally:
            peer.close()

    with SimAutopilot(f"udpout:127.0.0.1:{port}", hover_path(), signing_key=key.key) as ap:
        cfg, setup = _scripted_flight(tmp_path, port, mavlink_key=key.key.hex())
        spoof = threading.Thread(target=spoofer, daemon=True)
        threading.Timer(2.0, spoof.start).start()
        report = fly(cfg, setup)
        done.set()
        spoof.join(5)
        signed, received = dict(ap.received_signed), dict(ap.received)
    assert report.announced, report
    # the autopilot drops unsigned packets: everything it took was signed with the key
    assert signed.get("STATUSTEXT", 0) >= len(report.announced)
    assert signed.get("ENCAPSULATED_DATA", 0) >= 1
    assert signed == received
    assert sent[0] >= 3 and answers == []  # the injected unsigned requests: ignored
    assert report.summary.telemetry["bad_packets"] >= 3  # dropped: bad signature (some sent
    # after the link closed are not counted)
