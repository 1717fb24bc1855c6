"""``holescan fly``: its configuration, the systemd unit, the verb end to end, link faults."""

from __future__ import annotations

import configparser
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from holescan.capture import (
    Flight,
    FlightConfig,
    FlyConfig,
    SensorSpec,
    load_fly_config,
    parse_fly_config,
    write_oni,
)
from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import InputError
from holescan.flightlog import LoggedFrame, LoggedHealth, LoggedHoles, log_info, read_flight_log
from holescan.sim import SimAutopilot, SimPath, sortie_params

os.environ.setdefault("MAVLINK20", "1")
from holescan.link import mavutil
from tests._support import free_udp_port

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "deploy" / "fly.example.toml"
UNIT = ROOT / "deploy" / "holescan.service"


def holescan(*args: str, **kw: Any) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, "-m", "holescan.cli", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def finish(proc: subprocess.Popen[str], timeout: float = 60.0) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"holescan fly did not finish in {timeout} s:\n{out}\n{err[-3000:]}")
    return proc.returncode, out, err


# -- configuration --------------------------------------------------------------------------


def test_example_config_is_valid_and_its_defaults_are_the_daemons(tmp_path: Path) -> None:
    cfg = load_fly_config(EXAMPLE)
    assert cfg.sensor == SensorSpec("openni2")
    assert (cfg.mavlink, cfg.gcs, cfg.sysid) == ("/dev/ttyAMA0", "udpout:192.168.1.10:14550", 1)
    assert cfg.log_dir == Path("/var/lib/holescan/flights")
    assert cfg.duration_s is None and cfg.max_frames is None and cfg.usb_reset
    # What the example shows as defaults are the defaults: of this module and of the daemon.
    bare = load_fly_config(None, {"log_dir": tmp_path})
    daemon = FlightConfig(log_prefix=Path("flight"))
    for name in (
        "params",
        "mount",
        "attitude_sigma_deg",
        "log_options",
        "frame_timeout_s",
        "retry_backoff_s",
        "announce_min_p_hole",
        "announce_min_sightings",
        "announce_min_span_s",
        "health_period_s",
        "pose_wait_s",
        "startup_sync_s",
    ):
        assert getattr(cfg.flight, name) == getattr(bare.flight, name) == getattr(daemon, name), (
            name
        )
    assert sortie_params(cfg.sim_table) == sortie_params(bare.sim_table)  # the [sim] table
    # Command-line overrides win over the file.
    over = load_fly_config(
        EXAMPLE,
        {"sensor": "oni:/data/a.oni", "duration_s": 60.0, "mavlink": None, "log_dir": tmp_path},
    )
    assert over.sensor == SensorSpec("oni", Path("/data/a.oni"))
    assert over.mavlink == "/dev/ttyAMA0" and over.log_dir == tmp_path
    fc = over.flight_config()
    assert fc.max_duration_s == 60.0 and fc.log_prefix.parent == tmp_path
    assert fc.log_prefix.name.startswith("flight-") and fc.config_record["sensor"] == (
        "oni:/data/a.oni"
    )


