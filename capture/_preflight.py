"""The pre-flight check: GO / NO-GO per item before take-off, as QGroundControl's checklist.

:func:`preflight` looks at what a flight configured by a :class:`~capture._flyconfig.FlyConfig`
needs, item by item, and says for each GO, NO-GO, WARN (flies, but look at it) or SKIP (not
configured):

``sensor``
    the frame source opens and streams: a first frame within ``sensor_s`` (the Xtion through
    OpenNI2, a recording, or the simulator's), with the share of pixels that have depth.
``autopilot``
    a heartbeat on the MAVLink link (on a signed link: a correctly signed one).
``clock``
    TIMESYNC answered, so frames are placed on the autopilot's clock.
``autopilot ready``
    the autopilot is initialised: a parameter reads back (PARAM_REQUEST_READ, index 0) and
    the mission storage answers (MISSION_REQUEST_LIST -> MISSION_COUNT). An autopilot just
    after boot answers neither, and refuses an upload with MAV_MISSION_NO_SPACE while its
    mission storage is not sized (ArduPilot SITL, README "SITL"): uploads retry on it
    (:func:`missions.upload_mission`).
``gps``
    GPS_RAW_INT reports a 3-D fix.
``mount and camera``
    the camera's intrinsics are plausible and the mount looks down (within 60 degrees of
    straight down: the survey plans and the hole geometry assume a downward camera).
``disk``
    room on the log folder's file system for the planned flight (:func:`disk_item`).
``signing``
    the MAVLink signing key, when one is configured.
``ground station``
    a ground station's heartbeat on the ``gcs`` link when one is configured, else heard
    through the autopilot (WARN when not: the holes may reach nobody).

:func:`require_go` is what ``holescan fly`` runs before flying: the sensor and the autopilot
(``bench=True`` flies without them, logged as a bench test).
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

from holescan.capture._flyconfig import FlyConfig
from holescan.capture._mavlink import COMPANION_COMPONENT, Telemetry
from holescan.capture._preflightitems import (
    CheckItem,
    PreflightReport,
    disk_item,
    mount_item,
    signing_item,
)
from holescan.capture._sensorloop import close_quietly, frames_with_timeout
from holescan.capture._sensorsetup import SensorSetup, open_sensor
from holescan.capture.errors import CaptureError, SensorError
from holescan.errors import HolescanError
from holescan.link import TelemetryError, mavlink, open_link

__all__ = [
    "ITEMS",
    "PreflightError",
    "PreflightLimits",
    "preflight",
    "require_go",
]

ITEMS: Final = (
    "sensor",
    "autopilot",
    "clock",
    "autopilot ready",
    "gps",
    "mount and camera",
    "disk",
    "signing",
    "ground station",
)
"""Every item :func:`preflight` reports, in the order it reports them."""

_GPS_3D: Final = 3


class PreflightError(CaptureError):
    """``holescan fly`` refused to start: an item it needs is NO-GO (one line says which)."""


@dataclass(frozen=True)
class PreflightLimits:
    """How long each item may take to answer, s (a check takes a few seconds in all)."""

    sensor_s: float = 6.0
    heartbeat_s: float = 5.0
    timesync_s: float = 3.0
    ready_s: float = 3.0
    fix_s: float = 3.0
    gcs_s: float = 3.0


class _Heard:
    """What the check waits for on the telemetry link (fed from its receiver thread)."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.param: tuple[str, float] | None = None
        self.mission_count: int | None = None
        self.gcs_heartbeats = 0

    def on_message(self, msg: Any, _t_mono_ns: int) -> None:
        kind = msg.get_type()
        with self.cond:
            if kind == "PARAM_VALUE":
                value = float(msg.param_value)
                name = msg.param_id
                name = name.decode(errors="replace") if isinstance(name, bytes) else str(name)
                if math.isfinite(value):
                    self.param = (name.rstrip("\x00")[:16], value)
            elif kind == "MISSION_COUNT" and getattr(msg, "mission_type", 0) == 0:
                if 0 <= int(msg.count) <= 65535:
                    self.mission_count = int(msg.count)
            elif kind == "HEARTBEAT" and msg.type == mavlink.MAV_TYPE_GCS:
                self.gcs_heartbeats += 1
            else:
                return
            self.cond.notify_all()

    def wait(self, ready: Callable[[], bool], timeout_s: float, resend: Callable[[], None]) -> bool:
        """Wait until ``ready()``, calling ``resend()`` now and every 0.5 s."""
        deadline = time.monotonic() + timeout_s
        next_send = 0.0
        with self.cond:
            while not ready():
                now = time.monotonic()
                if now >= deadline:
                    return False
                if now >= next_send:
                    self.cond.release()
                    try:
                        resend()
                    finally:
                        self.cond.acquire()
                    next_send = now + 0.5
                self.cond.wait(min(deadline, next_send) - now)
            return True


def _wait_until(ready: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not ready():
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.05)
    return True


