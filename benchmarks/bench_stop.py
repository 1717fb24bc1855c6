"""How fast ``holescan fly`` stops, and how much a SIGKILL loses: the figures the shutdown
tests (``tests/capture/test_shutdown.py``, ``tests/capture/test_faults.py``) leave to a
benchmark.

Each run starts ``holescan fly --sensor sim`` (a small simulated sortie at 10 fps) in its own
process group, waits until frames are flowing into the flight log, then

* ``SIGTERM`` / ``SIGINT`` to the whole group (``systemctl stop``, Ctrl-C): seconds until the
  daemon exits (detector drained, log closed), and until every process of the group is gone;
* ``SIGKILL`` of the daemon: the log recovered (``recover_log``), seconds between the kill
  and the last frame recovered (the writer fsyncs every second).

Medians over ``--runs`` runs per signal (the machine's load changes them: say it).

    python benchmarks/bench_stop.py [--runs 3] [--signals TERM,INT,KILL]
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout

from holescan.flightlog import LoggedFrame, read_flight_log, recover_log  # noqa: E402
from tests._support import SIM_TOML, group_members  # noqa: E402


def start(work: Path) -> tuple[subprocess.Popen[bytes], Path]:
    cfg = work / "fly.toml"
    cfg.write_text(SIM_TOML)
    logs = work / "logs"
    cmd = [sys.executable, "-m", "holescan.cli", "fly", "--config", str(cfg)]
    cmd += ["--log-dir", str(logs), "--duration", "300"]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        files = list(logs.glob("*.mcap"))
        if files and files[0].stat().st_size > 1_500_000:
            time.sleep(2.0)  # a few seconds of steady flight
            return proc, logs
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the simulated flight did not start")


def stop_once(sig: signal.Signals) -> tuple[float, float]:
    """(seconds until the daemon exited, until the group was gone) after ``sig``; for
    SIGKILL (seconds of flight lost, 0)."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        proc, logs = start(work)
        if sig == signal.SIGKILL:
            t_kill = time.time()
            proc.send_signal(sig)
            proc.wait(timeout=60)
            (path,) = sorted(logs.glob("*.mcap"))
            recover_log(path, work / "rec.mcap")
            frames = list(read_flight_log(work / "rec.mcap", kinds={LoggedFrame}))
            last = frames[-1]
            assert isinstance(last, LoggedFrame)
            return t_kill - last.t_unix_ns / 1e9, 0.0
        t0 = time.monotonic()
        os.killpg(proc.pid, sig)
        proc.wait(timeout=120)
        exited = time.monotonic() - t0
        while group_members(proc.pid) and time.monotonic() - t0 < 60:
            time.sleep(0.01)
        return exited, time.monotonic() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--signals", default="TERM,INT,KILL")
    args = ap.parse_args()
    for name in args.signals.split(","):
        sig = signal.Signals[f"SIG{name.strip().upper()}"]
        runs = [stop_once(sig) for _ in range(args.runs)]
        first = statistics.median(r[0] for r in runs)
        spread = f"{min(r[0] for r in runs):.2f}-{max(r[0] for r in runs):.2f}"
        if sig == signal.SIGKILL:
            print(f"SIGKILL of the daemon: the last {first:.2f} s lost (median; {spread})")
        else:
            gone = statistics.median(r[1] for r in runs)
            print(
                f"{sig.name} to the group: the flight ended in {first:.2f} s (median; {spread}), "
                f"every process gone after {gone:.2f} s"
            )
    print(f"{args.runs} runs per signal; load average {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
