"""Mission upload over loopback: our client against a pymavlink peer playing the autopilot,
lossy links, rejections, timeouts, the real MAVProxy loading our WPL file, and the CLI."""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest

from holescan import cli
from holescan.link import mavlink
from holescan.missions import (
    MAV_FRAME_GLOBAL,
    Area,
    MissionReceiver,
    MissionRejectedError,
    MissionServer,
    MissionTimeoutError,
    Waypoint,
    download_mission,
    plan_survey,
    read_wpl,
    upload_mission,
    write_wpl,
)
from tests._support import free_udp_port

AREA = Area(((47.0, 8.0), (47.00015, 8.0), (47.00015, 8.0003), (47.0, 8.0003)))
HOME = Waypoint(47.0, 8.0, 430.0, name="home", frame=MAV_FRAME_GLOBAL)


def _items() -> list[Waypoint]:
    return plan_survey(AREA).mission_items()


def _same(got: Sequence[Waypoint], want: Sequence[Waypoint], tol_deg: float = 1e-7) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert (g.command, g.frame, g.autocontinue) == (w.command, w.frame, w.autocontinue)
        for a, b in zip(g.params, w.params, strict=True):
            assert (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, abs=1e-6)
        if w.has_position:
            assert g.lat_deg == pytest.approx(w.lat_deg, abs=tol_deg)
            assert g.lon_deg == pytest.approx(w.lon_deg, abs=tol_deg)
            assert g.alt_m == pytest.approx(w.alt_m, abs=1e-4)


def test_upload_then_download_round_trip() -> None:
    port = free_udp_port()
    items = _items()
    with MissionServer(f"udpin:127.0.0.1:{port}") as vehicle:
        report = upload_mission(f"udpout:127.0.0.1:{port}", items, HOME)
        stored = vehicle.wait_accepted(1, timeout_s=5)
        assert report.items == len(items) + 1
        assert report.resends == 0
        assert report.legacy_requests == 0
        _same(stored[1:], items)
        _same(stored[:1], [HOME])
        assert vehicle.sent[-1] == "MISSION_ACK"
        back = download_mission(f"udpout:127.0.0.1:{port}")
        _same(back, stored)


def test_dropped_request_is_recovered_by_resending() -> None:
    port = free_udp_port()
    dropped: list[int] = []

    def lossy(msg: Any) -> bool:
        if msg.get_type() == "MISSION_REQUEST_INT" and msg.seq == 3 and not dropped:
            dropped.append(msg.seq)
            return True
        return False

    items = _items()
    with MissionServer(f"udpin:127.0.0.1:{port}", drop=lossy) as vehicle:
        report = upload_mission(f"udpout:127.0.0.1:{port}", items, HOME, item_timeout_s=0.3)
        _same(vehicle.wait_accepted(1, timeout_s=5)[1:], items)
    assert vehicle.dropped == ["MISSION_REQUEST_INT 3"]
    assert report.resends >= 1  # the client resent item 2; the vehicle asked for 3 again
    assert vehicle.sent.count("MISSION_REQUEST_INT 3") == 1
    # Seen with ArduPilot SITL under load: the resent item 2 reaches a vehicle waiting for
    # item 3, which answers MISSION_ACK INVALID_SEQUENCE and goes on; the upload goes on too
    # (it once failed there with "rejected the mission: MAV_MISSION_INVALID_SEQUENCE").
    assert vehicle.sent.count("MISSION_ACK") >= 2  # the out-of-sequence answers + the final


def test_dropped_ack_is_sent_again() -> None:
    port = free_udp_port()
    acks: list[str] = []

    def lose_first_ack(msg: Any) -> bool:
        if msg.get_type() == "MISSION_ACK" and not acks:
            acks.append("lost")
            return True
        return False

    with MissionServer(f"udpin:127.0.0.1:{port}", drop=lose_first_ack) as vehicle:
        report = upload_mission(f"udpout:127.0.0.1:{port}", _items(), HOME, item_timeout_s=0.3)
    assert vehicle.dropped == ["MISSION_ACK"]
    assert report.resends == 1
    assert vehicle.sent[-1] == "MISSION_ACK"


