"""Signing cannot be turned against the crew: a burst of badly signed packets with the
largest timestamp, one per link id and component, changes nothing for genuine ones.

pymavlink 2.4.50 stores a stream's timestamp before it checks the signature; our one door
(:func:`link.open_link` with a :class:`link.SigningKey`) checks the signature
first. Real pymavlink peers over loopback UDP.
"""

from __future__ import annotations

import socket
import time
from typing import Any

from holescan.link import MavConnection, SigningKey, mavlink, open_link, verified_signature

SYSID = 1
KEY = SigningKey.from_passphrase("rubble-sortie-7")
WRONG = SigningKey.from_passphrase("not-the-key")
TS_MAX = 2**48 - 1
COMPONENTS = (mavlink.MAV_COMP_ID_AUTOPILOT1, mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def forged_burst() -> list[bytes]:
    """512 HEARTBEATs signed with the wrong key at timestamp 2**48 - 1: every link id
    (0..255) of the vehicle's autopilot and of its companion computer (~20 KiB)."""
    out = []
    for comp in COMPONENTS:
        mav = mavlink.MAVLink(None, srcSystem=SYSID, srcComponent=comp)
        mav.signing.secret_key = WRONG.key
        mav.signing.sign_outgoing = True
        for link_id in range(256):
            mav.signing.link_id = link_id
            mav.signing.timestamp = TS_MAX
            msg = mavlink.MAVLink_heartbeat_message(
                mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4, 3
            )
            out.append(bytes(msg.pack(mav)))
    return out


def heartbeats(conn: MavConnection, timeout_s: float) -> list[Any]:
    got: list[Any] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.1)
        if msg is not None:
            got.append(msg)
    return got


def test_signature_is_checked_before_the_timestamp_is_kept() -> None:
    """The check itself: a badly signed packet at 2**48 - 1 leaves the stream untouched,
    a genuine one then passes, and replaying that genuine one is refused."""
    rx = mavlink.MAVLink(None)
    rx.signing.secret_key = KEY.key
    rx.signing.timestamp = 10**12
    forged = bytearray(forged_burst()[0])
    assert not verified_signature(rx, forged, SYSID, COMPONENTS[0])
    assert rx.signing.stream_timestamps == {}
    tx = mavlink.MAVLink(None, srcSystem=SYSID, srcComponent=COMPONENTS[0])
    tx.signing.secret_key, tx.signing.sign_outgoing = KEY.key, True
    tx.signing.timestamp, tx.signing.link_id = 10**12 + 5, 0
    good = bytearray(
        mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(tx)  # a GCS heartbeat
    )
    assert verified_signature(rx, good, SYSID, COMPONENTS[0])
    assert rx.signing.stream_timestamps == {(0, SYSID, COMPONENTS[0]): 10**12 + 5}
    assert not verified_signature(rx, good, SYSID, COMPONENTS[0])  # replayed


def test_a_forged_burst_does_not_silence_the_signed_vehicle() -> None:
    """512 badly signed HEARTBEATs at 2**48 - 1 straight at a signed receiver (as the
    station's link opens it), then the vehicle's correctly signed HEARTBEATs from both
    components: every one arrives (pymavlink's own check refused them all)."""
    port = free_udp_port()
    rx = open_link(
        f"udpin:127.0.0.1:{port}",
        source_system=254,
        source_component=mavlink.MAV_COMP_ID_MISSIONPLANNER,
        signing=KEY,
    )
    senders = [
        open_link(
            f"udpout:127.0.0.1:{port}", source_system=SYSID, source_component=comp, signing=KEY
        )
        for comp in COMPONENTS
    ]
    forger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        passed = []
        for i, pkt in enumerate(forged_burst()):
            forger.sendto(pkt, ("127.0.0.1", port))
            if i % 32 == 31:  # read as it comes: each one must reach the check
                passed += heartbeats(rx, 0.05)
        passed += heartbeats(rx, 0.5)
        assert passed == []  # nothing of the burst got through
        for _ in range(5):
            for s in senders:
                s.mav.heartbeat_send(
                    mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4, 3
                )
            time.sleep(0.02)
        got = heartbeats(rx, 1.0)
        assert sorted({m.get_srcComponent() for m in got}) == sorted(COMPONENTS)
        assert len(got) == 10
        assert all(m.get_signed() for m in got)
    finally:
        forger.close()
        for s in senders:
            s.close()
        rx.close()
