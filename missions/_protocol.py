"""The MAVLink mission protocol: upload/download client and a vehicle-side receiver.

Client (ground or companion side): :func:`upload_mission` sends MISSION_COUNT, answers
each MISSION_REQUEST_INT (or legacy MISSION_REQUEST) with MISSION_ITEM_INT (MISSION_ITEM),
resends on silence, and waits for MISSION_ACK. :func:`download_mission` pulls a mission.

Vehicle side: :class:`MissionReceiver` is the autopilot's half as a state machine without
I/O (feed it messages, send what it returns), so a simulated autopilot can embed it;
:class:`MissionServer` runs one on a link in a thread and sends heartbeats, for tests and
for playing the autopilot on loopback.

pymavlink picks MAVLink 1 or 2 from the environment when first imported; links opened here
always speak MAVLink 2 (MAVProxy needs it) whatever that choice was.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from holescan_errors import HolescanError, InputError
from missions._link import mavlink, open_link
from missions._waypoint import MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL, MAV_FRAME_MISSION, Waypoint

__all__ = [
    "MAV_MISSION_ACCEPTED",
    "MissionError",
    "MissionReceiver",
    "MissionRejectedError",
    "MissionServer",
    "MissionTimeoutError",
    "UploadReport",
    "connect",
    "download_mission",
    "upload_mission",
]

log = logging.getLogger(__name__)

MAV_MISSION_ACCEPTED: int = mavlink.MAV_MISSION_ACCEPTED
_NS = 1_000_000_000

# Frames whose x/y are latitude/longitude.
_MISSION_FRAMES_WITHOUT_POSITION = {MAV_FRAME_MISSION}


class MissionError(HolescanError):
    """The mission transfer failed (bad link, protocol error)."""


class MissionTimeoutError(MissionError, TimeoutError):
    """The autopilot did not answer in time (after the retries)."""


class MissionRejectedError(MissionError):
    """The autopilot answered MISSION_ACK with an error; ``result`` is the MAV_MISSION_RESULT."""

    def __init__(self, message: str, result: int) -> None:
        super().__init__(message)
        self.result = result


def _result_name(result: int) -> str:
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name if entry is not None else f"MAV_MISSION_RESULT {result}"


def connect(link: str, *, source_system: int = 255, source_component: int = 190) -> Any:
    """Open a pymavlink link (``udpout:HOST:PORT``, ``udpin:...``, ``tcp:...``) speaking MAVLink 2.

    Raises :class:`MissionError` when the link cannot be opened.
    """
    try:
        return open_link(
            link,
            source_system=source_system,
            source_component=source_component,
            autoreconnect=False,
        )
    except Exception as err:  # pymavlink raises OSError, ValueError, SerialException ...
        raise MissionError(f"cannot open MAVLink link {link!r}: {err}") from err


def _item_message(
    w: Waypoint,
    seq: int,
    target: tuple[int, int],
    *,
    use_int: bool,
    current: int = 0,
) -> Any:
    m = mavlink  # the dialect's message classes
    p1, p2, p3, p4 = w.params
    if use_int:
        x = round(w.lat_deg * 1e7) if w.has_position else 0
        y = round(w.lon_deg * 1e7) if w.has_position else 0
        return m.MAVLink_mission_item_int_message(
            target[0], target[1], seq, w.frame, w.command, current, int(w.autocontinue),
            p1, p2, p3, p4, x, y, w.alt_m, 0,
        )  # fmt: skip
    return m.MAVLink_mission_item_message(
        target[0], target[1], seq, w.frame, w.command, current, int(w.autocontinue),
        p1, p2, p3, p4, w.lat_deg, w.lon_deg, w.alt_m, 0,
    )  # fmt: skip


def _waypoint_from_message(msg: Any) -> Waypoint:
    """MISSION_ITEM_INT / MISSION_ITEM -> Waypoint (degE7 converted here, once)."""
    positioned = msg.frame not in _MISSION_FRAMES_WITHOUT_POSITION
    if msg.get_type() == "MISSION_ITEM_INT":
        lat, lon = msg.x / 1e7, msg.y / 1e7
    else:
        lat, lon = float(msg.x), float(msg.y)
    return Waypoint(
        lat if positioned else 0.0,
        lon if positioned else 0.0,
        float(msg.z),
        command=int(msg.command),
        frame=int(msg.frame),
        params=(float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4)),
        autocontinue=bool(msg.autocontinue),
    )


def _home_item(home: Waypoint) -> Waypoint:
    return Waypoint(
        home.lat_deg, home.lon_deg, home.alt_m, name="home",
        command=MAV_CMD_NAV_WAYPOINT, frame=MAV_FRAME_GLOBAL,
    )  # fmt: skip


def _recv(
    conn: Any, types: Sequence[str], deadline: float, peer_system: int, own_system: int
) -> Any | None:
    """Next message of ``types`` from ``peer_system`` addressed to us, or None at deadline."""
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return None
        try:
            msg = conn.recv_match(type=list(types), blocking=True, timeout=remaining)
        except OSError as err:
            raise MissionError(f"MAVLink link failed: {err}") from err
        if msg is None:
            continue
        if msg.get_srcSystem() != peer_system:
            continue
        target = getattr(msg, "target_system", own_system)
        if target not in (0, own_system):
            continue
        return msg


def _heartbeat(conn: Any, *, gcs: bool) -> None:
    m = mavlink  # the dialect's message classes
    if gcs:
        msg = m.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3
        )
    else:
        msg = m.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_QUADROTOR,
            mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
            0,
            0,
            mavlink.MAV_STATE_STANDBY,
            3,
        )
    conn.mav.send(msg)


def _wait_vehicle(conn: Any, link: str, target_system: int, timeout_s: float) -> None:
    """Send GCS heartbeats (so a listening vehicle learns our address) until the vehicle's."""
    deadline = time.monotonic() + timeout_s
    while True:
        _heartbeat(conn, gcs=True)
        beat_deadline = min(deadline, time.monotonic() + 1.0)
        while True:
            msg = _recv(conn, ["HEARTBEAT"], beat_deadline, target_system, conn.source_system)
            if msg is None or msg.type != mavlink.MAV_TYPE_GCS:
                break
        if msg is not None:
            return
        if time.monotonic() >= deadline:
            raise MissionTimeoutError(
                f"no heartbeat from system {target_system} on {link} within {timeout_s:g} s: "
                "is the autopilot connected and the link right?"
            )


