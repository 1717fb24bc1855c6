"""The pre-flight check (``holescan check``, ``fly --check``) and ``fly``'s refusal to fly
without a sensor or an autopilot: the real OpenNI2 library (which finds no Xtion here) and
the pymavlink simulated autopilot on loopback."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from holescan.capture import (
    ITEMS,
    FlyConfig,
    PreflightError,
    PreflightLimits,
    SensorSetup,
    SensorSpec,
    find_xtion,
    preflight,
    require_go,
)
from holescan.cli import main
from holescan.detect import CameraIntrinsics, Frame
from holescan.link import SigningKey
from holescan.missions import MissionReceiver, Waypoint, upload_mission
from holescan.sim import SimAutopilot, SimPath
from tests._support import free_udp_port

CAM = CameraIntrinsics.xtion()
FAST = PreflightLimits(sensor_s=3.0, heartbeat_s=2.0, timesync_s=2.0, ready_s=2.0, fix_s=2.0)
HOVER = SimPath(waypoints_enu=((0.0, 0.0, 2.5), (0.3, 0.0, 2.5), (0.3, 0.3, 2.5)), speed_m_s=0.2)
no_xtion = pytest.mark.skipif(bool(find_xtion()), reason="an Xtion is attached to this machine")


class FloorSource:
    """A flat floor 2.5 m below at 30 fps, ``ranged`` of its pixels with depth."""

    camera = CAM

    def __init__(self, ranged: float = 1.0) -> None:
        self.ranged = ranged

    def __enter__(self) -> FloorSource:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def __iter__(self) -> Iterator[Frame]:
        depth = np.full((CAM.height, CAM.width), 2500, np.uint16)
        depth[: round(CAM.height * (1 - self.ranged))] = 0
        rgb = np.full((CAM.height, CAM.width, 3), 80, np.uint8)
        for i in range(100):
            time.sleep(1 / 30)
            yield Frame(i, rgb, depth, time.monotonic_ns(), i * 33_333_333)


def config(tmp_path: Path, **kw: object) -> FlyConfig:
    return FlyConfig(sensor=SensorSpec("openni2"), log_dir=tmp_path / "logs", **kw)  # type: ignore[arg-type]


@no_xtion
def test_fly_without_sensor_or_autopilot_is_no_go_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["fly", "--log-dir", str(tmp_path / "logs"), "--duration", "8"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert err.startswith("holescan fly: error: NO-GO: sensor: no Xtion found on USB"), err
    assert "autopilot: no autopilot link configured" in err and "--bench" in err
    assert not list(tmp_path.glob("logs/*.mcap"))  # nothing flown, no empty log left


@no_xtion
def test_check_lists_every_item_as_json_and_exits_1_on_no_go(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    port = free_udp_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", HOVER):
        argv = ["check", "--json", "--log-dir", str(tmp_path), "--mavlink"]
        code = main([*argv, f"udpin:127.0.0.1:{port}"])
    out, err = capsys.readouterr()
    doc = json.loads(out)
    status = {i["name"]: i["status"] for i in doc["items"]}
    assert [i["name"] for i in doc["items"]] == list(ITEMS)
    assert code == 1 and doc["go"] is False
    assert status == {
        "sensor": "NO-GO",  # the real OpenNI2 library finds no Xtion
        "autopilot": "GO",
        "clock": "GO",
        "autopilot ready": "GO",
        "gps": "GO",
        "mount and camera": "GO",
        "disk": "GO",
        "signing": "SKIP",
        "ground station": "WARN",  # no ground station heard through the autopilot
    }, doc
    assert err.startswith("holescan check: NO-GO: sensor: no Xtion") and err.count("\n") == 1


def test_everything_go_with_a_streaming_sensor_and_a_ready_autopilot(tmp_path: Path) -> None:
    port = free_udp_port()
    link = f"udpin:127.0.0.1:{port}"
    with SimAutopilot(f"udpout:127.0.0.1:{port}", HOVER, sysid=7):
        report = preflight(config(tmp_path), SensorSetup(FloorSource, CAM, link), limits=FAST)
    assert report.go, report
    assert report.item("autopilot").detail == f"system 7/1 on {link}"
    assert report.item("autopilot ready").detail.startswith("parameters readable (MIS_TOTAL = 0)")
    assert "100 % of pixels ranged" in report.item("sensor").detail
    assert report.item("gps").detail.startswith("3-D fix")


def test_an_autopilot_still_initialising_without_a_fix_is_no_go(tmp_path: Path) -> None:
    port = free_udp_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", HOVER, gps_fix=False) as ap:
        ap.params = None  # as just after boot: its parameters are not loaded yet
        setup = SensorSetup(lambda: FloorSource(ranged=0.1), CAM, f"udpin:127.0.0.1:{port}")
        report = preflight(config(tmp_path), setup, limits=FAST)
    assert not report.go
    assert report.item("autopilot ready").status == "NO-GO"
    assert "still initialising" in report.item("autopilot ready").detail
    assert report.item("gps").status == "NO-GO" and "no 3-D fix" in report.item("gps").detail
    assert report.item("sensor").status == "WARN"  # 10 % ranged: sunlight on the projector?


def test_a_silent_autopilot_a_bad_mount_and_a_full_plan_are_no_go(tmp_path: Path) -> None:
    from holescan.capture import FlightConfig
    from holescan.geotag import CameraMount

    sideways = FlightConfig(log_prefix=Path("flight"), mount=CameraMount.from_euler_deg(0, 0, 0))
    cfg = config(tmp_path, mavlink=f"udpin:127.0.0.1:{free_udp_port()}", flight=sideways)
    cfg = FlyConfig(**{**cfg.__dict__, "duration_s": 1e9})  # more than any card holds
    report = preflight(cfg, SensorSetup(FloorSource, CAM, cfg.mavlink), limits=FAST)
    assert report.item("autopilot").status == "NO-GO"
    assert "no autopilot heartbeat" in report.item("autopilot").detail
    assert report.item("mount and camera").status == "NO-GO"
    assert "90 deg from straight down" in report.item("mount and camera").detail
    assert report.item("disk").status == "NO-GO" and "does NOT fit" in report.item("disk").detail


def test_require_go_passes_a_flight_with_both_and_names_the_missing_one(tmp_path: Path) -> None:
    port = free_udp_port()
    with SimAutopilot(f"udpout:127.0.0.1:{port}", HOVER):
        setup = SensorSetup(FloorSource, CAM, f"udpin:127.0.0.1:{port}")
        assert [i.name for i in require_go(config(tmp_path), setup, limits=FAST).items] == [
            "sensor",
            "autopilot",
        ]
    with pytest.raises(PreflightError, match=r"^NO-GO: autopilot: no autopilot link configured"):
        require_go(config(tmp_path), SensorSetup(FloorSource, CAM, None), limits=FAST)


def test_the_ground_station_is_checked_on_its_own_signed_link(tmp_path: Path) -> None:
    from holescan.link import mavlink, open_link

    key = SigningKey.from_passphrase("rubble")
    port = free_udp_port()
    gcs = open_link(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190, signing=key)
    stop = threading.Event()

    def answer() -> None:  # a ground station: heartbeats back to whoever spoke to it
        while not stop.is_set():
            if gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2) is not None:
                gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    threading.Thread(target=answer, daemon=True).start()
    try:
        signed = config(tmp_path, gcs=f"udpout:127.0.0.1:{port}", signing=key)
        report = preflight(signed, items=("ground station", "signing"), limits=FAST)
        assert report.item("ground station").status == "GO", report
        assert (
            report.item("signing").detail == f"key {key.fingerprint} signs the ground-station link"
        )
        wrong = config(
            tmp_path, gcs=f"udpout:127.0.0.1:{port}", signing=SigningKey.from_passphrase("x")
        )
        report = preflight(wrong, items=("ground station",), limits=FAST)
        assert report.item("ground station").status == "NO-GO"
        assert "same key" in report.item("ground station").detail
    finally:
        stop.set()
        time.sleep(0.3)
        gcs.close()


def test_an_upload_just_after_boot_waits_for_the_mission_storage() -> None:
    """ArduPilot SITL answered MAV_MISSION_NO_SPACE seconds after boot: the upload asks
    again until the storage is sized, instead of failing the sortie."""
    port = free_udp_port()
    home = Waypoint(43.0, -79.0, 0.0)
    items = [Waypoint(43.0 + k * 1e-5, -79.0, 10.0) for k in range(1, 4)]
    receiver = MissionReceiver(capacity=0)  # not sized yet
    with SimAutopilot(f"udpin:127.0.0.1:{port}", HOVER, mission=receiver):
        sized = threading.Timer(1.5, lambda: setattr(receiver, "capacity", 700))
        sized.start()
        report = upload_mission(f"udpout:127.0.0.1:{port}", items, home, no_space_wait_s=8.0)
        sized.join()
    assert report.items == 4 and len(receiver.mission) == 4
    assert report.elapsed_s >= 1.0  # it waited for the storage (not a speed bound)


@pytest.mark.slow
def test_check_of_the_simulated_sortie_is_go(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", "--sensor", "sim", "--log-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "pre-flight: GO" in out and "NO-GO" not in out


def test_the_udev_rule_covers_every_xtion_for_the_service_group() -> None:
    import configparser
    import re

    from holescan.capture._usb import XTION_PRODUCTS, XTION_VENDOR_ID

    deploy = Path(__file__).resolve().parents[2] / "deploy"
    rules = [
        line
        for line in (deploy / "99-xtion.rules").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]
    products = set()
    for rule in rules:
        keys = dict(re.findall(r'(\w+(?:\{[\w/]+\})?)=?="([^"]*)"', rule))
        assert keys["SUBSYSTEM"] == "usb" and int(keys["ATTR{idVendor}"], 16) == XTION_VENDOR_ID
        assert keys["MODE"] == "0660" and keys["ATTR{power/control}"] == "on"
        products.add(int(keys["ATTR{idProduct}"], 16))
        group = keys["GROUP"]
    assert products == set(XTION_PRODUCTS)
    unit = configparser.ConfigParser(strict=True, interpolation=None)
    unit.read(deploy / "holescan.service")
    assert group in unit["Service"]["SupplementaryGroups"].split()
