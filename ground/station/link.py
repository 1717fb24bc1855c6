"""The ground station's MAVLink side: a second ground station on the vehicles' stream.

Fed by MAVProxy (``--out udpout:LAPTOP:PORT`` -> ``udpin:0.0.0.0:PORT`` here), a UDP port
or a serial radio, :class:`VehicleLink` (one thread) takes from the stream:

* ``STATUSTEXT`` ``HOLE <id> <score> <lat> <lon>`` from the companion computer: a hole,
  at once;
* the image transmission protocol from component 191 (``DATA_TRANSMISSION_HANDSHAKE`` +
  ``ENCAPSULATED_DATA``): hole cards, picture and facts (:func:`missions.read_card`), and
  the live map's tiles (:func:`missions.is_map_tile`), kept in the ``map_store``;
* ``GLOBAL_POSITION_INT`` / ``ATTITUDE`` from the autopilot: the track (1 point/s kept),
  decoded by the link's one MAVLink adapter (:func:`link.position_from_global_position_int`);
  with ``HEARTBEAT``, ``SYS_STATUS``, ``BATTERY_STATUS``, ``RADIO_STATUS``,
  ``HOME_POSITION``, ``MOUNT_ORIENTATION`` and every packet's sequence number: the
  vehicle's status (:class:`~ground.station.vehicles.VehicleStatus`: mode, armed,
  battery, link quality, home, the camera mount). When the autopilot is heard but one of
  position, attitude, system status or home does not come within ``streams_after_s``, the
  link asks the autopilot for that one only (``MAV_CMD_SET_MESSAGE_INTERVAL``, home by
  ``MAV_CMD_REQUEST_MESSAGE``), again every 10 s while it stays missing, at most 3 times;
* the hole mission of component 191, downloaded by this thread itself (the MAVLink
  mission protocol, MISSION_REQUEST_LIST -> COUNT -> REQUEST_INT per seq -> ITEM_INT, each
  item read by :func:`missions.waypoint_from_mission_item`) a few seconds after each new
  hole and every ``mission_period_s``, without stopping the other traffic.

Every vehicle heard is followed (``sysid`` None; one id: that vehicle only): each system
id that sends a HEARTBEAT other than a ground station's, with its own card assembly, hole
mission download and status; several links (one :class:`VehicleLink` each) feed one
:class:`~ground.station.state.StationState`, which keeps one id per opening across them.

After a silence longer than ``silence_s`` (a cut radio, a restarted MAVProxy) or at start,
it asks component 191 for every card again (DATA_TRANSMISSION_HANDSHAKE with size 0),
first saying which live-map tiles it holds (:func:`missions.send_inventory`: only the
others are sent again), and also when the mission has waypoints no known hole explains:
holes announced while the link was down are caught up. A link that cannot be opened,
dies or delivers garbage is reported in one log line and retried; nothing collected is
lost (it is in the state). Every value taken is checked first (:mod:`link._values`,
through the state: a NaN yaw, a position off the Earth, an id out of range is counted in
the state's ``rejected`` and logged, never kept).
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from holescan.ground.station.mapstore import MapStore
from holescan.ground.station.records import TrackPoint
from holescan.ground.station.state import StationState
from holescan.link import (
    LinkValueError,
    MavConnection,
    SigningKey,
    link_int,
    link_yaw,
    mavlink,
    open_link,
    position_from_global_position_int,
)
from holescan.missions import (
    CardAssembler,
    is_map_tile,
    read_card,
    send_inventory,
    waypoint_from_mission_item,
)

__all__ = ["SECOND_GCS_SYSID", "VehicleLink"]

_log = logging.getLogger(__name__)

_COMPANION = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
_AUTOPILOT = mavlink.MAV_COMP_ID_AUTOPILOT1
SECOND_GCS_SYSID = 254
"""The station's system id: 255 is usually the main ground station's (QGC, Mission Planner)."""
_STATUS = (
    "HEARTBEAT",
    "SYS_STATUS",
    "BATTERY_STATUS",
    "RADIO_STATUS",
    "HOME_POSITION",
    "MOUNT_ORIENTATION",
)
_WANTED = [
    *_STATUS,
    "STATUSTEXT",
    "DATA_TRANSMISSION_HANDSHAKE",
    "ENCAPSULATED_DATA",
    "GLOBAL_POSITION_INT",
    "ATTITUDE",
    "MISSION_COUNT",
    "MISSION_ITEM_INT",
]
_STREAMS = {  # what the page needs from the autopilot -> the rate asked, Hz (0: once)
    "GLOBAL_POSITION_INT": 2.0,
    "ATTITUDE": 2.0,
    "SYS_STATUS": 1.0,
    "HOME_POSITION": 0.0,
}
_STREAM_RETRY_S = 10.0
_STREAM_TRIES = 3


class _Peer:
    """What the link keeps of one vehicle (one system id) while it runs."""

    def __init__(self, sysid: int) -> None:
        self.sysid = sysid
        self.cards = CardAssembler()
        self.link_up = False
        self.last_rx = -math.inf
        self.next_mission = math.inf
        self.mission: dict[str, Any] | None = None
        self.yaw = 0.0
        self.missing_before: frozenset[int] = frozenset()
        self.autopilot_since: float | None = None  # first autopilot HEARTBEAT (monotonic s)
        self.heard: set[str] = set()
        self.asked: dict[str, tuple[int, float]] = {}  # message -> (tries, when)


class VehicleLink:
    """See the module docstring. Use as a context manager (starts/stops the thread).

    connection : pymavlink connection string (``udpin:0.0.0.0:14551``, ``/dev/ttyUSB0``).
    sysid : the vehicle's system id (None: every vehicle heard).
    source_system, source_component : who we are on the link (a GCS: system 255 is usually
        taken by the main GCS, so :data:`SECOND_GCS_SYSID` and the dialect's
        ``MAV_COMP_ID_MISSIONPLANNER`` by default).
    clock : monotonic seconds, for the link's timeouts (the track's times are the state's
        Unix clock).
    map_store : where the live map's tiles go (None: they are ignored).
    signing : MAVLink 2 signing key shared with the vehicle (None: unsigned). With one,
        what this link sends is signed and every unsigned or badly signed packet is
        dropped: a forger's HOLE STATUSTEXT, cards and mission items are never seen.
    streams_after_s : how long the autopilot may be heard without a message the page
        needs before that message is asked for (None: never ask).
    """

    def __init__(
        self,
        connection: str,
        state: StationState,
        *,
        sysid: int | None = None,
        source_system: int = SECOND_GCS_SYSID,
        source_component: int = mavlink.MAV_COMP_ID_MISSIONPLANNER,
        baud: int = 57600,
        silence_s: float = 3.0,
        mission_period_s: float = 30.0,
        clock: Callable[[], float] = time.monotonic,
        map_store: MapStore | None = None,
        signing: SigningKey | None = None,
        streams_after_s: float | None = 3.0,
    ) -> None:
        self.connection = connection
        self.map_store = map_store
        self.tiles_received = 0
        self.signing = signing
        self.state = state
        self.sysid = sysid
        self.source_system = source_system
        self.source_component = source_component
        self.baud = baud
        self.silence_s = silence_s
        self.mission_period_s = mission_period_s
        self.streams_after_s = streams_after_s
        self.clock = clock
        self.messages = 0
        self.bad = 0
        self.resync_requests = 0
        self.missions_downloaded = 0
        self.streams_requested: list[tuple[int, str]] = []
        """(system id, message) of every stream this link asked an autopilot for."""
        self.peers: dict[int, _Peer] = {}
        self._conn: MavConnection | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="vehicle-link", daemon=True)
        self._open_failed = False

    @property
    def link_up(self) -> bool:
        """Whether any vehicle is heard on this link now."""
        return any(p.link_up for p in self.peers.values())

    def __enter__(self) -> VehicleLink:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    # -- the thread -------------------------------------------------------------------
    def _open(self) -> bool:
        try:
            self._conn = open_link(
                self.connection,
                source_system=self.source_system,
                source_component=self.source_component,
                baud=self.baud,
                signing=self.signing,
            )
        except Exception as err:  # pymavlink: OSError, ValueError, SerialException
            if not self._open_failed:  # one line, not one every retry
                _log.error(
                    "cannot open the MAVLink link %r: %s; retrying every 5 s",
                    self.connection,
                    err,
                )
            self._open_failed = True
            return False
        self._open_failed = False
        _log.info(
            "listening for the vehicle on %s%s",
            self.connection,
            "" if self.signing is None else f", MAVLink signed ({self.signing})",
        )
        return True

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._conn is None and not self._open():
                self._stop.wait(5.0)
                continue
            conn = self._conn
            assert conn is not None
            try:
                msg = conn.recv_match(type=_WANTED, blocking=True, timeout=0.2)
            except Exception as err:  # a dead serial port, a closed socket
                _log.warning("MAVLink link %r failed (%s); reopening", self.connection, err)
                with contextlib.suppress(Exception):
                    conn.close()
                self._conn = None
                for p in self.peers.values():
                    p.link_up = False
                self._stop.wait(2.0)
                continue
            now = self.clock()
            if msg is not None:
                try:
                    self._handle(msg, now)
                except Exception as err:  # one malformed message must not stop the station
                    self.bad += 1
                    _log.warning("ignored a bad %s message: %s", msg.get_type(), err)
            for peer in list(self.peers.values()):
                self._tick(peer, now)

    def _tick(self, peer: _Peer, now: float) -> None:
        if peer.link_up and now - peer.last_rx > self.silence_s:
            _log.warning(
                "no MAVLink from vehicle %d for %.0f s (link cut?); keeping all holes",
                peer.sysid,
                now - peer.last_rx,
            )
            peer.link_up = False
        if now >= peer.next_mission and peer.mission is None and peer.link_up:
            self._start_mission_download(peer, now)
        m = peer.mission
        if m is not None and now - m["t"] > 1.5:
            if m["tries"] >= 4:
                _log.warning("hole mission download gave up (no answer); will try again")
                peer.mission = None
                peer.next_mission = now + self.mission_period_s
            else:
                m["tries"] += 1
                m["t"] = now
                self._request_next(peer)
        self._ask_streams(peer, now)

    def _peer(self, msg: Any) -> _Peer | None:
        """The vehicle ``msg`` is from (a new one on its first HEARTBEAT that is not a
        ground station's), or None for anyone else."""
        sysid = msg.get_srcSystem()
        peer = self.peers.get(sysid)
        if peer is not None:
            return peer
        if self.sysid is not None and sysid != self.sysid:
            return None
        if msg.get_type() != "HEARTBEAT" or msg.type == mavlink.MAV_TYPE_GCS:
            return None
        if not 1 <= sysid <= 255 or sysid == self.source_system:
            return None
        peer = self.peers[sysid] = _Peer(sysid)
        _log.info("vehicle system %d heard on %s", sysid, self.connection)
        return peer

    def _handle(self, msg: Any, now: float) -> None:
        if msg.get_type() == "BAD_DATA":
            self.bad += 1
            return
        peer = self._peer(msg)
        if peer is None:
            return
        self.messages += 1
        if not peer.link_up:
            peer.link_up = True
            _log.info("vehicle %d link up; asking the companion for every hole card", peer.sysid)
            self._request_cards(peer)
            peer.next_mission = min(peer.next_mission, now + 2.0)
        peer.last_rx = now
        kind = msg.get_type()
        comp = msg.get_srcComponent()
        self._status(peer, msg, kind, comp, now)
        if kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode("ascii", "replace")
            if self.state.on_statustext(text, sysid=peer.sysid) is not None:
                peer.next_mission = min(peer.next_mission, now + 3.0)
        elif kind in ("DATA_TRANSMISSION_HANDSHAKE", "ENCAPSULATED_DATA") and comp == _COMPANION:
            card = peer.cards.add(msg)
            if card is not None and is_map_tile(card):
                self.tiles_received += 1
                if self.map_store is not None:
                    self.map_store.put(card, peer.sysid)
            elif card is not None:
                facts = read_card(card)
                if facts is None:
                    self.bad += 1
                    _log.warning("a picture without hole facts was ignored")
                else:
                    h = self.state.on_card(facts, card, sysid=peer.sysid)
                    if h is not None and h.seq is None:  # not yet seen in the mission
                        peer.next_mission = min(peer.next_mission, now + 2.0)
        elif kind == "ATTITUDE":
            with contextlib.suppress(LinkValueError):  # counted once, by on_vehicle_message
                peer.yaw = link_yaw(msg.yaw)
        elif kind == "GLOBAL_POSITION_INT" and comp != _COMPANION:
            p = position_from_global_position_int(msg)
            if p.lat_deg == 0 and p.lon_deg == 0:  # no fix yet
                return
            t_unix_ns = self.state.clock()
            self.state.on_position(
                TrackPoint(t_unix_ns, p.lat_deg, p.lon_deg, p.rel_alt_m, peer.yaw, peer.sysid)
            )
        elif kind in ("MISSION_COUNT", "MISSION_ITEM_INT") and comp == _COMPANION:
            self._mission_reply(peer, msg, now)

    def _status(self, peer: _Peer, msg: Any, kind: str, comp: int, now: float) -> None:
        """The vehicle's status (:class:`~ground.station.vehicles.VehicleStatus`)."""
        if comp == _COMPANION and kind != "RADIO_STATUS":  # the companion's own heartbeat
            self.state.on_vehicle_packet(peer.sysid, self.connection, comp, msg.get_seq(), now)
            return
        autopilot = kind == "HEARTBEAT" and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID
        if autopilot and peer.autopilot_since is None:
            peer.autopilot_since = now
        if kind in _STREAMS:
            peer.heard.add(kind)
        self.state.on_vehicle_packet(peer.sysid, self.connection, comp, msg.get_seq(), now)
        if kind in _STATUS or kind in ("GLOBAL_POSITION_INT", "ATTITUDE"):
            self.state.on_vehicle_message(peer.sysid, msg)

    def _ask_streams(self, peer: _Peer, now: float) -> None:
        """Ask the autopilot for what the page needs and does not get (module docstring)."""
        if self.streams_after_s is None or peer.autopilot_since is None:
            return
        if now - peer.autopilot_since < self.streams_after_s:
            return
        for name, hz in _STREAMS.items():
            if name in peer.heard:
                continue
            tries, when = peer.asked.get(name, (0, -math.inf))
            if tries >= _STREAM_TRIES or now - when < _STREAM_RETRY_S:
                continue
            peer.asked[name] = (tries + 1, now)
            msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
            if hz > 0:  # an interval, or the message once
                cmd, p2 = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, round(1e6 / hz)
            else:
                cmd, p2 = mavlink.MAV_CMD_REQUEST_MESSAGE, 0
            self._send(_command(peer.sysid, cmd, msg_id, p2))
            self.streams_requested.append((peer.sysid, name))
            _log.info("vehicle %d: no %s heard; asked its autopilot for it", peer.sysid, name)

    # -- requests to the companion ----------------------------------------------------------
    def _send(self, fn: Callable[[Any], object]) -> None:
        if self._conn is None:
            return
        try:
            fn(self._conn.mav)
        except Exception as err:  # udpin before the peer spoke, a full serial buffer
            _log.debug("send failed: %s", err)

    def _request_cards(self, peer: _Peer) -> None:
        self.resync_requests += 1
        inv = self.map_store.inventory(peer.sysid) if self.map_store is not None else None
        if inv is not None:  # first what it holds: only the other tiles come again
            self._send(lambda mav: send_inventory(mav, inv))
        self._send(
            lambda mav: mav.data_transmission_handshake_send(
                mavlink.MAVLINK_DATA_STREAM_IMG_JPEG, 0, 0, 0, 0, 0, 0
            )
        )

    def _start_mission_download(self, peer: _Peer, now: float) -> None:
        peer.mission = {"t": now, "tries": 0, "count": None, "items": {}}
        self._request_next(peer)

    def _request_next(self, peer: _Peer) -> None:
        m = peer.mission
        assert m is not None
        target = (peer.sysid, _COMPANION)
        if m["count"] is None:
            self._send(
                lambda mav: mav.mission_request_list_send(*target, mavlink.MAV_MISSION_TYPE_MISSION)
            )
            return
        seq = len(m["items"])
        self._send(
            lambda mav: mav.mission_request_int_send(*target, seq, mavlink.MAV_MISSION_TYPE_MISSION)
        )

    def _mission_reply(self, peer: _Peer, msg: Any, now: float) -> None:
        m = peer.mission
        if m is None:
            return
        if msg.get_type() == "MISSION_COUNT":
            if m["count"] is None:
                try:  # seq 0 is home; at most as many holes as the state keeps
                    m["count"] = link_int(msg.count, 0, self.state.max_holes + 1, "item count")
                except LinkValueError as err:
                    self.state.reject("a MISSION_COUNT", err)
                    return
        elif m["count"] is not None and msg.seq == len(m["items"]):
            w = waypoint_from_mission_item(msg)
            m["items"][int(msg.seq)] = (int(msg.seq), w.lat_deg, w.lon_deg)
        else:
            return
        m["t"], m["tries"] = now, 0
        if len(m["items"]) >= m["count"]:
            peer.mission = None
            peer.next_mission = now + self.mission_period_s
            self.missions_downloaded += 1
            holes = [m["items"][s] for s in range(1, m["count"])]  # seq 0 is home
            unknown = self.state.on_mission(holes, sysid=peer.sysid)
            if unknown:
                _log.info("%d served waypoints are not known here; asking for cards", unknown)
                self._request_cards(peer)
            # holes heard of (STATUSTEXT, card) but not in this mission: it was snapshotted
            # before they were served; look again soon, once per new set of them
            missing = self.state.missing_from_mission(peer.sysid)
            if missing and missing != peer.missing_before:
                peer.next_mission = now + 3.0
            peer.missing_before = missing
            return
        self._request_next(peer)


def _command(sysid: int, cmd: int, p1: float, p2: float) -> Callable[[Any], object]:
    """A COMMAND_LONG to vehicle ``sysid``'s autopilot (fire and forget: the stream that
    comes, or not, is the answer)."""

    def send(mav: Any) -> object:
        return mav.command_long_send(sysid, _AUTOPILOT, cmd, 0, p1, p2, 0, 0, 0, 0, 0)

    return send
