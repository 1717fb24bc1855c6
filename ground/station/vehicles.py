"""The vehicles a ground station hears: where each is, what it is doing, how well it is heard.

One :class:`VehicleStatus` per MAVLink system id, filled from what the autopilot sends on
the station's own link (:class:`~ground.station.link.VehicleLink`), every value checked
first (:mod:`link._values`; a refused one is counted and nothing of its packet kept):

* ``HEARTBEAT``: flight mode (:func:`pymavlink.mavutil.mode_string_v10`), armed
  (``MAV_MODE_FLAG_SAFETY_ARMED``), vehicle type;
* ``GLOBAL_POSITION_INT``: position, MSL altitude, height above home, ground speed;
* ``ATTITUDE``: roll, pitch, yaw (the heading shown);
* ``SYS_STATUS`` / ``BATTERY_STATUS`` (the latter wins when both come): voltage,
  current, charge left;
* ``RADIO_STATUS`` (a SiK radio on the way): RSSI here and at the other end;
* ``HOME_POSITION``: the launch point (distances and bearings "from home");
* ``MOUNT_ORIENTATION``: the camera mount's angles, when the vehicle tells them (else the
  camera is taken as looking straight down, as holescan flies it);
* every packet of the system: link quality (:class:`LinkQuality`: packets lost from the
  gaps in each component's sequence numbers, overall and over the last 10 s) and the time
  it was last heard.

:func:`camera_footprint` is the ground the Xtion sees now (its 58 x 45 degree field of
view through the mount and the attitude onto flat ground at the height above home).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from holescan.link import (
    home_from_home_position,
    link_float,
    link_int,
    link_lat_lon,
    link_yaw,
    mavlink,
    mavutil,
    position_from_global_position_int,
    xml_text,
)
from holescan.missions import XTION, Camera

__all__ = [
    "LOSS_WINDOW_S",
    "LinkQuality",
    "VehicleStatus",
    "camera_footprint",
]

LOSS_WINDOW_S = 10.0
"""The window of the recent packet loss, seconds."""
_ALT_M = (-1000.0, 10_000.0)
_UINT16_UNKNOWN = 65535


@dataclass
class LinkQuality:
    """Packets heard and lost (sequence gaps, per component) on the station's link.

    ``received`` and ``lost`` count since the station started; :meth:`recent_loss` is the
    share lost over the last :data:`LOSS_WINDOW_S` seconds (None: nothing heard then).
    A gap of more than 128 (a component restarted, or packets from an impostor with the
    same ids) counts as a restart, not as loss.
    """

    received: int = 0
    lost: int = 0
    _seq: dict[int, int] = field(default_factory=dict)
    _window: deque[tuple[float, int]] = field(default_factory=deque)

    def on_packet(self, compid: int, seq: int, t_mono_s: float) -> None:
        last = self._seq.get(compid)
        gap = 0 if last is None else (seq - last - 1) % 256
        if gap > 128:
            gap = 0
        self._seq[compid] = seq
        self.received += 1
        self.lost += gap
        self._window.append((t_mono_s, gap))
        while self._window and self._window[0][0] < t_mono_s - LOSS_WINDOW_S:
            self._window.popleft()

    def recent_loss(self) -> float | None:
        """Share of packets lost over the window (0..1), None when none were heard."""
        if not self._window:
            return None
        lost = sum(g for _, g in self._window)
        return lost / (lost + len(self._window))


@dataclass
class VehicleStatus:
    """One vehicle as the station knows it now (None: not told yet).

    sysid : its MAVLink system id. links : the station's links it is heard on.
    mode, armed, mav_type : from its HEARTBEAT. lat_deg, lon_deg, alt_m (MSL),
    rel_alt_m (above home), groundspeed_m_s : GLOBAL_POSITION_INT. roll, pitch, yaw :
    ATTITUDE, rad (yaw from north, clockwise). battery_v, battery_a, battery_pct :
    SYS_STATUS or BATTERY_STATUS. rssi, remote_rssi : RADIO_STATUS (0..254).
    home : (lat_deg, lon_deg, alt_m MSL) of HOME_POSITION. mount_deg : (roll, pitch, yaw)
    of MOUNT_ORIENTATION, degrees (None: nadir). t_heard_unix_ns : when any packet of it
    was last heard; t_position_unix_ns : its last position.
    """

    sysid: int
    links: list[str] = field(default_factory=list)
    mode: str | None = None
    armed: bool | None = None
    mav_type: int | None = None
    lat_deg: float | None = None
    lon_deg: float | None = None
    alt_m: float | None = None
    rel_alt_m: float | None = None
    groundspeed_m_s: float | None = None
    roll: float | None = None
    pitch: float | None = None
    yaw: float | None = None
    battery_v: float | None = None
    battery_a: float | None = None
    battery_pct: int | None = None
    battery_from: str | None = None
    rssi: int | None = None
    remote_rssi: int | None = None
    home: tuple[float, float, float] | None = None
    mount_deg: tuple[float, float, float] | None = None
    t_heard_unix_ns: int = 0
    t_position_unix_ns: int = 0
    quality: LinkQuality = field(default_factory=LinkQuality)

    def copy(self) -> VehicleStatus:
        """A copy the station can hand out (its link counters are not shared)."""
        q = self.quality
        return dataclasses.replace(
            self,
            links=list(self.links),
            quality=LinkQuality(q.received, q.lost, dict(q._seq), deque(q._window)),
        )

    def take(self, msg: Any) -> bool:
        """Take what ``msg`` (a message of this system) says; True when it told something
        the page shows. Raises :class:`link.LinkValueError` for a value out of range
        (nothing of the message is kept)."""
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            return self._heartbeat(msg)
        if kind == "GLOBAL_POSITION_INT":
            p = position_from_global_position_int(msg)
            lat, lon = link_lat_lon(p.lat_deg, p.lon_deg)
            if lat == 0 and lon == 0:  # no fix yet
                return False
            alt = link_float(p.alt_m, *_ALT_M, "altitude")
            rel = link_float(p.rel_alt_m, *_ALT_M, "height above home")
            gs = link_float(math.hypot(p.vn, p.ve), 0.0, 400.0, "ground speed")
            self.lat_deg, self.lon_deg, self.alt_m, self.rel_alt_m = lat, lon, alt, rel
            self.groundspeed_m_s = gs
            return True
        if kind == "ATTITUDE":
            roll = link_float(msg.roll, -math.pi, math.pi, "roll")
            pitch = link_float(msg.pitch, -math.pi, math.pi, "pitch")
            self.roll, self.pitch, self.yaw = roll, pitch, link_yaw(msg.yaw)
            return False  # drawn with the next position
        if kind == "SYS_STATUS":
            if self.battery_from == "BATTERY_STATUS":
                return False
            v = link_int(msg.voltage_battery, 0, _UINT16_UNKNOWN, "battery voltage")
            self._battery(
                None if v == _UINT16_UNKNOWN else v / 1000.0,
                link_int(msg.current_battery, -1, 32767, "battery current"),
                link_int(msg.battery_remaining, -1, 100, "battery remaining"),
                kind,
            )
            return True
        if kind == "BATTERY_STATUS":
            if link_int(msg.id, 0, 255, "battery id") != 0:
                return False
            cells = [link_int(c, 0, _UINT16_UNKNOWN, "cell voltage") for c in msg.voltages]
            mv = sum(c for c in cells if c != _UINT16_UNKNOWN)
            self._battery(
                mv / 1000.0 if mv else None,
                link_int(msg.current_battery, -1, 32767, "battery current"),
                link_int(msg.battery_remaining, -1, 100, "battery remaining"),
                kind,
            )
            return True
        if kind == "RADIO_STATUS":
            rssi = link_int(msg.rssi, 0, 255, "rssi")
            rem = link_int(msg.remrssi, 0, 255, "remote rssi")
            self.rssi = None if rssi == 255 else rssi
            self.remote_rssi = None if rem == 255 else rem
            return False
        if kind == "HOME_POSITION":
            lat, lon, alt = home_from_home_position(msg)
            lat, lon = link_lat_lon(lat, lon)
            home = (lat, lon, link_float(alt, *_ALT_M, "home altitude"))
            changed = home != self.home
            self.home = home
            return changed
        if kind == "MOUNT_ORIENTATION":
            mount = (
                link_float(msg.roll, -180.0, 180.0, "mount roll"),
                link_float(msg.pitch, -180.0, 180.0, "mount pitch"),
                link_float(msg.yaw, -360.0, 360.0, "mount yaw"),
            )
            self.mount_deg = mount
            return False
        return False

    def _heartbeat(self, msg: Any) -> bool:
        mav_type = link_int(msg.type, 0, 255, "vehicle type")
        link_int(msg.autopilot, 0, 255, "autopilot")
        base = link_int(msg.base_mode, 0, 255, "base mode")
        link_int(msg.custom_mode, 0, 2**32 - 1, "custom mode")
        try:
            mode = xml_text(mavutil.mode_string_v10(msg), 24)
        except (KeyError, ValueError, TypeError):  # an unknown vehicle type's table
            mode = f"Mode({int(msg.custom_mode)})"
        armed = bool(base & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        changed = (mode, armed, mav_type) != (self.mode, self.armed, self.mav_type)
        self.mode, self.armed, self.mav_type = mode, armed, mav_type
        return changed

    def _battery(self, volts: float | None, current_ca: int, pct: int, source: str) -> None:
        if volts is not None:
            volts = link_float(volts, 0.0, 100.0, "battery voltage")
        self.battery_v = volts
        self.battery_a = None if current_ca < 0 else current_ca / 100.0
        self.battery_pct = None if pct < 0 else pct
        self.battery_from = source

    def to_json(self, now_unix_ns: int) -> dict[str, Any]:
        """The page's view of it (angles in degrees; ``heard_s_ago``; ``loss_recent``)."""
        q = self.quality

        def deg(a: float | None) -> float | None:
            return None if a is None else round(math.degrees(a), 1)

        return {
            "sysid": self.sysid,
            "links": list(self.links),
            "mode": self.mode,
            "armed": self.armed,
            "lat_deg": self.lat_deg,
            "lon_deg": self.lon_deg,
            "alt_m": self.alt_m,
            "rel_alt_m": self.rel_alt_m,
            "groundspeed_m_s": self.groundspeed_m_s,
            "heading_deg": None if self.yaw is None else round(math.degrees(self.yaw) % 360, 1),
            "roll_deg": deg(self.roll),
            "pitch_deg": deg(self.pitch),
            "battery_v": self.battery_v,
            "battery_a": self.battery_a,
            "battery_pct": self.battery_pct,
            "rssi": self.rssi,
            "remote_rssi": self.remote_rssi,
            "home": list(self.home) if self.home is not None else None,
            "mount_deg": list(self.mount_deg) if self.mount_deg is not None else None,
            "packets": q.received,
            "lost": q.lost,
            "loss_recent": None if (r := q.recent_loss()) is None else round(r, 3),
            "heard_s_ago": (
                None
                if not self.t_heard_unix_ns
                else round(max(0, now_unix_ns - self.t_heard_unix_ns) / 1e9, 1)
            ),
        }


