"""The vehicle's side of the mission protocol: one receiver, one server, for every use.

:class:`MissionReceiver` is the state machine without I/O (feed it messages, send what it
returns): upload (MISSION_COUNT -> MISSION_REQUEST_INT/MISSION_REQUEST per item ->
MISSION_ACK), download (MISSION_REQUEST_LIST -> MISSION_COUNT, then any item in any order,
repeatedly, from a snapshot taken per requester at the list request) and
MISSION_CLEAR_ALL, for mission type 0. A simulated autopilot embeds it; read-only, it is
the companion computer's hole mission.

:class:`MissionServer` runs a receiver on a link in a thread with heartbeats: the test
autopilot on loopback, and (subclassed by :class:`missions.HoleMissionServer`) the
companion computer serving found holes as component 191. Items are
:class:`missions.Waypoint` records; degE7 exists only in the messages.
"""

from __future__ import annotations

import functools
import logging
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from holescan.errors import InputError
from holescan.link import SigningKey, mavlink
from holescan.missions._protocol import (
    MAV_MISSION_ACCEPTED,
    MissionError,
    connect,
    item_message,
    waypoint_from_message,
)
from holescan.missions._waypoint import Waypoint

__all__ = ["MissionReceiver", "MissionServer"]

log = logging.getLogger(__name__)

_NS = 1_000_000_000


@dataclass
class _Transfer:
    peer: tuple[int, int]
    count: int
    items: list[Waypoint] = field(default_factory=list)
    last_request_ns: int = 0
    tries: int = 0