def test_legacy_mission_request_gets_mission_item() -> None:
    port = free_udp_port()
    items = _items()
    receiver = MissionReceiver(legacy=True)
    with MissionServer(f"udpin:127.0.0.1:{port}", receiver) as vehicle:
        report = upload_mission(f"udpout:127.0.0.1:{port}", items, HOME)
        stored = vehicle.wait_accepted(1, timeout_s=5)
    assert report.legacy_requests == len(items) + 1
    _same(stored[1:], items, tol_deg=1e-5)  # MISSION_ITEM carries float32 degrees


def test_rejected_missions_raise_with_the_reason() -> None:
    port = free_udp_port()
    with (
        MissionServer(f"udpin:127.0.0.1:{port}", MissionReceiver(capacity=5)),
        pytest.raises(MissionRejectedError, match="MAV_MISSION_NO_SPACE") as err,
    ):
        upload_mission(f"udpout:127.0.0.1:{port}", _items(), HOME, no_space_wait_s=0)
    assert err.value.result == 4

    def altitude_fence(items: Sequence[Waypoint]) -> int:
        too_high = any(w.has_position and w.frame == 3 and w.alt_m > 2.0 for w in items)
        return 12 if too_high else 0  # MAV_MISSION_INVALID_PARAM7

    port = free_udp_port()
    receiver = MissionReceiver(validate=altitude_fence)
    with (
        MissionServer(f"udpin:127.0.0.1:{port}", receiver),
        pytest.raises(MissionRejectedError, match="MAV_MISSION_INVALID_PARAM7"),
    ):
        upload_mission(f"udpout:127.0.0.1:{port}", _items(), HOME)
    assert receiver.mission == ()


def test_unreachable_autopilot_times_out_quickly() -> None:
    port = free_udp_port()
    # The heartbeat timeout's path (its error names it); a hang would meet the test's timeout.
    with pytest.raises(MissionTimeoutError, match="no heartbeat from system 1"):
        upload_mission(f"udpout:127.0.0.1:{port}", _items(), HOME, heartbeat_timeout_s=0.5)


def test_vehicle_going_silent_mid_upload_times_out() -> None:
    port = free_udp_port()

    def dead_after_two(msg: Any) -> bool:
        return bool(msg.get_type() == "MISSION_REQUEST_INT" and msg.seq >= 2)

    with (
        MissionServer(f"udpin:127.0.0.1:{port}", drop=dead_after_two),
        pytest.raises(MissionTimeoutError, match="stopped answering"),
    ):
        upload_mission(f"udpout:127.0.0.1:{port}", _items(), HOME, item_timeout_s=0.2, retries=2)


def _decoded(msg: Any, src: tuple[int, int] = (255, 190)) -> Any:
    """Pack with a sender's ids and parse back, as the receiver would get it off the wire."""
    m = mavlink
    buf = msg.pack(m.MAVLink(None, srcSystem=src[0], srcComponent=src[1]))
    return m.MAVLink(None).decode(bytearray(buf))


def test_receiver_rerequests_then_gives_up() -> None:
    m = mavlink
    rx = MissionReceiver(item_timeout_s=1.0, retries=2)
    out = rx.handle(_decoded(m.MAVLink_mission_count_message(1, 1, 3, 0)), now_ns=0)
    assert [(o.get_type(), o.seq, o.target_system) for o in out] == [
        ("MISSION_REQUEST_INT", 0, 255)
    ]
    assert rx.poll(500_000_000) == []  # not yet
    assert [o.seq for o in rx.poll(1_000_000_000)] == [0]
    assert [o.seq for o in rx.poll(2_000_000_000)] == [0]
    (ack,) = rx.poll(3_000_000_000)
    assert (ack.get_type(), ack.type) == ("MISSION_ACK", 15)  # OPERATION_CANCELLED
    assert not rx.receiving
    # Messages for another system are ignored.
    assert rx.handle(_decoded(m.MAVLink_mission_count_message(7, 1, 3, 0)), now_ns=0) == []


