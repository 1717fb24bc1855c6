"""The hole mission server is read-only to the ground: the real MAVProxy's ``wp load`` (an
upload) and ``wp clear`` aimed at component 191 change nothing. Written against the public
behaviour only (what a ground station downloads before and after)."""

from __future__ import annotations

import logging
import os
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from holescan.geotag import Hole
from holescan.link import open_link
from holescan.missions import HoleMissionServer
from tests._support import free_udp_port

SYSID = 1
_REST = (10**9, 2 * 10**9, 7, (1, 2, 3, 4), 0.7, 0.4)
HOLES = [
    Hole(1, 45.12345671, 7.65432109, 31.0, 1.5, 0.55, 3, *_REST),
    Hole(2, 45.12347013, 7.65430877, 31.0, 1.5, 0.91, 5, *_REST),
]


def download(port: int) -> list[tuple[int, int]]:
    """The served mission as a ground station sees it: (lat degE7, lon degE7) per item."""
    gcs = open_link(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190)
    try:
        deadline = time.monotonic() + 60  # a hang guard (an answer takes ms)
        count = None
        while count is None and time.monotonic() < deadline:
            gcs.mav.mission_request_list_send(SYSID, 191)
            msg = gcs.recv_match(type="MISSION_COUNT", blocking=True, timeout=0.5)
            count = None if msg is None else msg.count
        assert count is not None, "the hole server did not answer"
        items = []
        for seq in range(count):
            gcs.mav.mission_request_int_send(SYSID, 191, seq)
            item: Any = gcs.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=20)
            assert item is not None and item.seq == seq
            items.append((item.x, item.y))
        return items
    finally:
        gcs.close()


@pytest.mark.slow
def test_mavproxy_upload_and_clear_leave_the_holes_unchanged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    mavproxy = shutil.which("mavproxy.py")
    if mavproxy is None:
        pytest.skip("MAVProxy is not installed (pip install MAVProxy: a test dependency)")
    attack = tmp_path / "attack.txt"
    attack.write_text(
        "QGC WPL 110\n"
        "0\t1\t0\t16\t0\t0\t0\t0\t10.0\t10.0\t0\t1\n"
        "1\t0\t3\t16\t0\t0\t0\t0\t10.001\t10.001\t20\t1\n"
        "2\t0\t3\t21\t0\t0\t0\t0\t10.002\t10.002\t0\t1\n"
    )
    caplog.set_level(logging.INFO)
    port = free_udp_port()
    with HoleMissionServer(f"udpout:127.0.0.1:{port}", SYSID) as srv:
        srv.update_holes(HOLES)
        before = download(port)
        assert len(before) == 1 + len(HOLES)
        proc = subprocess.Popen(
            [
                mavproxy, f"--master=udpin:127.0.0.1:{port}", "--daemon",
                f"--state-basedir={tmp_path}", "--target-system", str(SYSID),
                "--target-component", "191", "--cmd",
                f"set requireexit True; repeat add 2 wp load {attack}; repeat add 5 wp clear",
            ],
            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env=dict(os.environ, MAVLINK20="1"),
        )  # fmt: skip
        lines: list[str] = []
        assert proc.stdout is not None
        reader = threading.Thread(target=lambda: lines.extend(proc.stdout or ()), daemon=True)
        reader.start()  # read as it comes: a full pipe would stall MAVProxy

        def refused(kind: str) -> bool:
            return any(
                r.getMessage().startswith(f"refusing {kind} from (255, ") for r in caplog.records
            )

        def tried() -> bool:  # MAVProxy's upload and clear reached the server and were denied
            out = "".join(lines)
            return (
                refused("MISSION_COUNT")
                and refused("MISSION_CLEAR_ALL")
                and "Loaded 3 waypoints" in out
                and out.count("MISSION_ACK: TYPE_MISSION: DENIED") >= 2
            )

        try:
            # wp load every 2 s, wp clear every 5 s once MAVProxy runs: its start (seconds
            # alone, far more on a loaded machine) is waited for, not guessed
            deadline = time.monotonic() + 180.0  # a hang guard
            while not tried() and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.1)
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            reader.join(timeout=10)
        log = "".join(lines)
        assert refused("MISSION_COUNT") and refused("MISSION_CLEAR_ALL"), log[-2000:]
        after = download(port)
    assert "Loaded 3 waypoints" in log, log[-2000:]  # the upload was really tried
    assert log.count("MISSION_ACK: TYPE_MISSION: DENIED") >= 2, log[-2000:]  # load and clear
    assert after == before, f"the served holes changed:\n{log[-2000:]}"
    assert (round(HOLES[1].lat_deg * 1e7), round(HOLES[1].lon_deg * 1e7)) in after
