"""What the autopilot's messages say, as SI records: poses, the clock, and its reboots.

:class:`VehicleState` is the receive side of :class:`capture._mavlink.Telemetry`: the
receiver thread hands it each message from the autopilot, and it converts units once
(:func:`link._adapt.telemetry_sample`) into the :class:`~link._posebuffer.PoseBuffer`
and keeps the :class:`~capture._clock.ClockSync` up to date: the arrival times of stamped
messages, SYSTEM_TIME for UTC, and our TIMESYNC round trips. A boot clock that goes back is
an autopilot reboot: the clock sync is reset and ``on_reboot`` called (the rates must be
asked for again). Its heartbeats give the flight mode and whether it is armed (recorded in
the health records; nothing in capture, detection or announcement depends on them).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import Any

from holescan.capture._clock import ClockSync
from holescan.capture.errors import ClockUnavailable
from holescan.link import (
    AttitudeSample,
    GpsFix,
    NavStatus,
    PoseBuffer,
    PositionSample,
    mavlink,
    mavutil,
    telemetry_sample,
)

_log = logging.getLogger("holescan.capture._mavlink")

_NS_PER_MS = 1_000_000
# A boot clock this far behind the newest seen is a reboot, not reordering.
_REBOOT_STEP_NS = 2_000_000_000
# A TIMESYNC request unanswered this long is lost.
_TIMESYNC_LOST_NS = 2_000_000_000


class VehicleState:
    """Pose buffer and clock sync fed from the autopilot's messages (one writer thread).

    on_sample : called after each position or attitude sample (wake waiting readers).
    on_reboot : called when the autopilot's boot clock went back.
    """

    def __init__(
        self,
        poses: PoseBuffer,
        clock: ClockSync,
        *,
        on_sample: Callable[[], None],
        on_reboot: Callable[[], None],
    ) -> None:
        self.poses = poses
        self.clock = clock
        self._on_sample = on_sample
        self._on_reboot = on_reboot
        self.reboots = 0
        self.timesync_sent = 0
        self.timesync_received = 0
        self._last_boot_ns: int | None = None
        self._outstanding: dict[int, int] = {}  # TIMESYNC ts1 -> t0 (same value)
        self.mode = ""  # pymavlink's name of the autopilot's flight mode ("AUTO", "RTL" ...)
        self.armed: bool | None = None
        self.mode_changes = 0  # mode or arming changes seen

    def handle(self, mtype: str, msg: Any, t_mono_ns: int) -> None:
        """Take one message of the autopilot's (types this state does not use are ignored)."""
        handler = self._HANDLERS.get(mtype)
        if handler is not None:
            handler(self, msg, t_mono_ns)

    def timesync_request(self, t0_ns: int) -> None:
        """Our TIMESYNC request with ``ts1 = t0_ns`` (companion monotonic) went out."""
        for ts1 in [k for k in self._outstanding if t0_ns - k > _TIMESYNC_LOST_NS]:
            del self._outstanding[ts1]
        self._outstanding[t0_ns] = t0_ns
        self.timesync_sent += 1

    def timesync_reply(self, msg: Any, t_mono_ns: int) -> None:
        """The autopilot's answer (``tc1`` its boot clock, ns) to one of our requests."""
        t0 = self._outstanding.pop(int(msg.ts1), None)
        if t0 is None:  # someone else's exchange (e.g. a GCS on the same router)
            return
        self.timesync_received += 1
        self._check_boot(int(msg.tc1))
        self.clock.add_timesync(t0, t_mono_ns, int(msg.tc1))

    def _stamped(self, t_boot_ns: int, t_mono_ns: int) -> None:
        self._check_boot(t_boot_ns)
        self.clock.add_arrival(t_mono_ns, t_boot_ns)

    def _check_boot(self, t_boot_ns: int) -> None:
        """A boot clock more than 2 s behind the newest seen: the autopilot rebooted."""
        last = self._last_boot_ns
        went_back = last is not None and t_boot_ns < last - _REBOOT_STEP_NS
        if went_back:
            assert last is not None
            _log.warning(
                "autopilot boot time went back %.1f s: reboot, resetting clock sync",
                (last - t_boot_ns) / 1e9,
            )
            self.clock.reset()
            self.reboots += 1
            self._on_reboot()  # a rebooted autopilot forgot the rates
        if last is None or t_boot_ns > last or went_back:
            self._last_boot_ns = t_boot_ns

    def _on_pose_sample(self, msg: Any, t_mono_ns: int) -> None:
        """GLOBAL_POSITION_INT, ATTITUDE or ATTITUDE_QUATERNION: a stamped pose sample."""
        sample = telemetry_sample(msg, 0)
        assert isinstance(sample, (PositionSample, AttitudeSample))
        self._stamped(sample.t_boot_ns, t_mono_ns)
        if isinstance(sample, PositionSample):
            self.poses.add_position(sample)
        else:
            self.poses.add_attitude(sample)
        self._on_sample()

    def _on_gps(self, msg: Any, t_mono_ns: int) -> None:
        """GPS_RAW_INT or an estimator status: stamped with its arrival on the boot clock."""
        try:
            t_boot_ns = self.clock.mono_to_boot_ns(t_mono_ns)
        except ClockUnavailable:
            t_boot_ns = self._last_boot_ns or 0
        sample = telemetry_sample(msg, t_boot_ns)
        if isinstance(sample, GpsFix):
            self.poses.add_gps(sample)
        elif isinstance(sample, NavStatus):
            self.poses.add_nav(sample)

    def _on_system_time(self, msg: Any, t_mono_ns: int) -> None:
        t_boot_ns = int(msg.time_boot_ms) * _NS_PER_MS
        self._stamped(t_boot_ns, t_mono_ns)
        self.clock.add_system_time(t_boot_ns, int(msg.time_unix_usec) * 1000)

    def _on_heartbeat(self, msg: Any, t_mono_ns: int) -> None:
        mode = str(mavutil.mode_string_v10(msg))
        armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if (mode, armed) != (self.mode, self.armed):
            if self.armed is not None:
                self.mode_changes += 1
            _log.info("autopilot: %s, %s", mode, "armed" if armed else "disarmed")
            self.mode, self.armed = mode, armed

    def flight_state(self) -> dict[str, Any]:
        """The autopilot's mode, arming and changes seen, for the health records."""
        return {"mode": self.mode, "armed": self.armed, "mode_changes": self.mode_changes}

    _HANDLERS: Mapping[str, Callable[[VehicleState, Any, int], None]] = {
        "HEARTBEAT": _on_heartbeat,
        "GLOBAL_POSITION_INT": _on_pose_sample,
        "ATTITUDE": _on_pose_sample,
        "ATTITUDE_QUATERNION": _on_pose_sample,
        "GPS_RAW_INT": _on_gps,
        "EKF_STATUS_REPORT": _on_gps,
        "ESTIMATOR_STATUS": _on_gps,
        "SYSTEM_TIME": _on_system_time,
    }
