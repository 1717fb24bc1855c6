"""Serve the holes found so far as a MAVLink mission, live, from the companion computer.

:class:`HoleMissionServer` answers the MAVLink mission protocol (download direction) as
component 191 (MAV_COMP_ID_ONBOARD_COMPUTER) of the vehicle's system, so a ground station
targeting that component (MAVProxy: ``--target-component 191``, then ``wp list`` /
``wp save FILE``) downloads one waypoint per hole, and announces each new or updated hole
with a STATUSTEXT ``HOLE <id> <score> <lat> <lon>`` that every GCS shows.

The mission (decided after reading MAVProxy's ``wp save`` and the QGC WPL 110 format):

* seq 0 is the **home** item, as ArduPilot and QGC WPL files have it (``wp save`` writes
  every item it downloaded; a file's line 0 is read back as home, and an ArduPilot vehicle
  overwrites item 0 with its own home on upload). It carries the vehicle's home (MAV_FRAME
  _GLOBAL, MSL) when given, else 0/0/0 like an autopilot without home.
* seq 1.. are the holes, highest confidence first (best score, then more sightings, then
  lower id): MISSION_ITEM_INT, MAV_CMD_NAV_WAYPOINT (16), MAV_FRAME_GLOBAL_RELATIVE_ALT
  (3), lat/lon in degE7, altitude ``rel_alt_m`` above home, raised to ``clearance_m``
  above the hole when the home's MSL altitude is known. The STATUSTEXT gives a hole's id;
  :meth:`HoleMissionServer.items` maps seq -> hole id.
* The list is snapshotted per requester at MISSION_REQUEST_LIST, so a download stays
  consistent while holes update; any seq may be requested in any order, repeatedly.
  MISSION_REQUEST_INT is answered with MISSION_ITEM_INT; the deprecated MISSION_REQUEST
  with MISSION_ITEM (float32 lat/lon, about 0.4 m resolution: the protocol's own limit),
  as ArduPilot does. The server never waits for MISSION_ACK (MAVProxy sends none).
* Only messages addressed to this system and component are answered (not broadcasts:
  component 0 belongs to the autopilot's own mission). Uploads are refused with
  MISSION_ACK DENIED; fence and rally lists are empty.

The link speaks MAVLink 2 (:func:`missions.open_link`): MISSION_ITEM_INT's
``mission_type`` and MAVProxy's wp module need it.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from geotag import Hole
from holescan_errors import HolescanError, InputError
from missions._holecards import CardSender, card_facts, make_card
from missions._link import mavlink, open_link

__all__ = [
    "HoleMissionServer",
    "HoleWaypoint",
    "MissionServerError",
    "hole_statustext",
    "hole_waypoints",
]

_log = logging.getLogger(__name__)

MAV_COMP_ID_ONBOARD_COMPUTER: int = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
_FRAME_GLOBAL = 0
_FRAME_GLOBAL_RELATIVE_ALT = 3
_CMD_NAV_WAYPOINT = 16
_MISSION_TYPE_MISSION = 0
_MISSION_ACCEPTED = 0
_MISSION_INVALID_SEQUENCE = 13
_MISSION_DENIED = 14
_SEVERITY_NOTICE = 5
_STATUSTEXT_MAX = 50
_MISSION_MESSAGES = frozenset(
    {
        "MISSION_REQUEST_LIST",
        "MISSION_REQUEST_INT",
        "MISSION_REQUEST",
        "MISSION_COUNT",
        "MISSION_CLEAR_ALL",
        "MISSION_ACK",
        "DATA_TRANSMISSION_HANDSHAKE",
    }
)


class MissionServerError(HolescanError):
    """The mission server's link failed or it was used wrongly."""


