"""MAVLink telemetry link: rates, TIMESYNC, and MAVLink -> SI records (one adapter).

:class:`Telemetry` opens a pymavlink connection (serial device, ``udpin:``/``udpout:``,
``tcp:``), finds the autopilot by its heartbeat, takes the identity of a companion computer on
that vehicle (the vehicle's system id, component 191 = MAV_COMP_ID_ONBOARD_COMPUTER), asks
for the messages it needs with MAV_CMD_SET_MESSAGE_INTERVAL (falling back to
REQUEST_DATA_STREAM when that is not acknowledged), and runs a receiver thread that
hands the autopilot's messages to a :class:`~capture._mavingest.VehicleState`, which

* converts units once (``time_boot_ms`` -> ns, degE7 -> deg, mm -> m, cm/s -> m/s,
  cdeg -> rad) into :class:`~link._posebuffer.PositionSample`,
  :class:`~link._posebuffer.AttitudeSample` and :class:`~link._posebuffer.GpsFix`
  records that fill a :class:`~link._posebuffer.PoseBuffer`;
* keeps a :class:`~capture._clock.ClockSync` up to date (TIMESYNC round trips at
  ``timesync_hz``, arrival times of stamped messages, SYSTEM_TIME for UTC), notices
  reboots and follows the flight mode and arming (heartbeats);
and itself counts (and logs) garbage bytes and packets that fail to parse (otherwise
ignored) and hands every parsed message with its arrival time to ``on_message``.

MAVLink 2 through :func:`link.open_link` (TIMESYNC and MAVProxy's wp module need it).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final

from holescan.capture._clock import ClockSync
from holescan.capture._mavingest import VehicleState
from holescan.capture.errors import ClockUnavailable
from holescan.geotag import VehiclePose
from holescan.link import (
    GpsFix,
    MavConnection,
    MavlinkStream,
    PoseBuffer,
    PoseUnavailable,
    RateMethod,
    RateRequests,
    SigningKey,
    TelemetryError,
    TelemetryTimeoutError,
    is_autopilot_heartbeat,
    mavlink,
    open_link,
)

__all__ = [
    "COMPANION_COMPONENT",
    "DEFAULT_BAUD",
    "DEFAULT_RATES_HZ",
    "MessageCallback",
    "RateMethod",
    "Telemetry",
    "TelemetryStats",
]

_log = logging.getLogger(__name__)
COMPANION_COMPONENT = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER  # 191
DEFAULT_BAUD: Final = 921_600  # the flight controller's TELEM port (also ``fly``'s default)
DEFAULT_RATES_HZ: Mapping[str, float] = {
    "GLOBAL_POSITION_INT": 10.0,
    "ATTITUDE": 50.0,
    "GPS_RAW_INT": 5.0,
    "EKF_STATUS_REPORT": 2.0,
    "SYSTEM_TIME": 1.0,
}

MessageCallback = Callable[[Any, int], None]
"""``on_message(msg, t_mono_ns)``: a parsed pymavlink message and its arrival time."""

#: Links read as raw bytes through :class:`MavlinkStream` (datagram links: each datagram
#: framed on its own); other links (tlog replay ...) go through pymavlink's own parser.
_STREAM_LINKS = {"mavserial": False, "mavtcp": False, "mavtcpin": False}
_DATAGRAM_LINKS = {"mavudp": True, "mavmcast": True}


@dataclass(frozen=True)
class TelemetryStats:
    """Counters of a :class:`Telemetry` link.

    messages : parsed messages from the autopilot, by type.
    bad_bytes : garbage bytes skipped while looking for a MAVLink frame start.
    bad_packets : framed packets that failed (bad CRC, bad length/flags).
    unknown_packets : well-framed packets of a message id our dialect does not know (their
        CRC cannot be checked); passed to ``on_message`` but otherwise ignored.
    lost_packets : sequence-number gaps seen by pymavlink (all sources).
    callback_errors : exceptions raised by ``on_message`` (logged, swallowed).
    rate_method : how message rates were obtained.
    timesync_sent, timesync_received : TIMESYNC requests sent / matching replies.
    vehicle : the autopilot's flight ``mode``, ``armed`` and ``mode_changes`` seen.
    """

    messages: Mapping[str, int]
    bad_bytes: int
    bad_packets: int
    unknown_packets: int
    lost_packets: int
    callback_errors: int
    rate_method: RateMethod
    timesync_sent: int
    timesync_received: int
    vehicle: Mapping[str, Any]


class Telemetry(RateRequests):
    """A MAVLink link to the autopilot with a receiver thread; use as a context manager.

    Parameters
    ----------
    connection : pymavlink connection string: a serial device (``/dev/ttyAMA0``),
        ``udpin:HOST:PORT``, ``udpout:HOST:PORT``, ``tcp:HOST:PORT``.
    baud : serial baud rate (ignored for network links).
    target_system, target_component : the autopilot; None = take them from the first
        autopilot heartbeat.
    rates_hz : message name -> wanted rate, Hz (request ATTITUDE or ATTITUDE_QUATERNION).
    timesync_hz : TIMESYNC requests per second (0 disables; the clock then falls back to
        message arrival times).
    heartbeat_timeout_s : how long :meth:`__enter__` waits for the autopilot.
    command_timeout_s, command_retries : per COMMAND_LONG attempt / attempts.
    on_message : called from the receiver thread for every parsed message, after the link
        took it in (a position is in :attr:`poses` already); keep it quick.
    poses, clock : bring your own (e.g. tuned) buffer / clock; defaults are created.
    signing_key : MAVLink 2 signing secret (32 bytes, :func:`read_signing_key`): outgoing
        packets are signed, incoming ones without a valid signature are dropped as bad.
    """

    def __init__(
        self,
        connection: str,
        *,
        baud: int = DEFAULT_BAUD,
        target_system: int | None = None,
        target_component: int | None = None,
        rates_hz: Mapping[str, float] = DEFAULT_RATES_HZ,
        timesync_hz: float = 4.0,
        heartbeat_timeout_s: float = 10.0,
        command_timeout_s: float = 0.5,
        command_retries: int = 3,
        on_message: MessageCallback | None = None,
        poses: PoseBuffer | None = None,
        clock: ClockSync | None = None,
        signing_key: bytes | None = None,
    ) -> None:
        if signing_key is not None and len(signing_key) != 32:
            raise TelemetryError("a MAVLink 2 signing key is 32 bytes (read_signing_key)")
        self._signing_key = signing_key
        for name in rates_hz:
            if not hasattr(mavlink, f"MAVLINK_MSG_ID_{name}"):
                raise ValueError(f"unknown MAVLink message {name!r} in rates_hz")
        self.connection = connection
        self.poses = poses if poses is not None else PoseBuffer()
        self.clock = clock if clock is not None else ClockSync()
        self._baud = baud
        self._want_sysid = target_system
        self._want_compid = target_component
        self._rates = dict(rates_hz)
        self._timesync_period_ns = round(1e9 / timesync_hz) if timesync_hz > 0 else 0
        self._hb_timeout_s = heartbeat_timeout_s
        self._cmd_timeout_s = command_timeout_s
        self._cmd_retries = command_retries
        self._on_message = on_message

        self._conn: MavConnection | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._send_lock = threading.Lock()
        self._cond = threading.Condition()  # guards _acks, _target; signals new samples
        self._target: tuple[int, int] | None = None
        self._acks: dict[int, int] = {}  # command -> MAV_RESULT of the latest ack
        self._counts: dict[str, int] = {}
        self._arrivals: dict[str, deque[int]] = {}
        self._bad_bytes = 0
        self._bad_packets = 0
        self._stream: MavlinkStream | None = None
        self._state = VehicleState(
            self.poses, self.clock, on_sample=self._notify, on_reboot=self._rerequest_rates_soon
        )
        self._last_hb_ns: int | None = None
        self._last_rate_request_ns = 0
        self._unknown_packets = 0
        self._callback_errors = 0
        self._last_bad_log_ns = 0
        self._last_rx_mono_ns: int | None = None
        self.rate_method: RateMethod = "none"

    # -- lifecycle -------------------------------------------------------------------------

    def __enter__(self) -> Telemetry:
        try:
            conn = open_link(
                self.connection,
                baud=self._baud,
                source_system=self._want_sysid if self._want_sysid is not None else 255,
                source_component=COMPANION_COMPONENT,
                autoreconnect=True,
            )
        except Exception as err:  # pymavlink raises OSError, SerialException, ValueError...
            raise TelemetryError(f"cannot open MAVLink link {self.connection!r}: {err}") from err
        self._conn = conn
        if self._signing_key is not None:  # unsigned or badly signed packets: bad packets
            SigningKey(self._signing_key).apply(conn)  # the signature checked first
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="telemetry-rx", daemon=True)
        self._thread.start()
        try:
            sysid, compid = self.wait_target(self._hb_timeout_s)
            _log.info("autopilot %d/%d on %s", sysid, compid, self.connection)
            if self._rates:
                self.request_rates(self._rates)
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the receiver thread and close the link (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    # -- public queries --------------------------------------------------------------------

    @property
    def reboots(self) -> int:
        """Autopilot reboots seen (its boot clock went back)."""
        return self._state.reboots

    @property
    def target(self) -> tuple[int, int] | None:
        """(system id, component id) of the autopilot, once its heartbeat was seen."""
        return self._target

    def wait_target(self, timeout_s: float) -> tuple[int, int]:
        """Block until the autopilot's heartbeat was seen; raise :class:`TelemetryTimeoutError`."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while self._target is None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TelemetryTimeoutError(
                        f"no autopilot heartbeat on {self.connection!r} within {timeout_s:g} s"
                    )
                self._cond.wait(remaining)
            return self._target

    def pose_at(self, t_boot_ns: int, *, wait_s: float = 0.0) -> VehiclePose:
        """Pose at autopilot boot time ``t_boot_ns``; raises :class:`PoseUnavailable`.

        With ``wait_s > 0``, first wait up to that long for samples after the time, so the
        pose is interpolated instead of extrapolated.
        """
        if wait_s > 0:
            deadline = time.monotonic() + wait_s
            with self._cond:
                while True:
                    newest = self.poses.newest_t_boot_ns
                    remaining = deadline - time.monotonic()
                    if (newest is not None and newest >= t_boot_ns) or remaining <= 0:
                        break
                    self._cond.wait(remaining)
        return self.poses.pose_at(t_boot_ns)

    def pose_at_mono(self, t_mono_ns: int, *, wait_s: float = 0.0) -> VehiclePose:
        """Pose at companion monotonic time ``t_mono_ns`` (e.g. a frame's ``t_mono_ns``).

        With ``wait_s > 0``, first wait up to that long for samples after the time, so the
        pose is interpolated instead of extrapolated. Raises :class:`PoseUnavailable` (also
        when the clocks are not synchronised yet).
        """
        try:
            t_boot_ns = self.clock.mono_to_boot_ns(t_mono_ns)
        except ClockUnavailable as err:
            raise PoseUnavailable(str(err)) from err
        return self.pose_at(t_boot_ns, wait_s=wait_s)

    def send_with(self, fn: Callable[[Any], None]) -> None:
        """``fn(mav)`` with this link's sender under its lock (for a server sharing the link;
        sent as the companion, sysid/191); :class:`TelemetryError` once closed."""
        with self._send_lock:
            fn(self._link.mav)

    def latest_gps(self) -> GpsFix | None:
        return self.poses.latest_gps()

    def message_rates_hz(self, window_s: float = 3.0) -> dict[str, float]:
        """Measured arrival rate of each message type from the autopilot over the last
        ``window_s`` seconds, Hz (types with fewer than 2 arrivals are left out)."""
        now = time.monotonic_ns()
        start = now - round(window_s * 1e9)
        rates: dict[str, float] = {}
        with self._cond:
            series = {k: list(v) for k, v in self._arrivals.items()}
        for name, times in series.items():
            recent = [t for t in times if t >= start]
            if len(recent) >= 2 and recent[-1] > recent[0]:
                rates[name] = (len(recent) - 1) * 1e9 / (recent[-1] - recent[0])
        return rates

    def last_message_age_s(self) -> float:
        """Seconds since anything arrived from the autopilot (inf before the first)."""
        last = self._last_rx_mono_ns
        return math.inf if last is None else (time.monotonic_ns() - last) / 1e9

    def stats(self) -> TelemetryStats:
        with self._cond:
            counts = dict(self._counts)
        return TelemetryStats(
            messages=counts,
            bad_bytes=self._bad_bytes,
            bad_packets=self._bad_packets,
            unknown_packets=self._unknown_packets,
            lost_packets=int(getattr(self._conn, "mav_loss", 0)) if self._conn else 0,
            callback_errors=self._callback_errors,
            rate_method=self.rate_method,
            timesync_sent=self._state.timesync_sent,
            timesync_received=self._state.timesync_received,
            vehicle=self._state.flight_state(),
        )

    # -- commands --------------------------------------------------------------------------

    def _require_target(self) -> tuple[int, int]:
        if self._conn is None or self._target is None:
            raise TelemetryError("telemetry link is not open (use it as a context manager)")
        return self._target

    # -- receiver thread -------------------------------------------------------------------

    def _run(self) -> None:
        conn = self._link
        kind = type(conn).__name__
        stream: MavlinkStream | None = None
        if kind in _STREAM_LINKS or kind in _DATAGRAM_LINKS:
            stream = MavlinkStream(conn.mav, datagrams=kind in _DATAGRAM_LINKS)
        self._stream = stream
        next_hb = 0
        next_ts = 0
        while not self._stop.is_set():
            now = time.monotonic_ns()
            if now >= next_hb:
                self._send_heartbeat()
                self._watch_rates(now)
                next_hb = now + 1_000_000_000
            if self._timesync_period_ns and self._target is not None and now >= next_ts:
                self._send_timesync()
                next_ts = now + self._timesync_period_ns
            try:
                msgs = self._receive(conn, stream)
            except Exception as err:  # socket/serial trouble: log, back off, keep going
                _log.warning("MAVLink receive failed on %s: %s", self.connection, err)
                self._stop.wait(0.1)
                continue
            if not msgs:
                wait_ns = min(next_hb, next_ts if self._timesync_period_ns else next_hb) - now
                conn.select(max(0.0, min(wait_ns / 1e9, 0.02)))
                continue
            t_mono_ns = time.monotonic_ns()
            for msg in msgs:
                try:
                    self._handle(msg, t_mono_ns)
                except Exception:  # one bad message must not kill the link
                    _log.exception("failed to handle %s", msg.get_type())

    def _receive(self, conn: MavConnection, stream: MavlinkStream | None) -> list[Any]:
        """Messages now available: a datagram's or a read's worth."""
        if stream is None:
            msg = conn.recv_msg()
            return [] if msg is None else [msg]
        data = conn.recv(4096)
        if not data:
            return []
        bad = (stream.bad_bytes, stream.bad_packets)
        msgs = stream.feed(bytes(data))
        if (stream.bad_bytes, stream.bad_packets) != bad:
            self._note_bad(stream.bad_bytes - bad[0], stream.bad_packets - bad[1], stream)
        for msg in msgs:
            conn.post_message(msg)  # pymavlink's link state: sequence losses, last messages
        return msgs

    def _send_heartbeat(self) -> None:
        # None before the autopilot (and so our system id) is known: a GCS behind it would
        # see a system 255 (ArduPilot SITL); except on a link that must speak first.
        if self._target is None and not self.connection.startswith("udpout:"):
            return
        with self._send_lock:
            self._link.mav.heartbeat_send(
                mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                mavlink.MAV_AUTOPILOT_INVALID,
                0,
                0,
                mavlink.MAV_STATE_ACTIVE,
            )

    def _send_timesync(self) -> None:
        with self._send_lock:
            t0 = time.monotonic_ns()
            self._link.mav.timesync_send(0, t0)
        self._state.timesync_request(t0)

    def _notify(self) -> None:
        with self._cond:
            self._cond.notify_all()

    def _handle(self, msg: Any, t_mono_ns: int) -> None:
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            self._count_bad(msg, t_mono_ns)
            return
        try:
            self._take(msg, mtype, t_mono_ns)
        finally:  # after the link has it: a position's pose is the position itself
            if self._on_message is not None:
                try:
                    self._on_message(msg, t_mono_ns)
                except Exception:
                    self._callback_errors += 1
                    _log.exception("on_message callback failed for %s", mtype)

    def _take(self, msg: Any, mtype: str, t_mono_ns: int) -> None:
        if mtype.startswith("UNKNOWN_"):
            self._unknown_packets += 1
            if self._unknown_packets == 1:
                _log.warning("ignoring %s: a message id our dialect does not know", mtype)
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if self._target is None:
            self._maybe_adopt_target(msg, src)
            return
        if src != self._target:
            return
        self._last_rx_mono_ns = t_mono_ns
        if mtype == "HEARTBEAT":
            self._last_hb_ns = t_mono_ns
        with self._cond:
            self._counts[mtype] = self._counts.get(mtype, 0) + 1
            self._arrivals.setdefault(mtype, deque(maxlen=512)).append(t_mono_ns)
        if mtype == "TIMESYNC":
            self._on_timesync(msg, t_mono_ns)
        elif mtype == "COMMAND_ACK":
            self._on_command_ack(msg)
        else:
            self._state.handle(mtype, msg, t_mono_ns)

    def _maybe_adopt_target(self, msg: Any, src: tuple[int, int]) -> None:
        if not is_autopilot_heartbeat(msg):
            return
        if self._want_sysid is not None and src[0] != self._want_sysid:
            return
        if self._want_compid is not None and src[1] != self._want_compid:
            return
        with self._send_lock:
            link = self._link
            link.target_system, link.target_component = src
            link.mav.srcSystem = src[0]  # a companion takes its vehicle's system id
            link.mav.srcComponent = COMPANION_COMPONENT
        with self._cond:
            self._target = src
            self._cond.notify_all()

    def _count_bad(self, msg: Any, t_mono_ns: int) -> None:
        """A BAD_DATA message of pymavlink's own parser (links read with recv_msg)."""
        if msg.reason == "Bad prefix":
            self._note_bad(len(msg.data), 0, msg.reason, t_mono_ns)
        else:
            self._note_bad(0, 1, msg.reason, t_mono_ns)

    def _note_bad(
        self, n_bytes: int, n_packets: int, why: Any, t_mono_ns: int | None = None
    ) -> None:
        self._bad_bytes += n_bytes
        self._bad_packets += n_packets
        t = time.monotonic_ns() if t_mono_ns is None else t_mono_ns
        if t - self._last_bad_log_ns > 10_000_000_000:
            self._last_bad_log_ns = t
            reason = why.last_error if isinstance(why, MavlinkStream) else why
            _log.warning(
                "ignoring unparseable MAVLink data on %s (%s); totals: %d garbage "
                "bytes, %d bad packets",
                self.connection,
                reason or "bytes before a start byte",
                self._bad_bytes,
                self._bad_packets,
            )

    def _on_timesync(self, msg: Any, t_mono_ns: int) -> None:
        if msg.tc1 == 0:  # the autopilot asks us: answer with our clock
            with self._send_lock:
                self._link.mav.timesync_send(time.monotonic_ns(), msg.ts1)
            return
        self._state.timesync_reply(msg, t_mono_ns)

    def _on_command_ack(self, msg: Any) -> None:
        target = (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0))
        ours = (self._link.mav.srcSystem, COMPANION_COMPONENT)
        if target != (0, 0) and target != ours:  # an answer to someone else's command
            return
        with self._cond:
            self._acks[int(msg.command)] = int(msg.result)
            self._cond.notify_all()