@dataclass(frozen=True)
class UploadReport:
    """What an upload took: items sent (incl. home), resends, legacy requests, seconds."""

    items: int
    resends: int
    legacy_requests: int
    elapsed_s: float


def upload_mission(
    link: str | Any,
    items: Sequence[Waypoint],
    home: Waypoint | None = None,
    *,
    target_system: int = 1,
    target_component: int = 1,
    source_system: int = 255,
    source_component: int = 190,
    heartbeat_timeout_s: float = 5.0,
    item_timeout_s: float = 1.0,
    retries: int = 5,
) -> UploadReport:
    """Upload ``items`` with the MAVLink mission protocol.

    Parameters
    ----------
    link : connection string (``udpout:HOST:PORT``, ``tcp:HOST:PORT``, ...) or an open
        pymavlink connection (then it is not closed here).
    items : mission items; sent as seq 1..N after ``home``.
    home : seq 0 (ArduPilot convention: the vehicle replaces it with its real home); None
        sends ``items`` from seq 0 (PX4 convention).
    item_timeout_s, retries : resend MISSION_COUNT or the last item after this much
        silence, up to ``retries`` times in a row.

    Raises
    ------
    MissionTimeoutError
        No heartbeat, or no answer after the retries.
    MissionRejectedError
        The autopilot answered MISSION_ACK with an error (e.g. MAV_MISSION_NO_SPACE).
    """
    rows = ([_home_item(home)] if home is not None else []) + list(items)
    own = isinstance(link, str)
    conn: Any = (
        connect(link, source_system=source_system, source_component=source_component)
        if own
        else link
    )
    name = link if isinstance(link, str) else "the link"
    m = mavlink  # the dialect's message classes
    target = (target_system, target_component)
    t0 = time.monotonic()
    try:
        _wait_vehicle(conn, name, target_system, heartbeat_timeout_s)
        last = m.MAVLink_mission_count_message(target_system, target_component, len(rows), 0)
        conn.mav.send(last)
        resends = legacy = 0
        silent = 0
        highest = -1
        while True:
            msg = _recv(
                conn,
                ["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                time.monotonic() + item_timeout_s,
                target_system,
                conn.source_system,
            )
            if msg is None:
                silent += 1
                if silent > retries:
                    what = "MISSION_COUNT" if highest < 0 else f"item {highest}"
                    raise MissionTimeoutError(
                        f"the autopilot stopped answering during the mission upload on {name} "
                        f"({retries} resends of {what}, {item_timeout_s:g} s apart)"
                    )
                resends += 1
                log.debug("resending %s", last.get_type())
                conn.mav.send(last)
                continue
            silent = 0
            if getattr(msg, "mission_type", 0) != 0:
                continue
            if msg.get_type() == "MISSION_ACK":
                if msg.type != MAV_MISSION_ACCEPTED:
                    raise MissionRejectedError(
                        f"the autopilot rejected the mission: {_result_name(msg.type)}",
                        int(msg.type),
                    )
                if highest == len(rows) - 1 or not rows:
                    break
                log.debug("ignoring an early MISSION_ACK (highest item sent %d)", highest)
                continue
            seq = int(msg.seq)
            if not 0 <= seq < len(rows):
                raise MissionError(
                    f"the autopilot asked for item {seq} of a {len(rows)}-item mission"
                )
            use_int = msg.get_type() == "MISSION_REQUEST_INT"
            legacy += 0 if use_int else 1
            last = _item_message(
                rows[seq], seq, target, use_int=use_int, current=int(seq == 0 and home is not None)
            )
            conn.mav.send(last)
            highest = max(highest, seq)
        elapsed = time.monotonic() - t0
        log.info("uploaded %d mission items in %.2f s (%d resends)", len(rows), elapsed, resends)
        return UploadReport(len(rows), resends, legacy, elapsed)
    finally:
        if own:
            conn.close()


def download_mission(
    link: str | Any,
    *,
    target_system: int = 1,
    target_component: int = 1,
    source_system: int = 255,
    source_component: int = 190,
    heartbeat_timeout_s: float = 5.0,
    item_timeout_s: float = 1.0,
    retries: int = 5,
) -> list[Waypoint]:
    """Download the vehicle's mission (every item from seq 0) with MISSION_REQUEST_INT."""
    own = isinstance(link, str)
    conn: Any = (
        connect(link, source_system=source_system, source_component=source_component)
        if own
        else link
    )
    name = link if isinstance(link, str) else "the link"
    m = mavlink  # the dialect's message classes
    try:
        _wait_vehicle(conn, name, target_system, heartbeat_timeout_s)
        request: Any = m.MAVLink_mission_request_list_message(target_system, target_component, 0)
        expect = ["MISSION_COUNT"]
        count: int | None = None
        items: list[Waypoint] = []
        silent = 0
        conn.mav.send(request)
        while count is None or len(items) < count:
            msg = _recv(
                conn, expect, time.monotonic() + item_timeout_s, target_system, conn.source_system
            )
            if msg is None:
                silent += 1
                if silent > retries:
                    raise MissionTimeoutError(
                        f"the autopilot stopped answering the download on {name}"
                    )
                conn.mav.send(request)
                continue
            silent = 0
            if msg.get_type() == "MISSION_COUNT":
                if count is None:
                    count = int(msg.count)
                    expect = ["MISSION_ITEM_INT", "MISSION_COUNT"]
            elif int(msg.seq) == len(items):
                items.append(_waypoint_from_message(msg))
            if count is not None and len(items) < count:
                request = m.MAVLink_mission_request_int_message(
                    target_system, target_component, len(items), 0
                )
                conn.mav.send(request)
        conn.mav.send(
            m.MAVLink_mission_ack_message(target_system, target_component, MAV_MISSION_ACCEPTED, 0)
        )
        return items
    finally:
        if own:
            conn.close()


# ----------------------------------------------------------------------------- vehicle side


@dataclass
class _Transfer:
    peer: tuple[int, int]
    count: int
    items: list[Waypoint] = field(default_factory=list)
    last_request_ns: int = 0
    tries: int = 0


class MissionReceiver:
    """The autopilot's half of the mission protocol, without I/O.

    Feed every received message to :meth:`handle` and call :meth:`poll` regularly; send
    the messages both return (addressed to the peer). Supports upload (MISSION_COUNT ->
    MISSION_REQUEST_INT/MISSION_REQUEST per item -> MISSION_ACK), download
    (MISSION_REQUEST_LIST) and MISSION_CLEAR_ALL, for mission type 0 (waypoints).

    Parameters
    ----------
    system_id, component_id : this vehicle's ids (messages to others are ignored).
    capacity : most items it stores; a longer upload gets MAV_MISSION_NO_SPACE.
    validate : called with the complete upload; returns a MAV_MISSION_RESULT (0 accepts).
    legacy : request items with the deprecated MISSION_REQUEST (float lat/lon).
    item_timeout_s, retries : re-request an item after this much silence, then give up.
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
    ) -> None:
        self.system_id = system_id
        self.component_id = component_id
        self.capacity = capacity
        self.validate = validate
        self.legacy = legacy
        self.item_timeout_ns = round(item_timeout_s * _NS)
        self.retries = retries
        self.mission: tuple[Waypoint, ...] = ()
        self.uploads_accepted = 0
        self.last_result: int | None = None
        self._rx: _Transfer | None = None
        self._done: tuple[tuple[int, int], int, int] | None = (
            None  # last upload: peer, count, result
        )

    @property
    def receiving(self) -> bool:
        return self._rx is not None

    def _for_me(self, msg: Any) -> bool:
        ts = getattr(msg, "target_system", self.system_id)
        tc = getattr(msg, "target_component", self.component_id)
        return ts == self.system_id and tc in (0, self.component_id)

    def _ack(self, peer: tuple[int, int], result: int) -> Any:
        self.last_result = result
        return mavlink.MAVLink_mission_ack_message(peer[0], peer[1], result, 0)

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
        if getattr(msg, "mission_type", 0) != 0:
            return [self._ack(peer, mavlink.MAV_MISSION_UNSUPPORTED)]
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
            m = mavlink
            return [m.MAVLink_mission_count_message(peer[0], peer[1], len(self.mission), 0)]
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            seq = int(msg.seq)
            if not 0 <= seq < len(self.mission):
                return [self._ack(peer, mavlink.MAV_MISSION_INVALID_SEQUENCE)]
            return [
                _item_message(
                    self.mission[seq],
                    seq,
                    peer,
                    use_int=kind == "MISSION_REQUEST_INT",
                    current=int(seq == 0),
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
            return [self._request(now_ns)]
        try:
            rx.items.append(_waypoint_from_message(msg))
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


class MissionServer:
    """Play a vehicle on a MAVLink link: heartbeats at 1 Hz and a :class:`MissionReceiver`.

    Runs in a thread (use as a context manager). ``drop`` is called with each outgoing
    message; returning True drops it, to simulate a lossy link in tests.

    Parameters
    ----------
    link : e.g. ``udpin:127.0.0.1:14555`` (answers whoever speaks first) or
        ``udpout:127.0.0.1:14550`` (speaks first, e.g. to MAVProxy's ``udpin``).
    """

    def __init__(
        self,
        link: str,
        receiver: MissionReceiver | None = None,
        *,
        drop: Callable[[Any], bool] | None = None,
        heartbeat_period_s: float = 1.0,
    ) -> None:
        self.receiver = receiver if receiver is not None else MissionReceiver()
        self.link = link
        self.drop = drop
        self.heartbeat_period_s = heartbeat_period_s
        self.sent: list[str] = []
        self.dropped: list[str] = []
        self.received: list[str] = []
        self._conn: Any = None
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
        self._conn = connect(
            self.link,
            source_system=self.receiver.system_id,
            source_component=self.receiver.component_id,
        )
        self._thread = threading.Thread(target=self._run, name="mission-server", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
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

    def _send(self, out: Sequence[Any]) -> None:
        for msg in out:
            label = msg.get_type() + (f" {msg.seq}" if hasattr(msg, "seq") else "")
            if self.drop is not None and self.drop(msg):
                self.dropped.append(label)
                continue
            self.sent.append(label)
            self._conn.mav.send(msg)

    def _run(self) -> None:
        conn = self._conn
        period = self.heartbeat_period_s
        next_beat = 0.0
        known: set[object] = set()
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if now >= next_beat:
                    _heartbeat(conn, gcs=False)
                    next_beat = now + period
                msg = conn.recv_match(blocking=True, timeout=0.02)
                now_ns = time.monotonic_ns()
                before = self.receiver.uploads_accepted
                if msg is not None and msg.get_type() != "BAD_DATA":
                    self.received.append(msg.get_type())
                    clients = set(getattr(conn, "clients", ()))  # udpin: peer addresses
                    if msg.get_type() == "HEARTBEAT" and not clients <= known:
                        known |= clients
                        next_beat = 0.0  # a new peer: answer its heartbeat at once
                    self._send(self.receiver.handle(msg, now_ns))
                self._send(self.receiver.poll(now_ns))
                if self.receiver.uploads_accepted != before:
                    with self._accepted:
                        self._accepted.notify_all()
        except (OSError, ValueError) as err:
            if not self._stop.is_set():
                log.warning("mission server stopped: %s", err)
                self._error = err
        finally:
            with self._accepted:
                self._accepted.notify_all()
