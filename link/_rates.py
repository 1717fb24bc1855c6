"""Asking the autopilot for messages: COMMAND_LONG with acknowledgement, message intervals
with the REQUEST_DATA_STREAM fallback (a part of :class:`capture._mavlink.Telemetry`)."""

from __future__ import annotations

import abc
import logging
import math
import os
import threading
import time
from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import Literal

from holescan.link._connection import MavConnection, mavlink
from holescan.link.errors import TelemetryError, TelemetryTimeoutError

__all__ = [
    "RateMethod",
    "RateRequests",
    "read_signing_key",
]

_log = logging.getLogger("holescan.capture._mavlink")

RateMethod = Literal["message_interval", "data_stream", "mixed", "none"]

# REQUEST_DATA_STREAM groups (ArduPilot's assignment) for the fallback.
_DATA_STREAM: Mapping[str, int] = {
    "GLOBAL_POSITION_INT": mavlink.MAV_DATA_STREAM_POSITION,
    "ATTITUDE": mavlink.MAV_DATA_STREAM_EXTRA1,
    "ATTITUDE_QUATERNION": mavlink.MAV_DATA_STREAM_EXTRA1,
    "GPS_RAW_INT": mavlink.MAV_DATA_STREAM_EXTENDED_STATUS,
    "SYSTEM_TIME": mavlink.MAV_DATA_STREAM_EXTRA3,
    "EKF_STATUS_REPORT": mavlink.MAV_DATA_STREAM_EXTRA3,
}


def read_signing_key(path: str | os.PathLike[str]) -> bytes:
    """A MAVLink 2 signing secret from a file: 64 hex digits (as MAVProxy and QGC show it)
    or 32 raw bytes. Raises :class:`TelemetryError` naming the problem."""
    try:
        raw = Path(path).read_bytes()
    except OSError as err:
        raise TelemetryError(f"signing key {path}: cannot read: {err.strerror}") from err
    text = raw.strip()
    if len(text) == 64:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    if len(raw) == 32:
        return raw
    raise TelemetryError(f"signing key {path}: expected 64 hex digits or 32 bytes")


class RateRequests(abc.ABC):
    """Commands and message rates; the receiver thread fills ``_acks`` from COMMAND_ACKs."""

    _conn: MavConnection | None
    _cond: threading.Condition
    _send_lock: threading.Lock
    _acks: dict[int, int]
    _cmd_retries: int
    _cmd_timeout_s: float
    _rates: dict[str, float]
    _target: tuple[int, int] | None
    _last_hb_ns: int | None
    _last_rate_request_ns: int
    _arrivals: dict[str, deque[int]]
    rate_method: RateMethod

    @property
    def _link(self) -> MavConnection:
        """The open connection; :class:`TelemetryError` once the link is closed."""
        conn = self._conn
        if conn is None:
            raise TelemetryError("telemetry link is not open (use it as a context manager)")
        return conn

    @abc.abstractmethod
    def _require_target(self) -> tuple[int, int]:
        """The autopilot's (system, component); the link class knows it from the heartbeat."""

    def command_long(self, command: int, *params: float) -> int:
        """Send COMMAND_LONG to the autopilot and return the MAV_RESULT of its COMMAND_ACK.

        Retries ``command_retries`` times (confirmation counts up); raises
        :class:`TelemetryTimeoutError` when no ACK comes. Not callable from ``on_message``.
        """
        sysid, compid = self._require_target()
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        for attempt in range(self._cmd_retries):
            with self._cond:
                self._acks.pop(command, None)
            with self._send_lock:
                self._link.mav.command_long_send(sysid, compid, command, attempt, *p)
            deadline = time.monotonic() + self._cmd_timeout_s
            with self._cond:
                while True:
                    result = self._acks.get(command)
                    if result is not None and result != mavlink.MAV_RESULT_IN_PROGRESS:
                        return result
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        break
                    self._cond.wait(remaining)
        raise TelemetryTimeoutError(
            f"no COMMAND_ACK for command {command} after {self._cmd_retries} attempts"
        )

    def request_rates(self, rates_hz: Mapping[str, float]) -> RateMethod:
        """Ask for each message at its rate (Hz; <= 0 stops it).

        MAV_CMD_SET_MESSAGE_INTERVAL per message; messages it does not get ACCEPTED for are
        requested with REQUEST_DATA_STREAM (ArduPilot stream groups, integer Hz). If the
        first command is not acknowledged at all, the rest go straight to the fallback.
        """
        refused: dict[str, float] = {}
        acked_any = False
        for name, hz in rates_hz.items():
            msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
            interval_us = round(1e6 / hz) if hz > 0 else -1
            if refused and not acked_any:
                refused[name] = hz
                continue
            try:
                result = self.command_long(
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us
                )
            except TelemetryTimeoutError:
                _log.info("SET_MESSAGE_INTERVAL not acknowledged for %s", name)
                refused[name] = hz
                continue
            acked_any = True
            if result != mavlink.MAV_RESULT_ACCEPTED:
                _log.info("SET_MESSAGE_INTERVAL for %s refused (MAV_RESULT %d)", name, result)
                refused[name] = hz
        if refused:
            self._request_data_streams(refused)
        if not refused:
            method: RateMethod = "message_interval"
        elif len(refused) == len(rates_hz):
            method = "data_stream"
        else:
            method = "mixed"
        self.rate_method = method
        _log.info("message rates requested by %s: %s", method, dict(rates_hz))
        return method

    def _request_data_streams(self, rates_hz: Mapping[str, float]) -> None:
        sysid, compid = self._require_target()
        streams: dict[int, int] = {}
        for name, hz in rates_hz.items():
            stream = _DATA_STREAM.get(name)
            if stream is None:
                _log.warning("no REQUEST_DATA_STREAM group known for %s: not requested", name)
                continue
            streams[stream] = max(streams.get(stream, 0), math.ceil(hz) if hz > 0 else 0)
        for _ in range(2):  # no acknowledgement exists: send twice against loss
            for stream, hz in streams.items():
                with self._send_lock:
                    self._link.mav.request_data_stream_send(sysid, compid, stream, hz, int(hz > 0))

    def _rerequest_rates_soon(self) -> None:
        """Ask for the rates again from another thread (the ACKs come through this one)."""
        now = time.monotonic_ns()
        if not self._rates or now - self._last_rate_request_ns < 3_000_000_000:
            return
        self._last_rate_request_ns = now
        threading.Thread(target=self._rerequest_rates, name="telemetry-rates", daemon=True).start()

    def _rerequest_rates(self) -> None:
        try:
            self.request_rates(self._rates)
        except TelemetryError as err:
            _log.warning("message rates not re-requested: %s", err)

    def _watch_rates(self, now_ns: int) -> None:
        """Heartbeats but none of the requested messages for 3 s (the autopilot rebooted or
        lost its stream settings while the link was down): request them again."""
        if self._target is None or not self._rates or self._last_hb_ns is None:
            return
        if now_ns - self._last_hb_ns > 2_000_000_000:
            return  # the link is down: nothing to ask
        with self._cond:
            newest = max(
                (self._arrivals[n][-1] for n in self._rates if self._arrivals.get(n)), default=0
            )
        if now_ns - newest > 3_000_000_000:
            _log.info("no requested message for 3 s while the autopilot is alive: re-requesting")
            self._rerequest_rates_soon()
