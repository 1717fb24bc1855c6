"""The autopilot link of one flight: connected at start, retried while the autopilot is silent,
and the clocks and poses the daemon reads through it.

A flight never waits for its autopilot: when the link opens but nothing answers
(:class:`link.TelemetryTimeoutError`), capture starts anyway with unposed frames and a
background thread keeps connecting until the autopilot speaks; frames are posed from then
on. A link that cannot be opened at all (a bad connection string) is an error.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from holescan.capture._health import AutopilotSilent
from holescan.capture._mavlink import Telemetry
from holescan.capture.errors import ClockUnavailable
from holescan.geotag import VehiclePose
from holescan.link import PoseInvalid, PoseUnavailable, TelemetryTimeoutError

__all__ = ["MessageListener", "TelemetryFactory", "TelemetrySupervisor"]

log = logging.getLogger(__name__)

MessageListener = Callable[[Any, int], None]
"""``on_message(msg, t_mono_ns)``: every parsed MAVLink message, on the receiver thread."""
TelemetryFactory = Callable[..., Telemetry]
"""``factory(connection, on_message=...)``: a :class:`capture.Telemetry`, not entered yet."""


class TelemetrySupervisor:
    """Connects, retries and closes the autopilot link; maps companion time to the autopilot's.

    Parameters
    ----------
    connection : pymavlink connection string; None: a flight without an autopilot (every
        frame unposed, Unix time from the companion's clock).
    factory : makes the :class:`capture.Telemetry` for each attempt.
    on_message : handed to each link (the daemon logs every message and each position).
    on_silent : told when the autopilot did not answer at start (the daemon logs it on
        ``/health``) before the retries begin.
    """

    def __init__(
        self,
        connection: str | None,
        factory: TelemetryFactory = Telemetry,
        *,
        on_message: MessageListener | None = None,
        on_silent: Callable[[AutopilotSilent], None] | None = None,
    ) -> None:
        self.connection = connection
        self._factory = factory
        self._on_message = on_message
        self._on_silent = on_silent
        self._telemetry: Telemetry | None = None
        self._unix_minus_mono = time.time_ns() - time.monotonic_ns()
        self.invalid = ""
        """Why the last position refused as :class:`link.PoseInvalid` was."""

    @property
    def telemetry(self) -> Telemetry | None:
        """The link once the autopilot answered, else None."""
        return self._telemetry

    # -- connect, retry, close --------------------------------------------------------------

    def start(self, stop: threading.Event, sync_s: float) -> None:
        """Connect and wait up to ``sync_s`` for the clock sync and a first pose (less if
        ``stop`` is set). If the autopilot is silent, return at once and keep connecting on
        a background thread until it answers or ``stop`` is set. Nothing without a
        connection string."""
        if not self.connection:
            return
        try:
            tel = self._connect(self.connection)
        except TelemetryTimeoutError as err:
            log.warning("%s; capturing unposed frames and retrying the link", err)
            if self._on_silent is not None:
                self._on_silent(AutopilotSilent(str(err)))
            retry = threading.Thread(
                target=self._retry, args=(self.connection, stop), name="telemetry-retry"
            )
            retry.daemon = True
            retry.start()
            return
        self._telemetry = tel
        self._wait_for_sync(stop, sync_s)

    def _connect(self, connection: str) -> Telemetry:
        tel = self._factory(connection, on_message=self._on_message)
        tel.__enter__()
        return tel

    def _retry(self, connection: str, stop: threading.Event) -> None:
        while not stop.is_set():
            try:
                tel = self._connect(connection)
            except TelemetryTimeoutError:
                continue  # each attempt already waited for a heartbeat
            if stop.is_set():
                tel.close()
                return
            self._telemetry = tel
            log.info("autopilot link up: frames are posed from now on")
            return

    def _wait_for_sync(self, stop: threading.Event, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not stop.is_set():
            if self.pose(time.monotonic_ns()) is not None:
                return
            time.sleep(0.05)
        log.warning("no synchronised pose after %.1f s; capturing anyway", timeout_s)

    def close(self) -> None:
        """Close the link (a retry still running ends when its ``stop`` is set)."""
        if self._telemetry is not None:
            self._telemetry.close()

    def summary(self) -> dict[str, Any]:
        """The link's figures for the flight's summary (``{}`` without a link)."""
        tel = self._telemetry
        if tel is None:
            return {}
        ts = tel.stats()
        return {
            "messages": dict(ts.messages),
            "bad_bytes": ts.bad_bytes,
            "bad_packets": ts.bad_packets,
            "rate_method": ts.rate_method,
            "clock_source": tel.clock.source,
        }

    # -- clocks and poses -------------------------------------------------------------------

    def unix_ns(self, t_mono_ns: int) -> int:
        """Unix time of a companion monotonic time: the autopilot's UTC when known, else the
        companion's clock."""
        tel = self._telemetry
        if tel is not None:
            try:
                return tel.clock.mono_to_unix_ns(t_mono_ns)
            except ClockUnavailable:
                pass
        return t_mono_ns + self._unix_minus_mono

    def boot_ns(self, t_mono_ns: int) -> int | None:
        """The autopilot's boot time of a companion monotonic time; None before the sync."""
        tel = self._telemetry
        if tel is None:
            return None
        try:
            return tel.clock.mono_to_boot_ns(t_mono_ns)
        except ClockUnavailable:
            return None

    def pose_pending(
        self,
        t_mono_ns: int,
        wait_s: float,
        *,
        since_ns: int | None = None,
        t_boot_ns: int | None = None,
        now_ns: int | None = None,
    ) -> bool:
        """Whether the telemetry after a companion monotonic time may still come: the link
        is up and synchronised, nothing as new as the time has arrived yet, and less than
        ``wait_s`` has passed since ``since_ns`` (default: the time itself; the daemon
        passes the later of a frame's time and its arrival at the capture thread).
        ``t_boot_ns``: the time's boot time as read before (else converted now).
        ``now_ns``: companion monotonic now (default: the clock). Never waits (the capture
        thread asks)."""
        tel = self._telemetry
        now = time.monotonic_ns() if now_ns is None else now_ns
        start = t_mono_ns if since_ns is None else max(t_mono_ns, since_ns)
        if tel is None or now - start >= wait_s * 1e9:
            return False
        if t_boot_ns is None:
            try:
                t_boot_ns = tel.clock.mono_to_boot_ns(t_mono_ns)
            except ClockUnavailable:
                return False
        newest = tel.poses.newest_t_boot_ns
        return newest is None or newest < t_boot_ns

    def pose(
        self,
        t_mono_ns: int,
        wait_s: float = 0.0,
        invalid: list[str] | None = None,
        *,
        since_ns: int | None = None,
        t_boot_ns: int | None = None,
    ) -> VehiclePose | None:
        """The vehicle pose at a companion monotonic time, or None: no link, not
        synchronised, or a position the autopilot does not have (:class:`PoseInvalid`: no
        fix, EKF without a position, 0/0, a jump; the reason appended to ``invalid``, kept
        in :attr:`invalid`). ``wait_s``: wait for the telemetry after the time until
        ``wait_s`` after ``since_ns`` (default: the time itself; no longer: a frame held
        that long already is not waited for again). ``t_boot_ns``: the time's boot time as
        read before (a frame's, at capture: its pose is the one at the time it is logged
        with), else converted now."""
        tel = self._telemetry
        if tel is None:
            return None
        start = t_mono_ns if since_ns is None else max(t_mono_ns, since_ns)
        wait_s = max(0.0, wait_s - (time.monotonic_ns() - start) / 1e9)
        try:
            if t_boot_ns is None:
                return tel.pose_at_mono(t_mono_ns, wait_s=wait_s)
            return tel.pose_at(t_boot_ns, wait_s=wait_s)
        except PoseInvalid as err:
            if str(err) != self.invalid:
                log.info("frames not posed: %s", err)
            self.invalid = str(err)
            if invalid is not None:
                invalid.append(str(err))
            return None
        except PoseUnavailable as err:
            log.debug("frame at mono %d not posed: %s", t_mono_ns, err)
            return None
