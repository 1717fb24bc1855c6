"""ArduPilot SITL flies the survey; holescan on the companion's link finds and delivers holes.

    python benchmarks/sitl_sortie.py --arducopter PATH/build/sitl/bin/arducopter [--out DIR]

Integration run and benchmark (never in CI: it needs an ``arducopter`` built from
ArduPilot's sources, which this repository neither holds nor builds; see docs/sitl.md "ArduPilot
SITL"). The real topology of issue 20, all on loopback:

* ``arducopter`` (copter, ``+`` frame, speedup 1) boots at the simulated world's home with
  its MAVLink serial ports as TCP servers: SERIAL0 5760 (this script's controller: arming,
  modes, SITL's truth), SERIAL1 5762 (the ground station, MAVProxy), SERIAL2 5763 (the
  companion: ``holescan fly --sensor sim --mavlink tcp:127.0.0.1:5763``, no ``--gcs``);
* ``holescan plan AREA --upload tcp:127.0.0.1:5762`` uploads the lawnmower over the world;
* the controller arms in GUIDED, takes off to the survey height, flies the mission in AUTO
  at the plan's speed and lands; the companion, started before SITL has a GPS fix, renders
  the simulated Xtion from the pose ArduPilot reports, captures, detects, geotags and sends
  its announcements, hole mission (component 191) and pictures through ArduPilot's routing;
* MAVProxy on SERIAL1 records what reached the ground (its tlog), then a second MAVProxy
  downloads the hole mission (``wp save``).

Printed: found / missed / false of the holes the GCS downloaded against the world's truth,
their position errors, first sighting -> at the GCS, the companion's clock (TIMESYNC)
against SITL's boot clock, the pose at frame time against SITL's own truth (SIMSTATE),
frames lost, and the bytes ArduPilot's routing delivered to the GCS (its own telemetry and
the pictures) against what a 57,600-baud radio carries.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from sitl_report import Truth, reboot_report, report  # noqa: E402

from holescan.link import mavlink, mavutil  # noqa: E402
from holescan.sim import (  # noqa: E402
    DEFAULT_ANCHOR,
    SortieParams,
    anchor_at_home,
    make_sortie_world,
    true_holes,
    world_area,
)

COPTER_GUIDED, COPTER_AUTO, COPTER_LAND = 4, 3, 9


class Controller:
    """The script's own GCS link on SERIAL0: commands, SITL's truth, TIMESYNC."""

    def __init__(self, conn: str) -> None:
        deadline = time.monotonic() + 30
        while True:
            try:
                self.m = mavutil.mavlink_connection(conn, source_system=250, source_component=190)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        self.m.wait_heartbeat(timeout=30)
        self.m.target_system, self.m.target_component = 1, 1
        self.lock = threading.Lock()
        self.truth: list[tuple[int, Any]] = []  # (arrival mono ns, SIMSTATE)
        self.gpi: list[tuple[int, Any]] = []
        self.offsets: list[tuple[int, int, int]] = []  # (mono ns, round trip ns, boot - mono)
        self.acks: dict[int, int] = {}
        self.reached: set[int] = set()
        self.armed = False
        self.rel_alt_m = 0.0
        self.ekf_flags = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._rx, daemon=True)
        self.thread.start()
        for msg_id, hz in ((164, 20), (33, 10), (193, 2), (42, 2)):
            self.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def _rx(self) -> None:
        next_ts = 0
        while not self.stop.is_set():
            now = time.monotonic_ns()
            if now >= next_ts:
                with self.lock:
                    self.m.mav.timesync_send(0, time.monotonic_ns())
                next_ts = now + 500_000_000
            msg = self.m.recv_match(blocking=True, timeout=0.05)
            if msg is None:
                continue
            t = time.monotonic_ns()
            if msg.get_srcSystem() != 1 or msg.get_srcComponent() != 1:
                continue
            kind = msg.get_type()
            if kind == "SIMSTATE":
                self.truth.append((t, msg))
            elif kind == "GLOBAL_POSITION_INT":
                self.gpi.append((t, msg))
                self.rel_alt_m = msg.relative_alt / 1000
            elif kind == "TIMESYNC" and msg.tc1 != 0:
                self.offsets.append((t, t - msg.ts1, msg.tc1 - (msg.ts1 + t) // 2))
            elif kind == "COMMAND_ACK":
                self.acks[msg.command] = msg.result
            elif kind == "MISSION_ITEM_REACHED":
                self.reached.add(msg.seq)
            elif kind == "HEARTBEAT":
                self.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            elif kind == "EKF_STATUS_REPORT":
                self.ekf_flags = msg.flags

    def command(self, cmd: int, *p: float, timeout: float = 3.0) -> int | None:
        params = [float(v) for v in p] + [0.0] * (7 - len(p))
        self.acks.pop(cmd, None)
        with self.lock:
            self.m.mav.command_long_send(1, 1, cmd, 0, *params)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if cmd in self.acks:
                return self.acks[cmd]
            time.sleep(0.02)
        return None

    def mode(self, custom: int) -> int | None:
        return self.command(mavlink.MAV_CMD_DO_SET_MODE, 1, custom)


def _wait(cond: Any, timeout: float, what: str) -> float:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise SystemExit(f"sitl_sortie: timed out waiting for {what}")
        time.sleep(0.1)
    return time.monotonic() - t0


def _truth_rows(ctl: Controller) -> Truth:
    return [(t, m.lat * 1e-7, m.lng * 1e-7, m.roll, m.pitch, m.yaw) for t, m in ctl.truth]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arducopter", type=Path, help="a built SITL arducopter (required)")
    ap.add_argument("--defaults", type=Path, help="copter.parm (default: from its source tree)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/sitl_sortie"))
    ap.add_argument("--world-seed", type=int, default=7)
    ap.add_argument("--size", type=float, default=10.0, help="surveyed square, m (10)")
    ap.add_argument("--altitude", type=float, default=3.0, help="survey height, m (3)")
    ap.add_argument("--fps", type=float, default=10.0, help="simulated Xtion rate (10)")
    ap.add_argument("--report-only", action="store_true", help="report a finished run in --out")
    ap.add_argument(
        "--reboot-at",
        type=float,
        help="reboot ArduPilot (forced, armed) this many s into AUTO, watch the companion "
        "45 s more and report its reboot handling instead of the survey",
    )
    args = ap.parse_args()
    params = SortieParams(
        world_seed=args.world_seed,
        size_m=(args.size, args.size),
        altitude_m=args.altitude,
        fps=args.fps,
    )
    truth = true_holes(make_sortie_world(params), DEFAULT_ANCHOR)
    if args.report_only:
        report(args.out, truth)
        return 0
    if args.arducopter is None:
        ap.error("--arducopter PATH is required (a built SITL arducopter)")
    exe = args.arducopter.resolve()
    defaults = args.defaults or exe.parents[3] / "Tools/autotest/default_params/copter.parm"
    if not exe.is_file() or not defaults.is_file():
        raise SystemExit(f"sitl_sortie: need {exe} and {defaults} (--defaults)")
    out = args.out
    shutil.rmtree(out, ignore_errors=True)
    (out / "sitl").mkdir(parents=True)

    world = make_sortie_world(params)
    anchor = DEFAULT_ANCHOR
    home_lat, home_lon, _ = anchor.to_geodetic(params.margin_m, params.margin_m, 0.0)
    home = (home_lat, home_lon, anchor.alt_m)
    # The companion places the world at the home it is first given (sim._reported): here.
    placed = anchor_at_home(home, params.margin_m)
    assert abs(placed.lat_deg - anchor.lat_deg) + abs(placed.lon_deg - anchor.lon_deg) < 1e-8
    area = world_area(world, anchor, params.margin_m)
    ring = [[lon, lat] for lat, lon in area.outer] + [[area.outer[0][1], area.outer[0][0]]]
    (out / "area.geojson").write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    (out / "fly.toml").write_text(
        f'sensor = "sim"\n[holes]\nannounce_min_sightings = 3\n[sim]\n'
        f"world_seed = {args.world_seed}\nsize_m = [{args.size}, {args.size}]\n"
        f"altitude_m = {args.altitude}\nfps = {args.fps}\n"
    )
    env = dict(os.environ, PYTHONPATH=str(REPO), MAVLINK20="1", PYTHONUNBUFFERED="1")
    procs: list[subprocess.Popen[Any]] = []

    def start(cmd: list[str], name: str, **kw: Any) -> subprocess.Popen[Any]:
        f = (out / f"{name}.log").open("w")
        p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, **kw)
        procs.append(p)
        return p

    t_boot_host = time.monotonic()
    start(
        [
            str(exe),
            "--model",
            "+",
            "--speedup",
            "1",
            "-I",
            "0",
            "-w",
            "--home",
            f"{home[0]:.8f},{home[1]:.8f},{home[2]:.2f},0",
            "--defaults",
            str(defaults),
            "--serial0",
            "tcp:5760",
            "--serial1",
            "tcp:5762",
            "--serial2",
            "tcp:5763",
        ],
        "sitl",
        cwd=out / "sitl",
    )
    try:
        ctl = Controller("tcp:127.0.0.1:5760")
        # The plan, uploaded on the GCS port before the GCS takes it.
        up = subprocess.run(
            [
                sys.executable,
                "-m",
                "holescan.cli",
                "plan",
                str(out / "area.geojson"),
                "--altitude",
                str(args.altitude),
                "--home",
                f"{home[0]:.8f},{home[1]:.8f}",
                "--home-amsl",
                str(home[2]),
                "--outside-sun-window",
                "--out",
                str(out / "survey.plan"),
                "--upload",
                "tcp:127.0.0.1:5762",
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        print(up.stdout.strip())
        if up.returncode:
            raise SystemExit(f"sitl_sortie: plan upload failed: {up.stderr.strip()}")
        # The companion, before any GPS fix (issue 20: no Null Island holes).
        comp = start(
            [
                sys.executable,
                "-m",
                "holescan.cli",
                "fly",
                "--config",
                str(out / "fly.toml"),
                "--mavlink",
                "tcp:127.0.0.1:5763",
                "--log-dir",
                str(out / "logs"),
            ],
            "companion",
        )
        gcs = start(
            [
                "mavproxy.py",
                "--master=tcp:127.0.0.1:5762",
                "--daemon",
                "--streamrate=-1",
                f"--state-basedir={out / 'gcs'}",
                f"--logfile={out / 'gcs.tlog'}",
                "--target-system",
                "1",
                "--target-component",
                "191",
            ],
            "mavproxy",
        )
        # Arm once the EKF has a position (about 30 s after boot), take off, fly AUTO.
        t_arm = _wait(
            lambda: (
                ctl.mode(COPTER_GUIDED) == 0
                and ctl.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
            ),
            180,
            "arming",
        )
        print(f"armed {time.monotonic() - t_boot_host:.0f} s after boot ({t_arm:.0f} s of tries)")
        ctl.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, args.altitude)
        _wait(lambda: ctl.rel_alt_m > 0.9 * args.altitude, 60, "take-off")
        n_items = json.loads((out / "survey.plan").read_text())["mission"]["items"]
        last = len(n_items)
        ctl.mode(COPTER_AUTO)
        t_auto = time.monotonic()
        if args.reboot_at is not None:
            time.sleep(args.reboot_at)
            t_reboot = time.monotonic_ns()
            with ctl.lock:  # param1 1 = reboot; param6 = ArduPilot's "even when armed" magic
                ctl.m.mav.command_long_send(
                    1, 1, mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0, 1, 0, 0, 0, 0, 20190226, 0
                )
            print(f"reboot sent {args.reboot_at:.0f} s into AUTO")
            time.sleep(45.0)
            comp.send_signal(signal.SIGINT)
            comp.wait(60)
            reboot_report(out, t_reboot)
            return 0
        _wait(lambda: last in ctl.reached or (last - 1) in ctl.reached, 1200, "the survey's end")
        t_survey = time.monotonic() - t_auto
        ctl.mode(COPTER_LAND)
        _wait(lambda: not ctl.armed, 120, "landing")
        print(f"survey flown in AUTO in {t_survey:.0f} s, landed")
        time.sleep(3.0)  # the last pictures
        gcs.send_signal(signal.SIGINT)
        gcs.wait(10)
        dl = out / "holes_at_gcs.txt"
        start(
            [
                "mavproxy.py",
                "--master=tcp:127.0.0.1:5762",
                "--daemon",
                "--streamrate=-1",
                f"--state-basedir={out / 'gcs2'}",
                "--target-system",
                "1",
                "--target-component",
                "191",
                "--cmd",
                f"set requireexit True; repeat add 2 wp save {dl}; repeat add 12 exit",
            ],
            "mavproxy-download",
        ).wait(60)
        comp.send_signal(signal.SIGINT)
        comp.wait(60)
        ctl.stop.set()
        saved = {
            "timesync": ctl.offsets,
            "truth": _truth_rows(ctl),
            "t_survey": t_survey,
            "unix_minus_mono": time.time_ns() - time.monotonic_ns(),
        }
        (out / "controller.json").write_text(json.dumps(saved))
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
    report(out, truth)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
