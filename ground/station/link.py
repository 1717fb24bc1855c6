"""The ground station's MAVLink side: a second ground station on the vehicle's stream.

Fed by MAVProxy (``--out udpout:LAPTOP:PORT`` -> ``udpin:0.0.0.0:PORT`` here), a UDP port
or a serial radio, :class:`VehicleLink` (one thread) takes from the stream:

* ``STATUSTEXT`` ``HOLE <id> <score> <lat> <lon>`` from the companion computer: a hole,
  at once;
* the image transmission protocol from component 191 (``DATA_TRANSMISSION_HANDSHAKE`` +
  ``ENCAPSULATED_DATA``): hole cards, picture and facts (:func:`missions.read_card`), and
  the live map's tiles (:func:`missions.is_map_tile`), kept in the ``map_store``;
* ``GLOBAL_POSITION_INT`` / ``ATTITUDE`` from the autopilot: the track (1 point/s kept),
  decoded by the link's one MAVLink adapter (:func:`link.position_from_global_position_int`);
* the hole mission of component 191, downloaded by this thread itself (the MAVLink
  mission protocol, MISSION_REQUEST_LIST -> COUNT -> REQUEST_INT per seq -> ITEM_INT, each
  item read by :func:`missions.waypoint_from_mission_item`) a few seconds after each new
  hole and every ``mission_period_s``, without stopping the other traffic.

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
from holescan.ground.station.state import StationState, TrackPoint
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
SECOND_GCS_SYSID = 254
"""The station's system id: 255 is usually the main ground station's (QGC, Mission Planner)."""
_WANTED = [
    "HEARTBEAT",
    "STATUSTEXT",
    "DATA_TRANSMISSION_HANDSHAKE",
    "ENCAPSULATED_DATA",
    "GLOBAL_POSITION_INT",
    "ATTITUDE",
    "MISSION_COUNT",
    "MISSION_ITEM_INT",
]


class VehicleLink:
    """See the module docstring. Use as a context manager (starts/stops the thread).

    connection : pymavlink connection string (``udpin:0.0.0.0:14551``, ``/dev/ttyUSB0``).
    sysid : the vehicle's system id (None: the first one heard).
    source_system, source_component : who we are on the link (a GCS: system 255 is usually
        taken by the main GCS, so :data:`SECOND_GCS_SYSID` and the dialect's
        ``MAV_COMP_ID_MISSIONPLANNER`` by default).
    clock : monotonic seconds, for the link's timeouts (the track's times are the state's
        Unix clock).
    map_store : where the live map's tiles go (None: they are ignored).
    signing : MAVLink 2 signing key shared with the vehicle (None: unsigned). With one,
        what this link sends is signed and every unsigned or badly signed packet is
        dropped: a forger's HOLE STATUSTEXT, cards and mission items are never seen.
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
        self.clock = clock
        self.cards = CardAssembler()
        self.messages = 0
        self.bad = 0
        self.resync_requests = 0
        self.missions_downloaded = 0
        self.link_up = False
        self._conn: MavConnection | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="vehicle-link", daemon=True)
        self._last_rx = -math.inf
        self._next_mission = math.inf
        self._mission: dict[str, Any] | None = None
        self._yaw = 0.0
        self._missing_before: frozenset[int] = frozenset()
        self._open_failed = False

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
                self.link_up = False
                self._stop.wait(2.0)
                continue
            now = self.clock()
            if msg is None:
                if self.link_up and now - self._last_rx > self.silence_s:
                    _log.warning(
                        "no MAVLink from the vehicle for %.0f s (link cut?); keeping all holes",
                        now - self._last_rx,
                    )
                    self.link_up = False
                self._tick(now)
                continue
            try:
                self._handle(msg, now)
            except Exception as err:  # one malformed message must not stop the station
                self.bad += 1
                _log.warning("ignored a bad %s message: %s", msg.get_type(), err)
            self._tick(now)

    def _tick(self, now: float) -> None:
        if now >= self._next_mission and self._mission is None and self.link_up:
            self._start_mission_download(now)
        m = self._mission
        if m is not None and now - m["t"] > 1.5:
            if m["tries"] >= 4:
                _log.warning("hole mission download gave up (no answer); will try again")
                self._mission = None
                self._next_mission = now + self.mission_period_s
            else:
                m["tries"] += 1
                m["t"] = now
                self._request_next()

    def _vehicle(self, msg: Any) -> bool:
        sysid = msg.get_srcSystem()
        if (
            self.sysid is None
            and msg.get_type() == "HEARTBEAT"
            and msg.type != mavlink.MAV_TYPE_GCS
        ):
            self.sysid = sysid
            _log.info("vehicle is system %d", sysid)
        return self.sysid is not None and sysid == self.sysid

    def _handle(self, msg: Any, now: float) -> None:
        if msg.get_type() == "BAD_DATA":
            self.bad += 1
            return
        if not self._vehicle(msg):
            return
        self.messages += 1
        if not self.link_up:
            self.link_up = True
            _log.info("vehicle link up; asking the companion for every hole card")
            self._request_cards()
            self._next_mission = min(self._next_mission, now + 2.0)
        self._last_rx = now
        kind = msg.get_type()
        comp = msg.get_srcComponent()
        if kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode("ascii", "replace")
            if self.state.on_statustext(text) is not None:
                self._next_mission = min(self._next_mission, now + 3.0)
        elif kind in ("DATA_TRANSMISSION_HANDSHAKE", "ENCAPSULATED_DATA") and comp == _COMPANION:
            card = self.cards.add(msg)
            if card is not None and is_map_tile(card):
                self.tiles_received += 1
                if self.map_store is not None:
                    self.map_store.put(card)
            elif card is not None:
                facts = read_card(card)
                if facts is None:
                    self.bad += 1
                    _log.warning("a picture without hole facts was ignored")
                else:
                    h = self.state.on_card(facts, card)
                    if h is not None and h.seq is None:  # not yet seen in the mission
                        self._next_mission = min(self._next_mission, now + 2.0)
        elif kind == "ATTITUDE":
            try:
                self._yaw = link_yaw(msg.yaw)
            except LinkValueError as err:
                self.state.reject("an ATTITUDE", err)
        elif kind == "GLOBAL_POSITION_INT" and comp != _COMPANION:
            p = position_from_global_position_int(msg)
            if p.lat_deg == 0 and p.lon_deg == 0:  # no fix yet
                return
            t_unix_ns = self.state.clock()
            self.state.on_position(
                TrackPoint(t_unix_ns, p.lat_deg, p.lon_deg, p.rel_alt_m, self._yaw)
            )
        elif kind in ("MISSION_COUNT", "MISSION_ITEM_INT") and comp == _COMPANION:
            self._mission_reply(msg, now)

    # -- requests to the companion ----------------------------------------------------------
    def _send(self, fn: Callable[[Any], object]) -> None:
        if self._conn is None:
            return
        try:
            fn(self._conn.mav)
        except Exception as err:  # udpin before the peer spoke, a full serial buffer
            _log.debug("send failed: %s", err)

    def _request_cards(self) -> None:
        self.resync_requests += 1
        inv = self.map_store.inventory() if self.map_store is not None else None
        if inv is not None:  # first what it holds: only the other tiles come again
            self._send(lambda mav: send_inventory(mav, inv))
        self._send(
            lambda mav: mav.data_transmission_handshake_send(
                mavlink.MAVLINK_DATA_STREAM_IMG_JPEG, 0, 0, 0, 0, 0, 0
            )
        )

    def _start_mission_download(self, now: float) -> None:
        self._mission = {"t": now, "tries": 0, "count": None, "items": {}}
        self._request_next()

    def _request_next(self) -> None:
        m = self._mission
        assert m is not None and self.sysid is not None
        target = (self.sysid, _COMPANION)
        if m["count"] is None:
            self._send(
                lambda mav: mav.mission_request_list_send(*target, mavlink.MAV_MISSION_TYPE_MISSION)
            )
            return
        seq = len(m["items"])
        self._send(
            lambda mav: mav.mission_request_int_send(*target, seq, mavlink.MAV_MISSION_TYPE_MISSION)
        )

    def _mission_reply(self, msg: Any, now: float) -> None:
        m = self._mission
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
            self._mission = None
            self._next_mission = now + self.mission_period_s
            self.missions_downloaded += 1
            holes = [m["items"][s] for s in range(1, m["count"])]  # seq 0 is home
            unknown = self.state.on_mission(holes)
            if unknown:
                _log.info("%d served waypoints are not known here; asking for cards", unknown)
                self._request_cards()
            # holes heard of (STATUSTEXT, card) but not in this mission: it was snapshotted
            # before they were served; look again soon, once per new set of them
            _, known, _ = self.state.snapshot()
            missing = frozenset(h.id for h in known if h.seq is None and h.mark != "rejected")
            if missing and missing != self._missing_before:
                self._next_mission = now + 3.0
            self._missing_before = missing
            return
        self._request_next()
