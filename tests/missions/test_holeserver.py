"""The live hole mission server against the real MAVProxy and a pymavlink ground station."""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from holescan.geotag import Hole
from holescan.missions._holeserver import (
    HoleMissionServer,
    MissionServerError,
    hole_statustext,
    hole_waypoints,
)

os.environ.setdefault("MAVLINK20", "1")
from holescan.link import mavutil
from tests._support import free_udp_port

SYSID = 1


def hole(
    hid: int, score: float, lat: float, lon: float, sightings: int = 3, p_hole: float = 0.97
) -> Hole:
    return Hole(
        hid, lat, lon, 31.0, 1.5, score, sightings, 10**9, 2 * 10**9, 7, (1, 2, 3, 4), 0.7, 0.4,
        p_hole=p_hole,
    )  # fmt: skip


HOLES = [
    hole(1, 0.55, 45.12345671, 7.65432109),
    hole(2, 0.91, 45.12347013, 7.65430877),
    hole(3, 0.73, -45.00000049, -170.98765432),
    hole(4, 0.73, 45.12346388, 7.65433512, sightings=9),
]
ORDER = [2, 4, 3, 1]  # best score first, then more sightings


def recv(conn: Any, kind: str, timeout: float = 5.0) -> Any:
    msg = conn.recv_match(type=kind, blocking=True, timeout=timeout)
    if msg is None:
        raise TimeoutError(f"no {kind} within {timeout} s")
    return msg


def test_hole_waypoints_home_first_then_by_confidence() -> None:
    items = hole_waypoints(HOLES, home=(45.1, 7.6, 25.0), rel_alt_m=10.0, clearance_m=8.0)
    home = items[0]
    assert (home.lat_deg, home.lon_deg, home.alt_m, home.frame, home.command) == (
        45.1,
        7.6,
        25.0,
        0,
        16,
    )
    assert [w.properties["hole_id"] for w in items[1:]] == ORDER
    assert len(items) == 5
    assert {(w.frame, w.command) for w in items[1:]} == {(3, 16)}
    # Holes at 31 m MSL, home at 25 m: 6 m + 8 m clearance = 14 m above home.
    assert {w.alt_m for w in items[1:]} == {14.0}
    by_id = {h.id: h for h in HOLES}
    for w in items[1:]:  # full precision in the record; degE7 only on the wire
        h = by_id[w.properties["hole_id"]]
        assert (w.lat_deg, w.lon_deg) == (h.lat_deg, h.lon_deg)
    unknown_home = hole_waypoints(HOLES[:1])
    assert (unknown_home[0].lat_deg, unknown_home[0].lon_deg, unknown_home[1].alt_m) == (
        0.0,
        0.0,
        10.0,
    )


def test_statustext_says_p_hole_and_fits_fifty_characters() -> None:
    # the hole-level p_hole, named "p", never the best frame's detector score (0.91 here)
    assert hole_statustext(HOLES[1]) == "HOLE 2 p0.97 45.1234701 7.6543088"
    worst = hole(123456789, 1.0, -89.12345678, -179.12345678, p_hole=1.0)
    assert hole_statustext(worst, "review") == "REVIEW 123456789 p1.00 -89.1234568 -179.1234568"
    assert len(hole_statustext(worst, "review")) <= 50
    exactly = hole_statustext(hole(10**13, 0.5, -89.12345678, -179.12345678, p_hole=0.5))
    assert exactly == f"HOLE {10**13} p0.50 -89.1234568 -179.1234568"
    assert len(exactly) == 50
    # Only absurd ids lose decimals.
    assert hole_statustext(hole(10**15, 0.5, -89.12345678, -179.12345678, p_hole=0.5)) == (
        f"HOLE {10**15} p0.50 -89.123457 -179.123457"
    )


@pytest.fixture
def served() -> Iterator[tuple[HoleMissionServer, Any]]:
    """Our server (udpout) and a pymavlink ground station (udpin) on loopback."""
    port = free_udp_port()
    gcs = mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
    )
    try:
        with HoleMissionServer(f"udpout:127.0.0.1:{port}", SYSID, heartbeat_period_s=0.2) as srv:
            srv.update_holes(HOLES)
            hb = recv(gcs, "HEARTBEAT")
            assert (hb.get_srcSystem(), hb.get_srcComponent()) == (SYSID, 191)
            assert hb.type == mavutil.mavlink.MAV_TYPE_ONBOARD_CONTROLLER
            yield srv, gcs
    finally:
        gcs.close()