@dataclass(frozen=True)
class HoleWaypoint:
    """One item of the served mission.

    seq : index in the mission (0 = home).
    hole_id : :attr:`geotag.Hole.id`, None for the home item.
    frame : MAV_FRAME (0 = global MSL for home, 3 = relative to home for holes).
    command : MAV_CMD (16 = NAV_WAYPOINT).
    lat_e7, lon_e7 : WGS84 degrees * 1e7, as sent.
    alt_m : metres in ``frame``.
    """

    seq: int
    hole_id: int | None
    frame: int
    command: int
    lat_e7: int
    lon_e7: int
    alt_m: float


def _deg_e7(value: float) -> int:
    return round(value * 1e7)


def hole_waypoints(
    holes: Iterable[Hole],
    *,
    home: tuple[float, float, float] | None = None,
    rel_alt_m: float = 10.0,
    clearance_m: float = 5.0,
) -> tuple[HoleWaypoint, ...]:
    """The mission served for ``holes``: home at seq 0, then holes by confidence.

    Parameters
    ----------
    holes : holes to serve (filter by :attr:`geotag.Hole.sightings` before).
    home : (lat_deg, lon_deg, alt_m MSL) of the vehicle's home, or None when unknown.
    rel_alt_m : waypoint altitude above home, metres.
    clearance_m : when ``home`` is known, a waypoint is at least this high above its hole.
    """
    ordered = sorted(holes, key=lambda h: (-h.score, -h.sightings, h.id))
    if home is None:
        items = [HoleWaypoint(0, None, _FRAME_GLOBAL, _CMD_NAV_WAYPOINT, 0, 0, 0.0)]
    else:
        lat, lon, alt = home
        items = [
            HoleWaypoint(0, None, _FRAME_GLOBAL, _CMD_NAV_WAYPOINT, _deg_e7(lat), _deg_e7(lon), alt)
        ]
    for seq, h in enumerate(ordered, start=1):
        alt_rel = rel_alt_m
        if home is not None and math.isfinite(h.alt_m):
            alt_rel = max(rel_alt_m, h.alt_m - home[2] + clearance_m)
        items.append(
            HoleWaypoint(
                seq,
                h.id,
                _FRAME_GLOBAL_RELATIVE_ALT,
                _CMD_NAV_WAYPOINT,
                _deg_e7(h.lat_deg),
                _deg_e7(h.lon_deg),
                alt_rel,
            )
        )
    return tuple(items)


def hole_statustext(hole: Hole) -> str:
    """``HOLE <id> <score> <lat> <lon>``, at most 50 characters (STATUSTEXT's text field).

    Seven decimals (1 cm) fit for any id below 10**9; fewer are used only if needed.
    """
    for decimals in (7, 6, 5, 4):
        lat, lon = f"{hole.lat_deg:.{decimals}f}", f"{hole.lon_deg:.{decimals}f}"
        text = f"HOLE {hole.id} {hole.score:.2f} {lat} {lon}"
        if len(text) <= _STATUSTEXT_MAX:
            return text
    raise InputError(f"hole id {hole.id} too long for a STATUSTEXT")