def _sensor_item(setup: SensorSetup | None, why_none: str, limits: PreflightLimits) -> CheckItem:
    if setup is None:
        return CheckItem("sensor", "NO-GO", why_none)
    stop = threading.Event()
    t0 = time.monotonic()
    try:
        source = setup.factory()
        source.__enter__()
    except HolescanError as err:
        return CheckItem("sensor", "NO-GO", str(err))
    try:
        frame = next(iter(frames_with_timeout(source, limits.sensor_s, stop)), None)
    except SensorError as err:
        return CheckItem("sensor", "NO-GO", str(err))
    finally:
        stop.set()
        close_quietly(source)
    if frame is None:
        return CheckItem("sensor", "NO-GO", "the source ended before its first frame")
    h, w = frame.depth.shape
    ranged = float(np.count_nonzero(frame.depth)) / max(frame.depth.size, 1)
    detail = (
        f"{w}x{h}, first frame after {time.monotonic() - t0:.1f} s, "
        f"{100 * ranged:.0f} % of pixels ranged"
    )
    if ranged < 0.2:  # sunlight on the infrared projector, a covered lens, or too close
        return CheckItem("sensor", "WARN", detail + " (sunlight, a covered lens, or too close?)")
    return CheckItem("sensor", "GO", detail)


def _gcs_item(cfg: FlyConfig, heard: _Heard | None, limits: PreflightLimits) -> CheckItem:
    if cfg.gcs is None:
        if heard is None:
            return CheckItem("ground station", "SKIP", "no gcs link and no autopilot link")
        with heard.cond:
            n = heard.gcs_heartbeats
        if n:
            return CheckItem("ground station", "GO", "heard through the autopilot")
        return CheckItem(
            "ground station", "WARN", "no ground-station heartbeat through the autopilot"
        )
    try:
        conn = open_link(
            cfg.gcs,
            source_system=cfg.sysid,
            source_component=COMPANION_COMPONENT,
            signing=cfg.signing,
        )
    except Exception as err:  # pymavlink raises OSError, ValueError, SerialException ...
        return CheckItem("ground station", "NO-GO", f"cannot open {cfg.gcs!r}: {err}")
    try:
        deadline = time.monotonic() + limits.gcs_s
        while time.monotonic() < deadline:
            conn.mav.heartbeat_send(
                mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
            )
            msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if msg is not None and msg.type == mavlink.MAV_TYPE_GCS:
                return CheckItem(
                    "ground station", "GO", f"system {msg.get_srcSystem()} on {cfg.gcs}"
                )
    except OSError as err:
        return CheckItem("ground station", "NO-GO", f"{cfg.gcs}: {err}")
    finally:
        conn.close()
    signed = " (signed: does it hold the same key?)" if cfg.signing else ""
    return CheckItem(
        "ground station", "NO-GO", f"no heartbeat on {cfg.gcs} in {limits.gcs_s:g} s{signed}"
    )


@contextlib.contextmanager
def _autopilot(
    cfg: FlyConfig, setup: SensorSetup | None, limits: PreflightLimits, out: list[CheckItem]
) -> Iterator[tuple[Telemetry, _Heard] | None]:
    """The telemetry link for the autopilot items (None, with the item NO-GO, without one)."""
    link = setup.mavlink if setup is not None else cfg.mavlink
    if link is None:
        out.append(
            CheckItem(
                "autopilot",
                "NO-GO",
                "no autopilot link configured (--mavlink, or mavlink in fly.toml)",
            )
        )
        yield None
        return
    heard = _Heard()
    key = cfg.signing.key if cfg.signing is not None and not cfg.gcs else None
    tel = Telemetry(
        link,
        baud=cfg.baud,
        heartbeat_timeout_s=limits.heartbeat_s,
        on_message=heard.on_message,
        signing_key=key,
    )
    try:
        tel.__enter__()
    except TelemetryError as err:
        hint = " (signed link: does the autopilot hold the same key?)" if key else ""
        out.append(CheckItem("autopilot", "NO-GO", f"{err}{hint}"))
        yield None
        return
    try:
        sysid, compid = tel.target or (0, 0)
        out.append(CheckItem("autopilot", "GO", f"system {sysid}/{compid} on {link}"))
        if setup is not None and setup.on_telemetry is not None:
            setup.on_telemetry(tel)
        yield tel, heard
    finally:
        tel.close()


def _clock_item(tel: Telemetry, limits: PreflightLimits) -> CheckItem:
    synced = _wait_until(lambda: tel.stats().timesync_received > 0, limits.timesync_s)
    source = tel.clock.source
    if synced and source == "timesync":
        return CheckItem(
            "clock",
            "GO",
            f"TIMESYNC, uncertainty {tel.clock.uncertainty_ns / 1e6:.2f} ms",
        )
    if source == "arrival":
        return CheckItem(
            "clock", "WARN", "no TIMESYNC answer: frames timed by message arrival (less exact)"
        )
    return CheckItem("clock", "NO-GO", f"no TIMESYNC answer in {limits.timesync_s:g} s")


