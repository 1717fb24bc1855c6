"""MAVLink 2 signing of the hole server's link: signed requests are answered; unsigned,
wrongly signed and replayed ones are ignored (real pymavlink peers over loopback)."""

from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Any

import pytest

from holescan.capture import parse_fly_config
from holescan.errors import InputError
from holescan.geotag import Hole
from holescan.link import SigningKey, open_link
from holescan.missions import HoleMissionServer
from tests._support import free_udp_port

SYSID = 1
KEY = SigningKey.from_passphrase("rubble-sortie-7")
HOLES = [
    Hole(1, 45.1234567, 7.6543210, 31.0, 0.4, 0.9, 5, 10**9, 2 * 10**9, 7, (1, 2, 3, 4), 0.7, 0.4)
]


def test_keys_from_hex_passphrase_and_file(tmp_path: Path) -> None:
    import hashlib

    assert KEY.key == hashlib.sha256(b"rubble-sortie-7").digest()  # MAVProxy's derivation
    assert SigningKey.from_hex(KEY.key.hex().upper()) == KEY
    f = tmp_path / "k"
    f.write_text("rubble-sortie-7\n")
    assert SigningKey.from_file(f) == KEY
    f.write_text(KEY.key.hex() + "\n")
    assert SigningKey.from_file(f) == KEY
    assert KEY.key.hex() not in repr(KEY) and "rubble" not in str(KEY)
    for bad in ("abc", "zz" * 32, KEY.key.hex()[:-2]):
        with pytest.raises(InputError, match="64 hex digits"):
            SigningKey.from_hex(bad)
    for text in ("", "two\nlines\n"):
        f.write_text(text)
        with pytest.raises(InputError, match="one line"):
            SigningKey.from_file(f)
    with pytest.raises(InputError, match="cannot read"):
        SigningKey.from_file(tmp_path / "missing")


def test_fly_toml_key_is_used_and_never_recorded(tmp_path: Path) -> None:
    f = tmp_path / "mavlink.key"
    f.write_text("rubble-sortie-7\n")
    cfg = parse_fly_config({"log_dir": str(tmp_path), "mavlink_key_file": str(f)})
    assert cfg.signing == KEY
    cfg = parse_fly_config({"log_dir": str(tmp_path), "mavlink_key": KEY.key.hex()})
    assert cfg.signing == KEY
    text = repr(cfg) + repr(cfg.record) + repr(cfg.flight_config().config_record)
    assert KEY.key.hex() not in text and "rubble" not in text and KEY.fingerprint in text
    assert parse_fly_config({"log_dir": str(tmp_path)}).signing is None
    with pytest.raises(InputError, match="not both"):
        parse_fly_config(
            {"log_dir": str(tmp_path), "mavlink_key": KEY.key.hex(), "mavlink_key_file": str(f)}
        )
    with pytest.raises(InputError, match=r"cfg\.toml: a MAVLink signing key"):
        parse_fly_config({"log_dir": str(tmp_path), "mavlink_key": "00"}, where="cfg.toml")


def _counts(server: HoleMissionServer) -> dict[str, int]:
    out: dict[str, int] = {}
    for t in server.received:
        out[t] = out.get(t, 0) + 1
    return out


def test_the_hole_server_answers_only_signed_requests() -> None:
    port = free_udp_port()
    with HoleMissionServer(
        f"udpin:127.0.0.1:{port}", SYSID, heartbeat_period_s=0.2, signing=KEY
    ) as server:
        server.update_holes(HOLES)
        peers: dict[str, Any] = {
            "unsigned": open_link(
                f"udpout:127.0.0.1:{port}", source_system=200, source_component=190
            ),
            "wrong key": open_link(
                f"udpout:127.0.0.1:{port}",
                source_system=201,
                source_component=190,
                signing=SigningKey.from_passphrase("not-the-key"),
            ),
            "signed": open_link(
                f"udpout:127.0.0.1:{port}", source_system=255, source_component=190, signing=KEY
            ),
        }
        try:
            # the forgers: a mission download, "send every card again", a command
            for name in ("unsigned", "wrong key"):
                mav = peers[name].mav
                mav.heartbeat_send(6, 8, 0, 0, 4)
                mav.mission_request_list_send(SYSID, 191)
                mav.data_transmission_handshake_send(0, 0, 0, 0, 0, 0, 0)
                mav.command_long_send(SYSID, 191, 246, 0, 1, 0, 0, 0, 0, 0, 0)  # reboot
            # none of them is answered (only the server's heartbeats come back)
            t0 = time.monotonic()
            while time.monotonic() - t0 < 1.5:
                for name in ("unsigned", "wrong key"):
                    m = peers[name].recv_match(blocking=True, timeout=0.1)
                    assert m is None or m.get_type() in ("HEARTBEAT", "BAD_DATA"), (name, m)
            # the ground station: signed, answered
            good = peers["signed"]
            good.mav.heartbeat_send(6, 8, 0, 0, 4)
            msg = good.mav.mission_request_list_encode(SYSID, 191)
            signed_bytes = bytes(msg.pack(good.mav))
            good.write(signed_bytes)
            count = good.recv_match(type="MISSION_COUNT", blocking=True, timeout=10)
            assert count is not None and count.count == 2  # home + hole 1
            assert count._signed  # the server signs what it sends
            # a replay of the signed request from elsewhere: same stream, old timestamp
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.sendto(signed_bytes, ("127.0.0.1", port))
            good.mav.mission_request_int_send(SYSID, 191, 1)
            item = good.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=10)
            assert item is not None and item.seq == 1
            time.sleep(0.3)  # the server's turn after the last datagram (order is kept)
            got = _counts(server)
            assert got.get("MISSION_REQUEST_LIST") == 1, got  # the signed one, not the replay
            assert "DATA_TRANSMISSION_HANDSHAKE" not in got and "COMMAND_LONG" not in got
            assert got.get("HEARTBEAT") == 1 and got.get("MISSION_REQUEST_INT") == 1
        finally:
            for p in peers.values():
                p.close()