class HoleMissionServer:
    """Live MAVLink mission server for found holes (a background thread).

    Parameters
    ----------
    connection_string : pymavlink connection, e.g. ``udpout:127.0.0.1:14550`` (towards a
        GCS or router), ``udpin:0.0.0.0:14560``, ``tcp:HOST:PORT``, a serial device.
    sysid : the vehicle's system id (GCS modules only listen to their target system).
    compid : our component id (191 = onboard computer).
    home : (lat_deg, lon_deg, alt_m MSL) of the vehicle's home, if known (see
        :meth:`set_home`).
    rel_alt_m, clearance_m : waypoint altitude, see :func:`hole_waypoints`.
    heartbeat_period_s : HEARTBEAT interval (MAV_TYPE_ONBOARD_CONTROLLER).
    card_bytes_per_s : byte budget of the hole cards (best view + facts, see
        :mod:`missions._holecards`) sent by :meth:`send_card`.

    Use as a context manager; the link opens on enter and closes on exit. Errors of the
    background thread are raised as :class:`MissionServerError` by :meth:`close`.
    """

    def __init__(
        self,
        connection_string: str,
        sysid: int,
        compid: int = MAV_COMP_ID_ONBOARD_COMPUTER,
        *,
        home: tuple[float, float, float] | None = None,
        rel_alt_m: float = 10.0,
        clearance_m: float = 5.0,
        heartbeat_period_s: float = 1.0,
        card_bytes_per_s: float = 1000.0,
    ) -> None:
        if not (1 <= sysid <= 255 and 1 <= compid <= 255):
            raise InputError(f"sysid and compid must be 1..255, got {sysid}, {compid}")
        self.connection_string = connection_string
        self.sysid = sysid
        self.compid = compid
        self.rel_alt_m = rel_alt_m
        self.clearance_m = clearance_m
        self.heartbeat_period_s = heartbeat_period_s
        self._home = home
        self._holes: tuple[Hole, ...] = ()
        self._items = hole_waypoints((), home=home, rel_alt_m=rel_alt_m, clearance_m=clearance_m)
        self._snapshots: dict[tuple[int, int], tuple[HoleWaypoint, ...]] = {}
        self._state_lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._conn: Any = None
        self._error: BaseException | None = None
        self.items_sent = 0
        self.cards = CardSender(bytes_per_s=card_bytes_per_s)
        self._card_revs: dict[int, int] = {}

    # -- lifecycle -----------------------------------------------------------------------
    def __enter__(self) -> HoleMissionServer:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def start(self) -> None:
        """Open the link and start answering."""
        if self._thread is not None:
            raise MissionServerError("server already started")
        try:
            self._conn = open_link(
                self.connection_string, source_system=self.sysid, source_component=self.compid
            )
        except Exception as err:  # pymavlink raises OSError, ValueError, SerialException ...
            raise MissionServerError(f"cannot open {self.connection_string!r}: {err}") from err
        self._thread = threading.Thread(target=self._run, name="hole-mission-server", daemon=True)
        self._thread.start()
        _log.info(
            "hole mission server on %s as %d/%d", self.connection_string, self.sysid, self.compid
        )

    def close(self) -> None:
        """Stop the thread and close the link; raise the thread's error if it had one."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._error is not None:
            err, self._error = self._error, None
            raise MissionServerError(f"mission server failed: {err}") from err

    # -- what we serve -------------------------------------------------------------------
    def update_holes(self, holes: Iterable[Hole]) -> None:
        """Replace the served holes (downloads already under way keep their snapshot)."""
        holes = tuple(holes)
        with self._state_lock:
            self._holes = holes
            self._rebuild()

    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Set the vehicle's home (MSL altitude), e.g. from HOME_POSITION."""
        with self._state_lock:
            self._home = (lat_deg, lon_deg, alt_m)
            self._rebuild()

    def _rebuild(self) -> None:
        self._items = hole_waypoints(
            self._holes, home=self._home, rel_alt_m=self.rel_alt_m, clearance_m=self.clearance_m
        )

    def items(self) -> tuple[HoleWaypoint, ...]:
        """The mission a new download gets now (seq 0 = home)."""
        with self._state_lock:
            return self._items

    def announce(self, hole: Hole) -> str:
        """Send STATUSTEXT ``HOLE <id> <score> <lat> <lon>`` (severity NOTICE); return it."""
        text = hole_statustext(hole)
        self._send(lambda mav: mav.statustext_send(_SEVERITY_NOTICE, text.encode("ascii")))
        _log.info("announced %s", text)
        return text

    def send_card(self, hole: Hole, jpeg: bytes, why: str = "") -> int:
        """Queue hole ``hole``'s card (its best view ``jpeg`` and facts); return its size.

        Sent under the byte budget by the server's thread; a newer card of the same hole
        replaces one not yet started.
        """
        with self._state_lock:
            rev = self._card_revs.get(hole.id, 0) + 1
            self._card_revs[hole.id] = rev
            card = make_card(jpeg, card_facts(hole, why, rev))
            self.cards.put(hole.id, card)
        return len(card)

    def flush_cards(self, timeout_s: float = 10.0) -> bool:
        """Wait (at most ``timeout_s``) until every queued card is sent; True when done."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._state_lock:
                if self.cards.pending == 0:
                    return True
            time.sleep(0.1)
        return False

    # -- the link ------------------------------------------------------------------------
    def _send(self, fn: Any) -> None:
        conn = self._conn
        if conn is None:
            raise MissionServerError("server is not running: use it as a context manager")
        with self._send_lock:
            fn(conn.mav)

    def _run(self) -> None:
        next_heartbeat = time.monotonic()
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if now >= next_heartbeat:
                    self._send(
                        lambda mav: mav.heartbeat_send(
                            mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                            mavlink.MAV_AUTOPILOT_INVALID,
                            0,
                            0,
                            mavlink.MAV_STATE_ACTIVE,
                        )
                    )
                    next_heartbeat = now + self.heartbeat_period_s
                try:
                    msg = self._conn.recv_match(
                        type=list(_MISSION_MESSAGES), blocking=True, timeout=0.1
                    )
                except OSError as err:
                    _log.warning("mission server link error: %s", err)
                    self._stop.wait(0.5)
                    continue
                if msg is not None:
                    self._handle(msg)
                with self._state_lock:
                    self.cards.pump(self._send)
        except Exception as err:  # surfaced by close()
            _log.exception("mission server thread failed")
            self._error = err

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "DATA_TRANSMISSION_HANDSHAKE":  # no target fields: any peer may ask
            if msg.size == 0 and msg.packets == 0:  # a ground station asks for every card
                _log.info("hole cards requested again by %s", peer)
                with self._state_lock:
                    self.cards.resend_all()
            return
        if msg.target_system != self.sysid or msg.target_component != self.compid:
            return
        mission_type = getattr(msg, "mission_type", _MISSION_TYPE_MISSION)
        if kind == "MISSION_ACK":
            _log.debug("MISSION_ACK %d from %s", msg.type, peer)
            return
        if kind in ("MISSION_COUNT", "MISSION_CLEAR_ALL"):
            _log.info("refusing %s from %s: the hole mission is read-only", kind, peer)
            self._ack(peer, _MISSION_DENIED, mission_type)
            return
        if mission_type != _MISSION_TYPE_MISSION:
            if kind == "MISSION_REQUEST_LIST":
                self._send(lambda mav: mav.mission_count_send(*peer, 0, mission_type))
            else:
                self._ack(peer, _MISSION_INVALID_SEQUENCE, mission_type)
            return
        if kind == "MISSION_REQUEST_LIST":
            with self._state_lock:
                snapshot = self._items
                self._snapshots[peer] = snapshot
            _log.info("mission list requested by %s: %d items", peer, len(snapshot))
            self._send(lambda mav: mav.mission_count_send(*peer, len(snapshot), mission_type))
            return
        with self._state_lock:
            snapshot = self._snapshots.setdefault(peer, self._items)
        seq = msg.seq
        if not 0 <= seq < len(snapshot):
            _log.info(
                "%s for seq %d from %s: out of range (%d items)", kind, seq, peer, len(snapshot)
            )
            self._ack(peer, _MISSION_INVALID_SEQUENCE, mission_type)
            return
        item = snapshot[seq]
        # seq, frame, command, current, autocontinue, param1..param4
        head = (seq, item.frame, item.command, 0, 1, 0.0, 0.0, 0.0, 0.0)
        if kind == "MISSION_REQUEST_INT":
            x: float = item.lat_e7
            y: float = item.lon_e7
            send = "mission_item_int_send"
        else:  # legacy MISSION_REQUEST -> MISSION_ITEM, float32 degrees
            x, y = item.lat_e7 * 1e-7, item.lon_e7 * 1e-7
            send = "mission_item_send"
        self._send(lambda mav: getattr(mav, send)(*peer, *head, x, y, item.alt_m, mission_type))
        self.items_sent += 1

    def _ack(self, peer: tuple[int, int], result: int, mission_type: int) -> None:
        self._send(lambda mav: mav.mission_ack_send(*peer, result, mission_type))
