#!/usr/bin/env python3
"""A Pi-class budget: the whole flight on one core, and on a core throttled to a Pi's speed.

Run (as root, from the repository root; the lap is pre-rendered once, ~1-3 min)::

    python benchmarks/bench_pi.py                       # 4 profiles, one lap each
    python benchmarks/bench_pi.py --profiles pi4 --duration 60 --workdir /tmp/bench-pi --keep

What runs: the simulated sortie (:class:`sim.SimSortie`: rubble world, lawnmower survey, the
simulated autopilot on loopback MAVLink) in this process, unconstrained, as an autopilot is
its own computer. Its lap is pre-rendered into an ``.oni`` file (the simulated Xtion's
renderer is not flight cost) and, per profile, a child process flies it through the real
flight path, :func:`capture.fly`: OpenNI2 playback of the lap in step with the autopilot,
the MCAP log, the detection worker, telemetry with TIMESYNC, geotagging, the hole tracker,
the hole server announcing each hole by STATUSTEXT on a ground-station link, pictures and
the live map. This process is the ground station: it timestamps each announcement as it
arrives. Profiles (the child and its detection worker together):

* ``full``: both cores of this machine;
* ``core``: one core (``taskset -c 1``);
* ``pi5``: one core with a CPU quota of ``--pi5-quota`` (0.5) of it;
* ``pi4``: one core with a CPU quota of ``--pi4-quota`` (0.25) of it.

The quota is a cgroup CPU bandwidth limit (cgroup v1 ``cpu.cfs_quota_us`` or v2
``cpu.max``, 100 ms period), made here without systemd. Why those ratios:
docs/measurements.md ("A Pi-class budget").

Printed per profile: frames captured, logged and dropped from the log; frames the sensor
delivered late; frames detected per second and detections per second; hole-level recall
(true access holes in view during the lap that were announced; announced or sent for
review); latency from a hole's first sighting (its frame's time) to its announcement
arriving at the ground station; telemetry (GLOBAL_POSITION_INT logged per second and the
longest gap between two: a blocked telemetry thread would show here); the CPU the child
used and how often the quota throttled it.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import logging
import math
import os
import resource
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pymap3d

from holescan.capture import FlightConfig, FlyConfig, SensorSetup, SensorSpec, fly
from holescan.flightlog import LoggedMavlink, LogOptions, read_flight_log
from holescan.link import mavutil
from holescan.sim import (
    LapReplay,
    SimSortie,
    SortieParams,
    camera_pose_in_world,
    hole_boxes,
    lap_frames,
    make_sortie_world,
    prerender_lap,
    survey_path,
)

log = logging.getLogger("bench_pi")
PROFILES = ("full", "core", "pi5", "pi4")
CGROUP_V1 = Path("/sys/fs/cgroup/cpu")
CGROUP_V2 = Path("/sys/fs/cgroup")
PERIOD_US = 100_000


# -- the child: one flight -----------------------------------------------------------------


class _BootClock:
    """The simulated autopilot's boot clock, as the parent measured it (linear in mono)."""

    def __init__(self, b0: int, rate: float) -> None:
        self.b0, self.rate = b0, rate

    def boot_ns_at_mono(self, t_mono_ns: int) -> int:
        return round(self.b0 + self.rate * t_mono_ns)