def test_log_names_never_collide(tmp_path: Path) -> None:
    cfg = parse_fly_config({}, {"log_dir": tmp_path / "new"})
    t = 1_700_000_000 * 10**9
    first = cfg.flight_config(t).log_prefix
    assert first == tmp_path / "new" / "flight-20231114T221320Z"
    Path(f"{first}_0000.mcap").touch()
    assert cfg.flight_config(t).log_prefix.name == "flight-20231114T221320Z-2"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('log_dir = "/x"\nsensr = "sim"', "unknown setting sensr"),
        ('log_dir = "/x"\n[capture]\nframe_timeout = 2', "unknown setting capture.frame_timeout"),
        ('log_dir = "/x"\n[capture]\nusb_reset = "yes"', "capture.usb_reset must be bool"),
        ('log_dir = "/x"\nbaud = true', "baud must be int"),
        ('log_dir = "/x"\nsensor = "kinect"', "sensor must be openni2, oni:PATH"),
        ('log_dir = "/x"\nsensor = "oni:"', "sensor must be openni2, oni:PATH"),
        ('log_dir = "/x"\n[mount]\noffset_m = [0, 0]', "mount.offset_m must be a list of 3"),
        ('log_dir = "/x"\n[mount]\nattitude_sigma_deg = -1', "attitude_sigma_deg must be in 0-10"),
        ('log_dir = "/x"\n[detect]\nmode = "fast"', "detect.mode must be"),
        ('log_dir = "/x"\n[holes]\nannounce_min_score = 0.6', "announce_min_p_hole"),
        ('log_dir = "/x"\n[holes]\nannounce_min_p_hole = 1.0', "min_p_hole must be in [0, 0.99]"),
        ('log_dir = "/x"\n[log]\ncompression = "gzip"', "compression must be one of"),
        ('log_dir = "/x"\nduration_s = -1', "duration_s must be a positive number"),
        ('log_dir = "/x"\ncapture = 3', "[capture] must be a table"),
        ('sensor = "sim"', "no log folder"),
        ('log_dir = "/x"\nsensor = sim', "not valid TOML"),
    ],
)
def test_config_mistakes_are_named(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "fly.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace(".", r"\.")):
        load_fly_config(path)


def test_missing_config_file_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found"):
        load_fly_config(tmp_path / "nope.toml")
    proc = holescan("fly", "--config", str(tmp_path / "nope.toml"))
    code, _, err = finish(proc)
    assert code == 2 and "configuration file not found" in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--sensor", "oni:{tmp}/none.oni"], "none.oni"),
        (["--sensor", "mcap:{tmp}/none.mcap"], "flight log not found"),
        (["--sensor", "sim"], "no log folder"),
    ],
)
def test_fly_refuses_bad_sensors_and_links_before_flying(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    from holescan.cli import main

    argv = ["fly", *(a.replace("{tmp}", str(tmp_path)) for a in args)]
    if message != "no log folder":
        argv += ["--log-dir", str(tmp_path / "logs")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("holescan fly: error: ") and message in err, err
    assert not list(tmp_path.glob("logs/*.mcap"))


# -- the systemd unit -------------------------------------------------------------------------


def test_systemd_unit() -> None:
    unit = configparser.ConfigParser(strict=True, interpolation=None)
    unit.optionxform = str  # type: ignore[assignment,method-assign]
    unit.read(UNIT)
    svc = unit["Service"]
    assert svc["ExecStart"].split()[1:] == ["fly", "--config", "/etc/holescan/fly.toml"]
    assert svc["ExecStart"].split()[0].endswith("/holescan")
    assert svc["Restart"] == "on-failure"
    assert svc["KillSignal"] == "SIGINT"
    assert svc["KillMode"] == "mixed"  # SIGINT to holescan only, not to its worker process
    assert int(svc["TimeoutStopSec"]) >= 15  # stops in 2-4 s; margin for a slow disk
    assert "RestartPreventExitStatus" not in svc  # exit 2 is also "autopilot not up yet"
    assert unit["Unit"]["StartLimitIntervalSec"] == "0"  # so retry without a limit
    assert unit["Install"]["WantedBy"] == "multi-user.target"
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed")
    res = subprocess.run([analyze, "verify", str(UNIT)], capture_output=True, text=True)
    problems = [
        line
        for line in (res.stdout + res.stderr).splitlines()
        if line.strip()
        and "is not executable" not in line  # holescan not installed here
        and "No such file or directory" not in line
    ]
    assert not problems, problems


# -- the verb, end to end ---------------------------------------------------------------------


SIM_TOML = """
sensor = "sim"
[capture]
startup_sync_s = 5.0
[holes]
announce_min_sightings = 3
[sim]
size_m = [4.0, 4.0]
world_seed = 15
n_access_holes = 4
fps = 10.0
"""


def test_fly_sim_serves_holes_to_the_gcs_and_stops_cleanly_on_sigint(tmp_path: Path) -> None:
    """The simulated sortie through the CLI: a ground station hears the holes; Ctrl-C."""
    cfg = tmp_path / "fly.toml"
    cfg.write_text(SIM_TOML)
    port = free_udp_port()
    gcs = mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
    )
    proc = holescan(
        "fly",
        "--config",
        str(cfg),
        "--log-dir",
        str(tmp_path / "logs"),
        "--gcs",
        f"udpout:127.0.0.1:{port}",
        "--duration",
        "120",
    )
    texts: list[str] = []
    count = None
    try:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and proc.poll() is None and count is None:
            msg = gcs.recv_match(type=["STATUSTEXT", "MISSION_COUNT"], blocking=True, timeout=0.5)
            if msg is None:
                continue
            if msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
                if msg.text.startswith("HOLE"):  # REVIEW ones are not in the mission
                    # Download the served mission: it lists the hole after home.
                    gcs.mav.mission_request_list_send(1, 191)
            else:
                count = msg.count
    finally:
        proc.send_signal(signal.SIGINT)
        code, out, err = finish(proc)
        gcs.close()
    assert code == 0, err[-3000:]
    # Ids follow first sighting; which hole is confirmed (announced) first depends on load.
    announced = [t for t in texts if not t.startswith("REVIEW")]
    assert announced and re.match(
        r"HOLE \d+ p[01]\.\d\d -?\d+\.\d{7} -?\d+\.\d{7}$", announced[0]
    ), (texts, err[-3000:])
    assert count is not None and count >= 2
    assert "SIGINT: finishing the flight" in err
    assert "dropped from the log 0" in out and "true access hole" in out
    files = sorted((tmp_path / "logs").glob("flight-*_*.mcap"))
    info = log_info(files)  # every CRC checked; raises on a file left unfinished
    records = list(read_flight_log(files, strict=True))
    frames = [r.frame.index for r in records if isinstance(r, LoggedFrame)]
    assert frames == list(range(len(frames))) and len(frames) >= 3
    assert any(isinstance(r, LoggedHoles) and r.holes for r in records)
    assert info.metadata["holescan.config"]["sensor"] == '"sim"'


def floor_frames(n: int, camera: CameraIntrinsics) -> list[Frame]:
    """A flat floor 2.5 m below with one dark opening and no floor reading, changing noise."""
    rng = np.random.default_rng(0)
    h, w = camera.height, camera.width
    out = []
    for i in range(n):
        depth = (2500 + rng.integers(-8, 9, size=(h, w))).astype(np.uint16)
        depth[h * 3 // 8 : h * 5 // 8, w * 2 // 5 : w * 2 // 3] = 0
        rgb = np.full((h, w, 3), 90, np.uint8)
        rgb[h * 3 // 8 : h * 5 // 8, w * 2 // 5 : w * 2 // 3] = 12
        rgb[..., 0] += np.uint8(i % 64)
        out.append(Frame(i, rgb, depth, 0, i * 33_333_333))
    return out


@pytest.mark.slow
def test_fly_replays_oni_then_its_own_log_and_stops_cleanly_on_sigterm(tmp_path: Path) -> None:
    """oni -> fly -> MCAP -> fly (SIGTERM mid-way) -> MCAP: every frame intact, logs valid."""
    n = 100
    cam = CameraIntrinsics.xtion(320, 240)
    frames = floor_frames(n, cam)
    write_oni(tmp_path / "in.oni", frames, cam)
    raw = tmp_path / "raw.toml"  # the raw image layout: exact pixels through both legs
    raw.write_text('[log]\ncolor = "raw"\ndepth = "raw"\n')
    code, out, err = finish(
        holescan(
            "fly",
            "--bench",
            "--sensor",
            f"oni:{tmp_path / 'in.oni'}",
            "--log-dir",
            str(tmp_path / "a"),
            "--config",
            str(raw),
        )
    )
    assert code == 0, err[-3000:]
    assert f"frames: captured {n}, logged {n}, dropped from the log 0, unposed {n}" in out
    first = sorted((tmp_path / "a").glob("*.mcap"))
    got = [
        r.frame
        for r in read_flight_log(first, kinds={LoggedFrame}, strict=True)
        if isinstance(r, LoggedFrame)
    ]
    assert len(got) == n
    for a, b in zip(got, frames, strict=True):
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)

    proc = holescan(
        "fly", "--bench", "--sensor", f"mcap:{first[0]}", "--log-dir", str(tmp_path / "b"),
        "--config", str(raw),
    )  # fmt: skip
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and proc.poll() is None:
        logs = list((tmp_path / "b").glob("*.mcap"))
        if logs and logs[0].stat().st_size > 2_000_000:  # frames are flowing (synced each 1 s)
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    code, out, err = finish(proc)
    assert code == 0, err[-3000:]
    assert "SIGTERM: finishing the flight" in err
    second = sorted((tmp_path / "b").glob("*.mcap"))
    log_info(second)  # a complete, valid MCAP (every CRC checked)
    again = [
        r.frame
        for r in read_flight_log(second, kinds={LoggedFrame}, strict=True)
        if isinstance(r, LoggedFrame)
    ]
    assert 0 < len(again) < n
    assert f"captured {len(again)}, logged {len(again)}, dropped from the log 0" in out
    for a, b in zip(again, frames, strict=False):
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
    # Paced like the recording: consecutive frames ~33 ms apart on the new clock.
    gaps = np.diff([f.t_mono_ns for f in again]) / 1e6
    assert 25 < float(np.median(gaps)) < 45


# -- MAVLink link faults ----------------------------------------------------------------------


class FloorSource:
    """The floor frames at 30 fps, stamped now."""

    def __init__(self, n: int, camera: CameraIntrinsics) -> None:
        self.camera = camera
        self.frames = floor_frames(n, camera)

    def __enter__(self) -> FloorSource:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def __iter__(self) -> Iterator[Frame]:
        t0 = time.monotonic_ns()
        for i, f in enumerate(self.frames):
            due = t0 + i * 33_333_333
            time.sleep(max(0, due - time.monotonic_ns()) / 1e9)
            yield Frame(i, f.rgb, f.depth, time.monotonic_ns(), f.t_sensor_ns)


def test_garbage_on_the_mavlink_link_is_ignored_and_counted(tmp_path: Path) -> None:
    cam = CameraIntrinsics.xtion(320, 240)
    port = free_udp_port()
    path = SimPath(waypoints_enu=((0.0, 0.0, 2.5), (0.3, 0.0, 2.5), (0.3, 0.3, 2.5)), speed_m_s=0.2)
    junk = b"not mavlink at all; " * 3  # no 0xFD/0xFE: every byte is a bad prefix byte
    bad_crc = bytes([0xFD, 9, 0, 0, 7, 1, 1, 0, 0, 0]) + bytes(9) + b"\x12\x34"
    injected = {"junk": 0, "bad": 0}
    stop = threading.Event()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", path) as ap:

        def inject() -> None:
            while not stop.wait(0.05):
                ap.inject_garbage(junk)
                injected["junk"] += 1
                if injected["junk"] % 5 == 0:
                    ap.inject_garbage(bad_crc)
                    injected["bad"] += 1

        # pose_wait_s: each frame waits (held, never the capture thread) for the telemetry
        # after it; long enough here for a loaded machine, whose in-process simulator and
        # receiver run tenths of a second late: what is tested is that frames are posed.
        cfg = FlightConfig(
            log_prefix=tmp_path / "flight", max_frames=90, health_period_s=0.5, pose_wait_s=3.0
        )
        flight = Flight(cfg, lambda: FloorSource(200, cam), cam, mavlink=f"udpin:127.0.0.1:{port}")
        injector = threading.Thread(target=inject, daemon=True)
        injector.start()
        try:
            summary = flight.run()
        finally:
            stop.set()
            injector.join()
    tel = summary.telemetry
    c = summary.counters
    print(
        f"\ngarbage: injected {injected}, counted {tel['bad_bytes']} bytes, "
        f"{tel['bad_packets']} bad packets; frames {c.frames_captured}, unposed "
        f"{c.frames_unposed}, holes {[h.sightings for h in summary.holes]}"
    )
    # Every junk byte counted (the last few injections may come after the link closed).
    assert tel["bad_bytes"] % len(junk) == 0
    assert injected["junk"] - 10 <= tel["bad_bytes"] // len(junk) <= injected["junk"]
    assert injected["bad"] - 2 <= tel["bad_packets"] <= injected["bad"]
    # The link kept working: every frame logged, (nearly) all posed, the hole found.
    assert summary.frames_logged == c.frames_captured == 90 and c.frames_log_dropped == 0
    assert c.frames_unposed <= 30, c
    # The hole found from what the detector read (as many frames as a loaded machine
    # lets it): one sighting of the one hole per detection on a posed frame.
    posed_detections = c.detections - c.pose_refusals
    assert len(summary.holes) == 1 and posed_detections >= 3, c
    assert summary.holes[0].sightings >= 0.8 * posed_detections, (summary.holes, c)
    health = [
        r.values
        for r in read_flight_log(summary.log.files, kinds={LoggedHealth})
        if isinstance(r, LoggedHealth) and "mavlink_bad_bytes" in r.values
    ]
    assert health and health[-1]["mavlink_bad_bytes"] > 0
    assert health[-1]["mavlink_bad_packets"] >= 1


def test_fly_config_is_a_frozen_record() -> None:
    cfg = parse_fly_config({"log_dir": "/tmp/x"})
    assert isinstance(cfg, FlyConfig)
    with pytest.raises(AttributeError):
        cfg.sysid = 2  # type: ignore[misc]