def _ready_item(tel: Telemetry, heard: _Heard, limits: PreflightLimits) -> CheckItem:
    sysid, compid = tel.target or (0, 0)

    def ask_param() -> None:
        tel.send_with(lambda mav: mav.param_request_read_send(sysid, compid, b"", 0))

    def ask_mission() -> None:
        tel.send_with(
            lambda mav: mav.mission_request_list_send(
                sysid, compid, mavlink.MAV_MISSION_TYPE_MISSION
            )
        )

    if not heard.wait(lambda: heard.param is not None, limits.ready_s, ask_param):
        return CheckItem(
            "autopilot ready",
            "NO-GO",
            f"no parameter read back in {limits.ready_s:g} s: still initialising?",
        )
    if not heard.wait(lambda: heard.mission_count is not None, limits.ready_s, ask_mission):
        return CheckItem(
            "autopilot ready",
            "NO-GO",
            f"mission storage did not answer in {limits.ready_s:g} s: still initialising?",
        )
    assert heard.param is not None
    name, value = heard.param
    return CheckItem(
        "autopilot ready",
        "GO",
        f"parameters readable ({name} = {value:g}), mission storage holds "
        f"{heard.mission_count} items",
    )


def _gps_item(tel: Telemetry, limits: PreflightLimits) -> CheckItem:
    def fixed() -> bool:
        gps = tel.latest_gps()
        return gps is not None and gps.fix_type >= _GPS_3D

    _wait_until(fixed, limits.fix_s)
    gps = tel.latest_gps()
    if gps is None:
        return CheckItem("gps", "NO-GO", f"no GPS_RAW_INT from the autopilot in {limits.fix_s:g} s")
    sats = f"{gps.satellites} satellites" if gps.satellites >= 0 else "satellites unknown"
    acc = f", h_acc {gps.h_acc_m:.1f} m" if math.isfinite(gps.h_acc_m) else ""
    if gps.fix_type < _GPS_3D:
        return CheckItem("gps", "NO-GO", f"no 3-D fix (fix_type {gps.fix_type}, {sats})")
    return CheckItem("gps", "GO", f"3-D fix (fix_type {gps.fix_type}), {sats}{acc}")


def _open_setup(cfg: FlyConfig, setup: SensorSetup | None) -> tuple[SensorSetup | None, str]:
    if setup is not None:
        return setup, ""
    try:
        return open_sensor(cfg), ""
    except HolescanError as err:
        return None, str(err)


def preflight(
    cfg: FlyConfig,
    setup: SensorSetup | None = None,
    *,
    items: Collection[str] = ITEMS,
    limits: PreflightLimits | None = None,
) -> PreflightReport:
    """Check what the flight ``cfg`` needs; see the module docstring for the items.

    ``setup`` : the sensor and link to check (None: :func:`capture.open_sensor` of ``cfg``;
    the simulator hands its own, :func:`sim.check_sim`). ``items`` : a subset of
    :data:`ITEMS` (in any order; reported in :data:`ITEMS`' order).
    """
    unknown = set(items) - set(ITEMS)
    if unknown:
        raise ValueError(f"unknown pre-flight items {sorted(unknown)}; known: {list(ITEMS)}")
    limits = limits or PreflightLimits()
    setup, why = _open_setup(cfg, setup) if "sensor" in items else (setup, "")
    found: list[CheckItem] = []
    needs_link = {"autopilot", "clock", "autopilot ready", "gps", "ground station"}
    heard: _Heard | None = None
    if needs_link & set(items):
        with _autopilot(cfg, setup, limits, found) as link:
            if link is not None:
                tel, heard = link
                if "clock" in items:
                    found.append(_clock_item(tel, limits))
                if "autopilot ready" in items:
                    found.append(_ready_item(tel, heard, limits))
                if "gps" in items:
                    found.append(_gps_item(tel, limits))
            else:
                for name in ("clock", "autopilot ready", "gps"):
                    if name in items:
                        found.append(CheckItem(name, "SKIP", "no autopilot link"))
            if "sensor" in items:  # with the link up: a simulated camera may fly on it
                found.append(_sensor_item(setup, why, limits))
    elif "sensor" in items:
        found.append(_sensor_item(setup, why, limits))
    if "mount and camera" in items:
        found.append(mount_item(cfg, setup.camera if setup is not None else None))
    if "disk" in items:
        found.append(disk_item(cfg))
    if "signing" in items:
        found.append(signing_item(cfg))
    if "ground station" in items:
        found.append(_gcs_item(cfg, heard, limits))
    if "autopilot" not in items:
        found = [i for i in found if i.name != "autopilot"]
    order = {name: k for k, name in enumerate(ITEMS)}
    return PreflightReport(tuple(sorted(found, key=lambda i: order[i.name])))


def require_go(
    cfg: FlyConfig, setup: SensorSetup | None = None, *, limits: PreflightLimits | None = None
) -> PreflightReport:
    """What ``holescan fly`` checks before flying: the sensor streams and the autopilot
    answers. Raises :class:`PreflightError` (one line: the NO-GO items and the way out)."""
    report = preflight(cfg, setup, items=("sensor", "autopilot"), limits=limits)
    if not report.go:
        raise PreflightError(
            f"NO-GO: {report.no_go_line()} (holescan check lists every item; "
            "--bench flies without a sensor or autopilot)"
        )
    return report