def child(args: argparse.Namespace) -> int:
    params = SortieParams(world_seed=args.seed, fps=30.0)
    clock = _BootClock(args.b0, args.rate)
    origin = round(params.clock_offset_s * 1e9)
    replays: list[LapReplay] = []

    def source() -> LapReplay:
        replays.append(LapReplay(args.oni, clock, params.fps, origin))  # type: ignore[arg-type]
        return replays[-1]

    probe = LapReplay(args.oni, clock, params.fps, origin)  # type: ignore[arg-type]
    cfg = FlyConfig(
        sensor=SensorSpec("sim"),
        log_dir=args.log_dir,
        mavlink=args.mavlink,
        gcs=args.gcs,
        duration_s=args.duration,
        flight=FlightConfig(
            log_prefix=Path("flight"), log_options=LogOptions(compression=args.compression)
        ),
    )
    t0 = os.times()
    report = fly(cfg, SensorSetup(source, probe.camera, args.mavlink))
    t1 = os.times()
    s = report.summary
    c = s.counters
    gate = cfg.flight.gate
    announced = {h.id for h in gate.select(list(s.holes))}
    review = {h.id for h in gate.review(list(s.holes))}
    out = {
        "duration_s": s.duration_s,
        "captured": c.frames_captured,
        "logged": s.frames_logged,
        "log_dropped": c.frames_log_dropped,
        "unposed": c.frames_unposed,
        "detected": c.frames_detected,
        "detections": c.detections,
        "detect_ms_mean": c.detect_ms_total / max(c.frames_detected, 1),
        "detect_skipped": s.detect_skipped,
        "shed": c.frames_shed,
        "late": sum(r.late_frames for r in replays),
        "max_late_ms": max((r.max_late_ms for r in replays), default=0.0),
        "files": [str(f) for f in s.log.files],
        "log_bytes": s.log.bytes_written,
        "telemetry": s.telemetry,
        "cpu_s": (t1.user - t0.user) + (t1.system - t0.system),
        "worker_cpu_s": (lambda r: r.ru_utime + r.ru_stime)(
            resource.getrusage(resource.RUSAGE_CHILDREN)
        ),
        "holes": [
            {
                "id": h.id,
                "lat": h.lat_deg,
                "lon": h.lon_deg,
                "t_first_boot_ns": h.t_first_boot_ns,
                "tier": "announced"
                if h.id in announced
                else "review"
                if h.id in review
                else "candidate",
            }
            for h in s.holes
        ],
    }
    args.out.write_text(json.dumps(out))
    return 0


# -- the parent: the autopilot, the ground station, the profiles -------------------------


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class GroundListener(threading.Thread):
    """Arrival time (monotonic ns) of each hole's first HOLE announcement on the gcs link."""

    def __init__(self, port: int) -> None:
        super().__init__(name="ground", daemon=True)
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.first: dict[int, int] = {}
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            msg = self.conn.recv_match(type="STATUSTEXT", blocking=True, timeout=0.2)
            if msg is None:
                continue
            words = str(msg.text).split()
            if len(words) >= 2 and words[0] == "HOLE" and words[1].isdigit():
                self.first.setdefault(int(words[1]), time.monotonic_ns())


@contextlib.contextmanager
def cpu_quota(name: str, quota: float | None) -> Iterator[Path | None]:
    """A cgroup limiting its members to ``quota`` of one core (None: no cgroup)."""
    if quota is None:
        yield None
        return
    v2 = (CGROUP_V2 / "cgroup.controllers").exists()
    group = (CGROUP_V2 if v2 else CGROUP_V1) / f"holescan-bench-pi-{os.getpid()}-{name}"
    group.mkdir()
    try:
        if v2:
            (group / "cpu.max").write_text(f"{round(quota * PERIOD_US)} {PERIOD_US}")
        else:
            (group / "cpu.cfs_period_us").write_text(str(PERIOD_US))
            (group / "cpu.cfs_quota_us").write_text(str(round(quota * PERIOD_US)))
        yield group
    finally:
        _remove_group(group)


def _remove_group(group: Path) -> None:
    """Remove the cgroup once its last member (a detection worker ending after its parent)
    has gone; a straggler after 10 s is moved to the root group first."""
    deadline = time.monotonic() + 10.0
    while True:
        try:
            group.rmdir()
            return
        except OSError:
            if time.monotonic() < deadline:
                time.sleep(0.2)
                continue
            for pid in (group / "cgroup.procs").read_text().split():
                (group.parent / "cgroup.procs").write_text(pid)
            group.rmdir()
            return


def _throttled(group: Path | None) -> str:
    if group is None:
        return ""
    stat = dict(line.split() for line in (group / "cpu.stat").read_text().splitlines())
    periods = int(stat.get("nr_periods", 0))
    return f", throttled in {stat.get('nr_throttled', '0')} of {periods} periods"


def _horizontal_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    e, n, _ = pymap3d.geodetic2enu(lat1, lon1, 0.0, lat2, lon2, 0.0)
    return math.hypot(float(e), float(n))


