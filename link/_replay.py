"""Logged raw MAVLink packets -> a :class:`PoseBuffer`, as the live link fills it.

:class:`TelemetryReplay` is log replay's side of the one telemetry decoder: packets go
through the project's MAVLink parser (:func:`link.parser`), the autopilot is the first
heartbeat of a real autopilot (:func:`link.is_autopilot_heartbeat`), and every
message from it goes through :func:`link.telemetry_sample`, the function
:class:`capture.Telemetry` calls on the live link. Pure: no clocks, files or sockets.
"""

from __future__ import annotations

import logging
from typing import Any, Final

from holescan.geotag import VehiclePose
from holescan.link._adapt import home_from_home_position, is_autopilot_heartbeat, telemetry_sample
from holescan.link._connection import mavlink, parser
from holescan.link._posebuffer import AttitudeSample, PoseBuffer
from holescan.link._posevalidity import GpsFix, NavStatus, PositionSample
from holescan.link.errors import PoseUnavailable

__all__ = ["TelemetryReplay"]

_log = logging.getLogger(__name__)

_REPLAY_CAPACITY: Final = 8192


class TelemetryReplay:
    """Feed logged packets in log order with :meth:`feed`; ask poses with :meth:`pose_at`.

    Attributes
    ----------
    poses : the buffer the samples go to.
    target : (system id, component id) of the autopilot once its heartbeat was seen.
    home : (lat_deg, lon_deg, alt_m MSL) of the last HOME_POSITION, or None.
    packets : packets fed.
    """

    def __init__(self, capacity: int = _REPLAY_CAPACITY) -> None:
        self._mav = parser()
        self.poses = PoseBuffer(capacity=capacity)
        self.target: tuple[int, int] | None = None
        self.home: tuple[float, float, float] | None = None
        self.packets = 0
        self._last_boot_ns = 0

    def feed(self, packet: bytes) -> bool:
        """Parse one logged packet; True when it added a position or attitude sample."""
        self.packets += 1
        try:
            msgs = self._mav.parse_buffer(packet) or []
        except mavlink.MAVError:
            return False
        added = False
        for msg in msgs:
            added |= self._handle(msg)
        return added

    def _handle(self, msg: Any) -> bool:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.target is None:
            if is_autopilot_heartbeat(msg):
                self.target = src
            return False
        if src != self.target:
            return False
        if msg.get_type() == "HOME_POSITION":
            self.home = home_from_home_position(msg)
            return False
        try:
            sample = telemetry_sample(msg, self._last_boot_ns)
        except ValueError:
            return False
        if isinstance(sample, PositionSample):
            self._last_boot_ns = max(self._last_boot_ns, sample.t_boot_ns)
            return self.poses.add_position(sample)
        if isinstance(sample, AttitudeSample):
            self._last_boot_ns = max(self._last_boot_ns, sample.t_boot_ns)
            return self.poses.add_attitude(sample)
        if isinstance(sample, GpsFix):
            self.poses.add_gps(sample)
        elif isinstance(sample, NavStatus):
            self.poses.add_nav(sample)
        return False

    def pose_at(self, t_boot_ns: int | None) -> VehiclePose | None:
        """The pose at autopilot boot time ``t_boot_ns``, or None when it cannot be had."""
        if t_boot_ns is None:
            return None
        try:
            return self.poses.pose_at(t_boot_ns)
        except PoseUnavailable as err:
            _log.debug("no pose at boot %d: %s", t_boot_ns, err)
            return None