def test_out_of_order_repeated_and_legacy_requests(served: tuple[HoleMissionServer, Any]) -> None:
    srv, gcs = served
    gcs.mav.mission_request_list_send(SYSID, 191)
    count = recv(gcs, "MISSION_COUNT")
    assert (count.count, count.target_system, count.target_component) == (5, 255, 190)
    by_id = {h.id: h for h in HOLES}
    for seq in (3, 1, 1, 4, 0, 2, 3):
        gcs.mav.mission_request_int_send(SYSID, 191, seq)
        item = recv(gcs, "MISSION_ITEM_INT")
        assert item.seq == seq
        if seq == 0:
            assert (item.frame, item.x, item.y) == (0, 0, 0)
            continue
        h = by_id[ORDER[seq - 1]]
        assert (item.frame, item.command, item.autocontinue) == (3, 16, 1)
        assert item.x == round(h.lat_deg * 1e7)
        assert item.y == round(h.lon_deg * 1e7)
        assert abs(item.x * 1e-7 - h.lat_deg) <= 5.01e-8  # degE7: 1e-7 deg
        assert item.z == pytest.approx(10.0)
    # Deprecated MISSION_REQUEST gets MISSION_ITEM (float32 degrees).
    for seq in (2, 2):
        gcs.mav.mission_request_send(SYSID, 191, seq)
        item = recv(gcs, "MISSION_ITEM")
        h = by_id[ORDER[seq - 1]]
        assert item.seq == seq
        assert item.x == pytest.approx(float(np.float32(h.lat_deg)), abs=1e-12)
        assert item.y == pytest.approx(float(np.float32(h.lon_deg)), abs=1e-12)
    # Out of range: refused, not ignored.
    gcs.mav.mission_request_int_send(SYSID, 191, 5)
    ack = recv(gcs, "MISSION_ACK")
    assert ack.type == mavutil.mavlink.MAV_MISSION_INVALID_SEQUENCE
    assert srv.items_sent == 9


def test_download_is_a_consistent_snapshot(served: tuple[HoleMissionServer, Any]) -> None:
    srv, gcs = served
    gcs.mav.mission_request_list_send(SYSID, 191)
    assert recv(gcs, "MISSION_COUNT").count == 5
    srv.update_holes([hole(9, 0.99, 10.0, 20.0)])  # changes while the GCS downloads
    gcs.mav.mission_request_int_send(SYSID, 191, 1)
    assert recv(gcs, "MISSION_ITEM_INT").x == round(HOLES[1].lat_deg * 1e7)  # old list
    gcs.mav.mission_request_list_send(SYSID, 191)
    assert recv(gcs, "MISSION_COUNT").count == 2
    gcs.mav.mission_request_int_send(SYSID, 191, 1)
    assert recv(gcs, "MISSION_ITEM_INT").x == 100_000_000


def test_answers_only_its_own_component_and_refuses_uploads(
    served: tuple[HoleMissionServer, Any],
) -> None:
    _, gcs = served
    gcs.mav.mission_request_list_send(SYSID, 0)  # broadcast: the autopilot's business
    gcs.mav.mission_request_list_send(SYSID, 1)  # the autopilot
    gcs.mav.mission_request_list_send(SYSID + 1, 191)  # another vehicle
    assert gcs.recv_match(type="MISSION_COUNT", blocking=True, timeout=0.6) is None
    gcs.mav.mission_count_send(SYSID, 191, 3)  # upload attempt
    assert recv(gcs, "MISSION_ACK").type == mavutil.mavlink.MAV_MISSION_DENIED
    gcs.mav.mission_request_list_send(SYSID, 191, mavutil.mavlink.MAV_MISSION_TYPE_FENCE)
    fence = recv(gcs, "MISSION_COUNT")
    assert (fence.count, fence.mission_type) == (0, mavutil.mavlink.MAV_MISSION_TYPE_FENCE)


def test_statustext_announces_hole(served: tuple[HoleMissionServer, Any]) -> None:
    srv, gcs = served
    sent = srv.announce(HOLES[2])
    msg = recv(gcs, "STATUSTEXT")
    assert msg.text == sent == "HOLE 3 p0.97 -45.0000005 -170.9876543"
    assert msg.severity == mavutil.mavlink.MAV_SEVERITY_NOTICE
    assert (msg.get_srcSystem(), msg.get_srcComponent()) == (SYSID, 191)