def run_profile(
    name: str, sortie: SimSortie, oni: Path, work: Path, args: argparse.Namespace
) -> dict[str, Any]:
    quota = {"pi5": args.pi5_quota, "pi4": args.pi4_quota}.get(name)
    port = _free_udp_port()
    ground = GroundListener(port)
    ground.start()
    ap = sortie.autopilot
    assert ap is not None
    b0 = ap.boot_ns_at_mono(0)
    rate = (ap.boot_ns_at_mono(10**12) - b0) / 1e12
    out = work / f"{name}.json"
    cmd = [
        *(() if name == "full" else ("taskset", "-c", str(args.cpu))),
        *(sys.executable, __file__, "--child", "--oni", str(oni), "--out", str(out)),
        *("--mavlink", sortie.mavlink, "--gcs", f"udpout:127.0.0.1:{port}"),
        *("--log-dir", str(work / name), "--duration", str(args.duration)),
        *("--b0", str(b0), "--rate", repr(rate), "--seed", str(args.seed)),
        *("--compression", args.compression),
    ]
    with cpu_quota(name, quota) as group:
        procs = None if group is None else group / "cgroup.procs"

        def enter() -> None:  # in the child, before exec: into the cgroup
            if procs is not None:
                procs.write_text(str(os.getpid()))

        done = subprocess.run(cmd, preexec_fn=enter, capture_output=True, text=True, check=False)
        throttled = _throttled(group)
    ground.stop.set()
    ground.join()
    ground.conn.close()
    if done.returncode != 0:
        raise SystemExit(f"bench_pi: the {name} flight failed:\n{done.stderr[-3000:]}")
    res: dict[str, Any] = json.loads(out.read_text())
    res["name"], res["quota"], res["throttled"] = name, quota, throttled
    res["announce_mono_ns"] = ground.first
    res["boot_at_mono"] = (b0, rate)
    return res


def telemetry_gaps(files: list[str]) -> tuple[float, float]:
    """GLOBAL_POSITION_INT logged per second and the longest gap between two, s."""
    times = [
        r.t_unix_ns
        for r in read_flight_log(files, kinds={LoggedMavlink})
        if isinstance(r, LoggedMavlink) and r.name == "GLOBAL_POSITION_INT"
    ]
    if len(times) < 2:
        return 0.0, math.inf
    span = (times[-1] - times[0]) / 1e9
    gaps = [(b - a) / 1e9 for a, b in itertools.pairwise(times)]
    return (len(times) - 1) / span, max(gaps)


def in_view_holes(sortie: SimSortie, params: SortieParams, n: int, world: Any) -> set[int]:
    """True access holes wholly in view in at least 3 frames of the lap."""
    ap = sortie.autopilot
    assert ap is not None
    origin = round(params.clock_offset_s * 1e9)
    seen: dict[int, int] = {}
    for k in range(n):
        pose = ap.truth_pose(origin + round(k * 1e9 / params.fps))
        cam = camera_pose_in_world(pose, sortie.mount, params.anchor)
        for b in hole_boxes(world, cam, sortie.camera):
            if not b.iscrowd:
                seen[b.hole_id] = seen.get(b.hole_id, 0) + 1
    return {h for h, count in seen.items() if count >= 3}


