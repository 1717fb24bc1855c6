"""Stopping ``holescan fly`` the ways systemd, a terminal and a crash do: SIGTERM to the
whole process group, Ctrl-C (SIGINT to the group), SIGKILL of the daemon; and the detection
worker dying with its parent."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from holescan.flightlog import LoggedHealth, log_info, read_flight_log
from tests._support import group_members
from tests.capture.test_fly import SIM_TOML, holescan

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")


#: Children leave within ~0.1 s of the daemon (the worker polls its parent every 0.1 s): a
#: process still there after 10 s (100 times that) is an orphan, not a slow machine.
GONE_S = 10.0
#: A hang guard, not a speed bound: ``fly`` ends within seconds of SIGTERM/SIGINT (detector
#: drained, log closed; systemd waits 90 s before it kills): still running after 30 s is a
#: hang. How long it takes is measured by benchmarks/bench_stop.py.
STOP_S = 30.0


def wait_gone(pgid: int, timeout_s: float) -> float:
    """Seconds until no process of the group is left (raises after ``timeout_s``)."""
    t0 = time.monotonic()
    while group_members(pgid):
        if time.monotonic() - t0 > timeout_s:
            left = group_members(pgid)
            cmds = [Path(f"/proc/{p}/cmdline").read_bytes()[:120] for p in left]
            pytest.fail(f"processes outlived the daemon by {timeout_s} s: {cmds}")
        time.sleep(0.02)
    return time.monotonic() - t0


def start_sim_flight(tmp_path: Path, *pre: str, **kw: object) -> tuple[subprocess.Popen[str], Path]:
    cfg = tmp_path / "fly.toml"
    cfg.write_text(SIM_TOML)
    logs = tmp_path / "logs"
    proc = holescan(
        *pre,
        "fly", "--config", str(cfg), "--log-dir", str(logs), "--duration", "300",
        start_new_session=True, **kw,
    )  # fmt: skip
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and proc.poll() is None:  # frames flowing and logged
        files = list(logs.glob("*.mcap"))
        if files and files[0].stat().st_size > 1_500_000 and len(group_members(proc.pid)) >= 3:
            return proc, logs
        time.sleep(0.1)
    proc.kill()
    _out, err = proc.communicate()
    pytest.fail(f"the simulated flight did not start: {err[-3000:]}")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_to_the_whole_group_ends_the_flight_in_seconds(
    tmp_path: Path, sig: signal.Signals
) -> None:
    """``systemctl stop`` (SIGTERM to the group) and Ctrl-C (SIGINT to the group)."""
    proc, logs = start_sim_flight(tmp_path)
    os.killpg(proc.pid, sig)
    try:
        out, err = proc.communicate(timeout=STOP_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _out, err = proc.communicate()
        pytest.fail(f"{sig.name} to the group: still running after {STOP_S} s:\n{err[-3000:]}")
    wait_gone(proc.pid, GONE_S)
    assert proc.returncode == 0, err[-3000:]
    # The flight ended by the signal (its handler's line), not by --duration 300, and
    # finished as a flight does: its report printed.
    assert f"{sig.name}: finishing the flight" in err
    assert "flight: " in out, out[-3000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-3000:]
    files = sorted(logs.glob("*.mcap"))
    info = log_info(files)  # opens without recovery: complete, every CRC checked
    assert info.frames > 0
    health = list(read_flight_log(files, kinds={LoggedHealth}, strict=True))
    seqs = [r.sequence for r in health]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)


def test_sigkill_of_the_daemon_leaves_no_process_behind(tmp_path: Path) -> None:
    proc, logs = start_sim_flight(tmp_path)
    members = group_members(proc.pid)
    assert len(members) >= 3  # daemon, detection worker, resource tracker
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=10)
    gone_s = wait_gone(proc.pid, GONE_S)
    print(f"\nSIGKILL: {len(members) - 1} child processes gone {gone_s:.2f} s after the daemon")
    # The log is recoverable up to its last synced chunk.
    info = log_info(sorted(logs.glob("*.mcap")), allow_truncated=True)
    assert info.frames > 0


def test_worker_exits_when_its_parent_dies_without_prctl(tmp_path: Path) -> None:
    """The fallback: a worker whose parent died (no PDEATHSIG) notices within ~0.1 s."""
    child = textwrap.dedent(
        """
        import os, sys, time
        from holescan.capture import DetectionWorker
        from holescan.detect import DEFAULT, CameraIntrinsics
        w = DetectionWorker(CameraIntrinsics.xtion(64, 48), DEFAULT)
        w.start()
        print(w._proc.pid, flush=True)
        os._exit(0)  # the parent vanishes without stopping the worker
        """
    )
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    proc = subprocess.Popen(
        [sys.executable, "-c", child], stdout=subprocess.PIPE, text=True, env=env,
        start_new_session=True,
    )  # fmt: skip
    out, _ = proc.communicate(timeout=120)
    worker_pid = int(out.split()[0])
    wait_gone(proc.pid, GONE_S)
    assert (
        not Path(f"/proc/{worker_pid}").exists()
        or "Z" in Path(f"/proc/{worker_pid}/stat").read_text().split(")")[1][:3]
    )