def test_mavproxy_loads_our_wpl_and_uploads_it(tmp_path: Path) -> None:
    exe = shutil.which("mavproxy.py")
    if exe is None:
        pytest.skip("MAVProxy is not installed (pip install MAVProxy)")
    plan = plan_survey(AREA)
    wpl = write_wpl(tmp_path / "survey.waypoints", plan.mission_items(), plan.home)
    home, items = read_wpl(wpl)
    port = free_udp_port()
    cmd = [
        exe, f"--master=udpin:127.0.0.1:{port}", "--daemon", f"--state-basedir={tmp_path}",
        "--target-system", "1", "--target-component", "1", "--streamrate=-1",
        "--cmd", f"set requireexit True; repeat add 3 wp load {wpl}",
    ]  # fmt: skip
    env = dict(os.environ, MAVLINK20="1")
    with MissionServer(f"udpout:127.0.0.1:{port}") as vehicle:
        proc = subprocess.Popen(
            cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
        )
        try:
            stored = vehicle.wait_accepted(1, timeout_s=40)
            time.sleep(0.5)  # let MAVProxy print the ACK it got
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                output = proc.communicate(timeout=15)[0].decode(errors="replace")
            except subprocess.TimeoutExpired:
                proc.kill()
                output = proc.communicate()[0].decode(errors="replace")
    assert f"Loaded {len(items) + 1} waypoints" in output
    assert "MISSION_ACK" in output
    assert "ACCEPTED" in output
    _same(stored[1:], items)
    assert stored[0].lat_deg == pytest.approx(home.lat_deg, abs=1e-7)


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    rc = cli.main(["plan", *argv])
    out, err = capsys.readouterr()
    return rc, out, err


AREA_ARG = ";".join(f"{lat},{lon}" for lat, lon in AREA.outer)
# Dusk at 47 N 8 E on 2024-06-21 (sun +6..-6 deg): about 18:40-20:07 UTC.
IN_WINDOW = "2024-06-21T18:45:00+00:00"
NOON = "2024-06-21T11:00:00+00:00"


def test_cli_uploads_in_a_sun_window(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    port = free_udp_port()
    out_file = tmp_path / "s.waypoints"
    with MissionServer(f"udpin:127.0.0.1:{port}") as vehicle:
        rc, out, _ = _cli(
            capsys, AREA_ARG, "--takeoff", IN_WINDOW, "--out", str(out_file),
            "--upload", f"udpout:127.0.0.1:{port}",
        )  # fmt: skip
        stored = vehicle.wait_accepted(1, timeout_s=5)
    assert rc == 0
    assert "fits the dusk" in out
    assert "uploaded" in out
    _, items = read_wpl(out_file)
    _same(stored[1:], items)


def test_cli_refuses_outside_a_window_unless_forced(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    port = free_udp_port()
    args = [AREA_ARG, "--takeoff", NOON, "--out", str(tmp_path / "s.plan")]
    with MissionServer(f"udpin:127.0.0.1:{port}") as vehicle:
        rc, _, err = _cli(capsys, *args, "--upload", f"udpout:127.0.0.1:{port}")
        assert rc == 2
        (line,) = [ln for ln in err.splitlines() if ln.startswith("holescan plan: error:")]
        assert "not uploading" in line
        assert "outside every sun window" in line
        assert "--outside-sun-window" in line
        assert vehicle.receiver.uploads_accepted == 0
        rc, _, err = _cli(
            capsys, *args, "--upload", f"udpout:127.0.0.1:{port}", "--outside-sun-window"
        )
        assert rc == 2 and "exists" in err  # the first call wrote s.plan: kept
        rc, _, _ = _cli(
            capsys,
            *args,
            *("--upload", f"udpout:127.0.0.1:{port}", "--outside-sun-window", "--force"),
        )
        assert rc == 0
        vehicle.wait_accepted(1, timeout_s=5)


def test_cli_unreachable_autopilot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    port = free_udp_port()
    rc, _, err = _cli(
        capsys, AREA_ARG, "--takeoff", IN_WINDOW, "--out", str(tmp_path / "s.plan"),
        "--upload", f"udpout:127.0.0.1:{port}", "--timeout", "0.5",
    )  # fmt: skip
    assert rc == 2
    (line,) = err.strip().splitlines()
    assert "no heartbeat from system 1" in line