class MissionReceiver:
    """The vehicle's half of the mission protocol, without I/O (see the module docstring).

    Parameters
    ----------
    system_id, component_id : this vehicle's ids (messages to others are ignored).
    capacity : most items it stores; a longer upload gets MAV_MISSION_NO_SPACE.
    validate : called with the complete upload; returns a MAV_MISSION_RESULT (0 accepts).
    legacy : request items with the deprecated MISSION_REQUEST (float lat/lon).
    item_timeout_s, retries : re-request an item after this much silence, then give up.
    read_only : refuse uploads and clearing (MISSION_ACK DENIED); other mission types
        (fence, rally) are listed empty. broadcast : also answer messages to component 0
        (an autopilot does; a companion computer leaves them to the autopilot).
    """

    def __init__(
        self,
        *,
        system_id: int = 1,
        component_id: int = 1,
        capacity: int = 700,
        validate: Callable[[Sequence[Waypoint]], int] | None = None,
        legacy: bool = False,
        item_timeout_s: float = 1.0,
        retries: int = 5,
        read_only: bool = False,
        broadcast: bool = True,
    ) -> None:
        self.system_id = system_id
        self.component_id = component_id
        self.capacity = capacity
        self.validate = validate
        self.legacy = legacy
        self.item_timeout_ns = round(item_timeout_s * _NS)
        self.retries = retries
        self.read_only = read_only
        self.broadcast = broadcast
        self.mission: tuple[Waypoint, ...] = ()
        self.uploads_accepted = 0
        self.items_sent = 0
        self.last_result: int | None = None
        self._rx: _Transfer | None = None
        self._done: tuple[tuple[int, int], int, int] | None = None  # peer, count, result
        self._snapshots: dict[tuple[int, int], tuple[Waypoint, ...]] = {}

    @property
    def receiving(self) -> bool:
        return self._rx is not None

    def _for_me(self, msg: Any) -> bool:
        ts = getattr(msg, "target_system", self.system_id)
        tc = getattr(msg, "target_component", self.component_id)
        comps = (0, self.component_id) if self.broadcast else (self.component_id,)
        return bool(ts == self.system_id and tc in comps)

    def _ack(self, peer: tuple[int, int], result: int, mission_type: int = 0) -> Any:
        self.last_result = result
        return mavlink.MAVLink_mission_ack_message(peer[0], peer[1], result, mission_type)

    def _request(self, now_ns: int) -> Any:
        rx = self._rx
        assert rx is not None
        rx.last_request_ns = now_ns
        m = mavlink
        seq = len(rx.items)
        if self.legacy:
            return m.MAVLink_mission_request_message(rx.peer[0], rx.peer[1], seq, 0)
        return m.MAVLink_mission_request_int_message(rx.peer[0], rx.peer[1], seq, 0)

    def handle(self, msg: Any, now_ns: int) -> list[Any]:
        """React to one received message; returns the messages to send."""
        kind = msg.get_type()
        if not kind.startswith("MISSION_") or not self._for_me(msg):
            return []
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        mission_type = getattr(msg, "mission_type", 0)
        if kind == "MISSION_ACK":
            return []
        if self.read_only and kind in ("MISSION_COUNT", "MISSION_CLEAR_ALL"):
            log.info("refusing %s from %s: this mission is read-only", kind, peer)
            return [self._ack(peer, mavlink.MAV_MISSION_DENIED, mission_type)]
        if mission_type != mavlink.MAV_MISSION_TYPE_MISSION:
            if self.read_only and kind == "MISSION_REQUEST_LIST":
                return [mavlink.MAVLink_mission_count_message(*peer, 0, mission_type)]
            return [self._ack(peer, mavlink.MAV_MISSION_UNSUPPORTED, mission_type)]
        if kind == "MISSION_COUNT":
            if msg.count > self.capacity:
                self._rx = None
                return [self._ack(peer, mavlink.MAV_MISSION_NO_SPACE)]
            if msg.count == 0:
                self._rx = None
                self.mission = ()
                return [self._ack(peer, MAV_MISSION_ACCEPTED)]
            self._done = None
            self._rx = _Transfer(peer, int(msg.count))
            return [self._request(now_ns)]
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._on_item(msg, peer, now_ns)
        if kind == "MISSION_REQUEST_LIST":
            snapshot = self._snapshots[peer] = self.mission
            log.debug("mission list requested by %s: %d items", peer, len(snapshot))
            return [mavlink.MAVLink_mission_count_message(peer[0], peer[1], len(snapshot), 0)]
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            snapshot = self._snapshots.get(peer, self.mission)
            seq = int(msg.seq)
            if not 0 <= seq < len(snapshot):
                return [self._ack(peer, mavlink.MAV_MISSION_INVALID_SEQUENCE)]
            self.items_sent += 1
            return [
                item_message(
                    snapshot[seq],
                    seq,
                    peer,
                    use_int=kind == "MISSION_REQUEST_INT",
                    current=int(seq == 0 and not self.read_only),
                )
            ]
        if kind == "MISSION_CLEAR_ALL":
            self._rx = None
            self.mission = ()
            return [self._ack(peer, MAV_MISSION_ACCEPTED)]
        return []

    def _on_item(self, msg: Any, peer: tuple[int, int], now_ns: int) -> list[Any]:
        rx = self._rx
        done = self._done
        if rx is None and done is not None and done[0] == peer and int(msg.seq) == done[1] - 1:
            # The peer resent the last item: our MISSION_ACK was lost, send it again.
            return [self._ack(peer, done[2])]
        if rx is None or peer != rx.peer:
            return []
        if int(msg.seq) != len(rx.items):
            # As ArduPilot: an item out of sequence (a resend that crossed our request) is
            # answered MISSION_ACK INVALID_SEQUENCE and the transfer goes on (poll re-requests).
            return [self._ack(peer, mavlink.MAV_MISSION_INVALID_SEQUENCE)]
        try:
            rx.items.append(waypoint_from_message(msg))
        except InputError:
            self._rx = None
            return [self._ack(peer, mavlink.MAV_MISSION_ERROR)]
        rx.tries = 0
        if len(rx.items) < rx.count:
            return [self._request(now_ns)]
        self._rx = None
        result = self.validate(rx.items) if self.validate is not None else MAV_MISSION_ACCEPTED
        self._done = (peer, rx.count, result)
        if result == MAV_MISSION_ACCEPTED:
            self.mission = tuple(rx.items)
            self.uploads_accepted += 1
        return [self._ack(peer, result)]

    def poll(self, now_ns: int) -> list[Any]:
        """Re-request the awaited item after a silence; give up after the retries."""
        rx = self._rx
        if rx is None or now_ns - rx.last_request_ns < self.item_timeout_ns:
            return []
        rx.tries += 1
        if rx.tries > self.retries:
            self._rx = None
            return [self._ack(rx.peer, mavlink.MAV_MISSION_OPERATION_CANCELLED)]
        return [self._request(now_ns)]