def camera_footprint(
    rel_alt_m: float,
    roll: float,
    pitch: float,
    yaw: float,
    mount_deg: tuple[float, float, float] | None = None,
    camera: Camera = XTION,
    max_range_factor: float = 10.0,
) -> list[tuple[float, float]] | None:
    """The ground the camera sees now: its four corners (east, north) in metres from the
    point below the vehicle, on flat ground ``rel_alt_m`` below it.

    The camera looks along the mount's direction (``mount_deg`` = roll, pitch, yaw of the
    mount from the body, degrees, pitch -90 = down; None: straight down), the image's top
    towards the nose when looking down; the airframe turned by ``roll``, ``pitch``, ``yaw``
    (rad, yaw from north clockwise). A corner ray that does not reach the ground within
    ``max_range_factor`` times the height is cut there. None below 0.2 m.

    Examples
    --------
    Level, heading north, 2 m up: 58 x 45 degrees give 2.22 m across, 1.66 m along.

    >>> c = camera_footprint(2.0, 0.0, 0.0, 0.0)
    >>> [(round(e, 2), round(n, 2)) for e, n in c]
    [(-1.11, 0.83), (1.11, 0.83), (1.11, -0.83), (-1.11, -0.83)]
    """
    if not rel_alt_m > 0.2:
        return None
    tx = math.tan(math.radians(camera.hfov_deg) / 2.0)
    ty = math.tan(math.radians(camera.vfov_deg) / 2.0)
    # camera rays (forward, right, down) with the camera looking forward, image top up:
    # top-left, top-right, bottom-right, bottom-left
    rays = np.array([[1.0, -tx, -ty], [1.0, tx, -ty], [1.0, tx, ty], [1.0, -tx, ty]])
    m = mount_deg if mount_deg is not None else (0.0, -90.0, 0.0)
    mount = Rotation.from_euler("ZYX", [m[2], m[1], m[0]], degrees=True)
    body = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    ned = (body * mount).apply(rays)
    out = []
    reach = max_range_factor * rel_alt_m
    for n, e, d in ned:
        horiz = math.hypot(n, e)
        if d <= 0 or horiz * rel_alt_m / d > reach:  # at or above the horizon: cut
            k = reach / horiz if horiz > 0 else 0.0
        else:
            k = rel_alt_m / d
        out.append((float(e * k), float(n * k)))
    return out