def report(res: dict[str, Any], sortie: SimSortie, in_view: set[int]) -> list[str]:
    dur = res["duration_s"]
    truth = {t.id: t for t in sortie.truth if t.id in in_view}
    found: dict[str, set[int]] = {"announced": set(), "review": set()}
    latency: list[float] = []
    b0, rate = res["boot_at_mono"]
    for h in res["holes"]:
        near = [
            t
            for t in truth.values()
            if _horizontal_m(h["lat"], h["lon"], t.lat_deg, t.lon_deg) <= 0.5
        ]
        if near and h["tier"] in found:
            found[h["tier"]].add(near[0].id)
        t_mono = res["announce_mono_ns"].get(str(h["id"]), res["announce_mono_ns"].get(h["id"]))
        if t_mono is not None:
            latency.append((b0 + rate * t_mono - h["t_first_boot_ns"]) / 1e9)
    rate_hz, gap_s = telemetry_gaps(res["files"])
    limit = "2 cores" if res["name"] == "full" else "1 core"
    if res["quota"] is not None:
        limit += f" at {100 * res['quota']:.0f} %"
    either = found["announced"] | found["review"]
    lat = (
        f"median {statistics.median(latency):.1f} s, max {max(latency):.1f} s (n={len(latency)})"
        if latency
        else "none announced"
    )
    return [
        f"== {res['name']} ({limit}) ==",
        f"frames: captured {res['captured']} ({res['captured'] / dur:.1f}/s), logged "
        f"{res['logged']}, dropped from the log {res['log_dropped']}; sensor late "
        f"{res['late']} (max {res['max_late_ms']:.0f} ms); unposed {res['unposed']}",
        f"detector: {res['detected'] / dur:.1f} frames/s (mean {res['detect_ms_mean']:.0f} ms, "
        f"{res['detect_skipped']} skipped for newer frames, {res['shed']} not offered while "
        f"the log caught up), {res['detections'] / dur:.1f} detections/s",
        f"holes: recall announced {len(found['announced'])}/{len(truth)}, announced or for "
        f"review {len(either)}/{len(truth)} (true access holes in view in >= 3 lap frames); "
        f"first sighting -> announcement at the ground: {lat}",
        f"telemetry: GLOBAL_POSITION_INT logged {rate_hz:.1f}/s (asked 10/s), longest gap "
        f"{gap_s:.2f} s; log {res['log_bytes'] / 1e6 / dur:.1f} MB/s",
        f"CPU: flight {res['cpu_s'] / dur:.2f} + detection worker "
        f"{res['worker_cpu_s'] / dur:.2f} cores over {dur:.0f} s{res['throttled']}",
    ]


def parent(args: argparse.Namespace) -> int:
    work = args.workdir or Path(tempfile.mkdtemp(prefix="holescan-bench-pi-"))
    work.mkdir(parents=True, exist_ok=True)
    params = SortieParams(world_seed=args.seed, fps=30.0)
    try:
        world = make_sortie_world(params)
        _plan, path = survey_path(world, params)
        lap, n = lap_frames(path, params.fps)
        oni = work / f"lap-seed{args.seed}-{n}.oni"
        if not oni.exists():
            t = time.monotonic()
            prerender_lap(params, lap, oni, workers=2)
            print(f"pre-rendered the lap: {n} frames in {time.monotonic() - t:.0f} s")
        print(f"lap: {n} frames, {n / params.fps:.0f} s; flights of {args.duration:.0f} s")
        in_view: set[int] | None = None
        for name in args.profiles.split(","):
            # a fresh autopilot per flight: each starts at the lap's start
            with SimSortie(params, world=world, path=lap) as sortie:
                res = run_profile(name, sortie, oni, work, args)
                if in_view is None:
                    in_view = in_view_holes(sortie, params, n, world)
                print("\n".join(report(res, sortie, in_view)), flush=True)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--profiles", default=",".join(PROFILES), help="of full,core,pi5,pi4")
    ap.add_argument("--duration", type=float, default=90.0, help="flight seconds (90)")
    ap.add_argument("--pi4-quota", type=float, default=0.25, help="share of one core (0.25)")
    ap.add_argument("--pi5-quota", type=float, default=0.5, help="share of one core (0.5)")
    ap.add_argument("--cpu", type=int, default=1, help="the core for one-core profiles (1)")
    ap.add_argument("--seed", type=int, default=7, help="world seed (7)")
    ap.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd")
    ap.add_argument("--workdir", type=Path, help="where the lap and the logs go (a temp dir)")
    ap.add_argument("--keep", action="store_true", help="keep the lap and the logs")
    child_args = ap.add_argument_group("child (internal)")
    child_args.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    for name in ("--oni", "--out", "--log-dir"):
        child_args.add_argument(name, type=Path, help=argparse.SUPPRESS)
    for name in ("--mavlink", "--gcs"):
        child_args.add_argument(name, help=argparse.SUPPRESS)
    child_args.add_argument("--b0", type=int, help=argparse.SUPPRESS)
    child_args.add_argument("--rate", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    logging.basicConfig(
        level=logging.WARNING, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    unknown = set(args.profiles.split(",")) - set(PROFILES)
    if unknown:
        ap.error(f"unknown profiles {sorted(unknown)}; known: {','.join(PROFILES)}")
    return child(args) if args.child else parent(args)


if __name__ == "__main__":
    sys.exit(main())