def _send_message(msg: Any, mav: Any) -> None:
    mav.send(msg)


class MissionServer:
    """A :class:`MissionReceiver` on a MAVLink link, in a thread, with heartbeats.

    Use as a context manager. ``drop`` is called with each outgoing mission message;
    returning True drops it, to simulate a lossy link in tests.

    Parameters
    ----------
    link : e.g. ``udpin:127.0.0.1:14555`` (answers whoever speaks first) or
        ``udpout:127.0.0.1:14550`` (speaks first, e.g. to MAVProxy's ``udpin``).
        None with ``sender``: share a link another part owns (see below).
    mav_type, autopilot : what the HEARTBEAT says we are (default: an ArduPilot quadrotor).
    heartbeat_period_s : HEARTBEAT interval.
    sender : share the owner's link instead of opening one (the companion's one link to
        the autopilot, which routes to the GCS): ``sender(fn)`` calls ``fn(mav)`` with the
        owner's MAVLink sender under its lock; the owner hands every message it receives
        to :meth:`feed` and sends the heartbeats (none are sent here).
    signing : MAVLink 2 signing key (None: unsigned); with one, unsigned or badly signed
        requests are dropped unanswered (:class:`link.SigningKey`).

    Subclasses hook in with :meth:`on_message` (every other message) and :meth:`tick`
    (each turn of the loop, about every ``tick_s``).
    """

    tick_s = 0.02

    def __init__(
        self,
        link: str | None,
        receiver: MissionReceiver | None = None,
        *,
        drop: Callable[[Any], bool] | None = None,
        heartbeat_period_s: float = 1.0,
        mav_type: int = mavlink.MAV_TYPE_QUADROTOR,
        autopilot: int = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
        sender: Callable[[Callable[[Any], None]], None] | None = None,
        signing: SigningKey | None = None,
    ) -> None:
        if (link is None) == (sender is None):
            raise InputError("a mission server needs a link or a sender, not both")
        self._sender = sender
        self._inbox: queue.Queue[Any] = queue.Queue(maxsize=1024)
        self.receiver = receiver if receiver is not None else MissionReceiver()
        self.link = link
        self.drop = drop
        self.heartbeat_period_s = heartbeat_period_s
        self.mav_type = mav_type
        self.autopilot = autopilot
        self.signing = signing
        self.sent: list[str] = []
        self.dropped: list[str] = []
        self.received: list[str] = []
        self._conn: Any = None
        self._lock = threading.RLock()  # the receiver and the link's sending side
        self._stop = threading.Event()
        self._accepted = threading.Condition()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def __enter__(self) -> MissionServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> None:
        """Open the link (:class:`missions.MissionError` if it cannot be) and start."""
        if self._thread is not None:
            raise MissionError("server already started")
        if self.link is not None:
            self._conn = connect(
                self.link,
                source_system=self.receiver.system_id,
                source_component=self.receiver.component_id,
                signing=self.signing,
            )
        self._thread = threading.Thread(target=self._run, name="mission-server", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def wait_accepted(self, uploads: int = 1, timeout_s: float = 10.0) -> tuple[Waypoint, ...]:
        """Block until ``uploads`` uploads were accepted; returns the stored mission."""
        deadline = time.monotonic() + timeout_s
        with self._accepted:
            while self.receiver.uploads_accepted < uploads:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self._error is not None:
                    raise TimeoutError(
                        f"no accepted upload within {timeout_s:g} s "
                        f"(last result {self.receiver.last_result})"
                    ) from self._error
                self._accepted.wait(remaining)
            return self.receiver.mission

    def feed(self, msg: Any) -> None:
        """A message the owner of a shared link received (any thread; never blocks: when
        the server lags 1024 messages behind, the message is dropped)."""
        try:
            self._inbox.put_nowait(msg)
        except queue.Full:
            log.debug("mission server inbox full: %s dropped", msg.get_type())

    # -- sending -------------------------------------------------------------------------
    def send_with(self, fn: Callable[[Any], None]) -> None:
        """Call ``fn(mav)`` with the link's MAVLink sender (any thread)."""
        if self._sender is not None:
            with self._lock:
                try:
                    self._sender(fn)
                except Exception as err:  # the owner's link is closed or failing
                    raise MissionError(f"shared link: {err}") from err
            return
        conn = self._conn
        if conn is None:
            raise MissionError("server is not running: use it as a context manager")
        with self._lock:
            fn(conn.mav)

    def _send(self, out: Sequence[Any]) -> None:
        for msg in out:
            label = msg.get_type() + (f" {msg.seq}" if hasattr(msg, "seq") else "")
            if self.drop is not None and self.drop(msg):
                self.dropped.append(label)
                continue
            self.sent.append(label)
            self.send_with(functools.partial(_send_message, msg))

    def _heartbeat(self) -> None:
        if self._sender is not None:
            return  # the owner of a shared link sends the heartbeats
        self.send_with(
            lambda mav: mav.heartbeat_send(
                self.mav_type, self.autopilot, 0, 0, mavlink.MAV_STATE_ACTIVE
            )
        )

    # -- hooks -----------------------------------------------------------------------------
    def on_message(self, msg: Any) -> None:
        """A received message that is not the mission protocol's (subclasses)."""

    def tick(self) -> None:
        """Called each turn of the loop (subclasses)."""

    # -- the thread ------------------------------------------------------------------------
    def _receive(self, conn: Any) -> Any:
        if conn is None:  # a shared link: the owner feeds us
            try:
                return self._inbox.get(timeout=self.tick_s)
            except queue.Empty:
                return None
        return conn.recv_match(blocking=True, timeout=self.tick_s)

    def _run(self) -> None:
        conn = self._conn
        period = self.heartbeat_period_s
        next_beat = 0.0
        known: set[object] = set()
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if now >= next_beat:
                    self._heartbeat()
                    next_beat = now + period
                try:
                    msg = self._receive(conn)
                except OSError as err:  # e.g. udpout towards a closed port
                    log.debug("mission server link: %s", err)
                    self._stop.wait(0.2)
                    continue
                try:
                    next_beat = self._turn(conn, msg, known, next_beat)
                except MissionError as err:
                    if self._sender is None:
                        raise
                    log.debug("shared link not usable now: %s", err)  # closed, or not yet up
                    self._stop.wait(0.2)
        except Exception as err:  # surfaced by wait_accepted / subclasses' close
            if not self._stop.is_set():
                log.exception("mission server stopped")
                self._error = err
        finally:
            with self._accepted:
                self._accepted.notify_all()

    def _turn(self, conn: Any, msg: Any, known: set[object], next_beat: float) -> float:
        """Handle one received message (or None), poll, tick; return the next beat time."""
        now_ns = time.monotonic_ns()
        before = self.receiver.uploads_accepted
        if msg is not None and msg.get_type() != "BAD_DATA":
            self.received.append(msg.get_type())
            clients = set(getattr(conn, "clients", ()))  # udpin: peer addresses
            if msg.get_type() == "HEARTBEAT" and not clients <= known:
                known |= clients
                next_beat = 0.0  # a new peer: answer its heartbeat at once
            with self._lock:
                out = self.receiver.handle(msg, now_ns)
            self._send(out)
            if not msg.get_type().startswith("MISSION_"):
                self.on_message(msg)
        with self._lock:
            out = self.receiver.poll(now_ns)
        self._send(out)
        self.tick()
        if self.receiver.uploads_accepted != before:
            with self._accepted:
                self._accepted.notify_all()
        return next_beat