def test_announce_needs_a_running_server() -> None:
    srv = HoleMissionServer("udpout:127.0.0.1:9", SYSID)
    with pytest.raises(MissionServerError):
        srv.announce(HOLES[0])


def _items_in_tlog(path: Path) -> dict[int, tuple[int, int]]:
    """``MISSION_ITEM_INT`` (x, y) by sequence number in a MAVProxy telemetry log."""
    if not path.exists():
        return {}
    tlog = mavutil.mavlink_connection(str(path))
    got = {}
    while (m := tlog.recv_match(type="MISSION_ITEM_INT")) is not None:
        got[m.seq] = (m.x, m.y)
    tlog.close()
    return got


def _read_wpl(path: Path) -> list[list[str]]:
    lines = path.read_text().splitlines()
    assert lines[0] == "QGC WPL 110"
    return [line.split("\t") for line in lines[1:]]


@pytest.mark.parametrize("use_int", [True, False], ids=["mission_int", "legacy"])
def test_mavproxy_downloads_and_saves_hole_waypoints(tmp_path: Path, use_int: bool) -> None:
    """The real MAVProxy, headless, as ground station: ``wp save`` writes our holes."""
    mavproxy = shutil.which("mavproxy.py")
    if mavproxy is None:
        pytest.skip("MAVProxy is not installed (pip install MAVProxy: a test dependency)")
    port = free_udp_port()
    out = tmp_path / "holes.txt"
    setting = "" if use_int else "set wp_use_mission_int 0; "
    cmd = [
        mavproxy,
        f"--master=udpin:127.0.0.1:{port}",
        "--daemon",
        f"--state-basedir={tmp_path}",
        "--target-system",
        str(SYSID),
        "--target-component",
        "191",
        "--cmd",
        f"set requireexit True; {setting}repeat add 1 wp save {out}",
    ]
    proc = subprocess.Popen(
        cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    try:
        with HoleMissionServer(f"udpout:127.0.0.1:{port}", SYSID) as srv:
            srv.update_holes(HOLES)
            deadline = time.monotonic() + 40.0
            while time.monotonic() < deadline and proc.poll() is None:
                # MAVProxy's telemetry log is written by a thread of its own: on a loaded
                # machine the waypoint file is complete before the log holds the items.
                saved = out.exists() and len(out.read_text().splitlines()) == 6
                if saved and (not use_int or len(_items_in_tlog(tmp_path / "mav.tlog")) == 5):
                    break
                time.sleep(0.2)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            log, _ = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            log, _ = proc.communicate()
    assert out.exists(), f"MAVProxy saved nothing; its output:\n{log[-2000:]}"
    rows = _read_wpl(out)
    assert [int(r[0]) for r in rows] == [0, 1, 2, 3, 4]
    assert rows[0][2:4] == ["0", "16"]
    assert float(rows[0][8]) == 0.0  # home: unknown
    by_id = {h.id: h for h in HOLES}
    for row, hid in zip(rows[1:], ORDER, strict=True):
        h = by_id[hid]
        assert (row[2], row[3], row[11]) == ("3", "16", "1")
        # MAVProxy writes degrees with "%f" (6 decimals) from what it received.
        if use_int:
            lat, lon = round(h.lat_deg * 1e7) * 1e-7, round(h.lon_deg * 1e7) * 1e-7
        else:
            lat, lon = float(np.float32(h.lat_deg)), float(np.float32(h.lon_deg))
        assert (row[8], row[9]) == (f"{lat:f}", f"{lon:f}")
        tol = 5.01e-7 if use_int else 5.01e-7 + 8e-6  # float32 at |lon| 171: 7.6e-6 deg
        assert math.isclose(float(row[8]), h.lat_deg, abs_tol=tol)
        assert math.isclose(float(row[9]), h.lon_deg, abs_tol=tol)
        assert float(row[10]) == pytest.approx(10.0)
    if use_int:  # MAVProxy's own telemetry log holds the items at full 1e-7 precision
        got = _items_in_tlog(tmp_path / "mav.tlog")
        for seq, hid in enumerate(ORDER, start=1):
            h = by_id[hid]
            x, y = got[seq]
            assert abs(x * 1e-7 - h.lat_deg) <= 5.01e-8
            assert abs(y * 1e-7 - h.lon_deg) <= 5.01e-8
