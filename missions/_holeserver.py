"""Serve the holes found so far as a MAVLink mission, live, from the companion computer.

:class:`HoleMissionServer` answers the MAVLink mission protocol (download direction) as
component 191 (MAV_COMP_ID_ONBOARD_COMPUTER) of the vehicle's system, so a ground station
targeting that component (MAVProxy: ``--target-component 191``, then ``wp list`` /
``wp save FILE``) downloads one waypoint per hole, and announces each new or updated hole
with a STATUSTEXT ``HOLE <id> p<p_hole> <lat> <lon>`` that every GCS shows. Holes for
review (:meth:`geotag.AnnounceGate.tier`) are not in the mission: they get a STATUSTEXT
``REVIEW <id> ...`` and a card whose facts say ``"tier": "review"``, sent after the
announced holes' cards under the same byte budget.

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
* The protocol is the one vehicle-side implementation, :class:`missions.MissionReceiver`
  (read-only): the list is snapshotted per requester at MISSION_REQUEST_LIST, so a
  download stays consistent while holes update; any seq may be requested in any order,
  repeatedly. MISSION_REQUEST_INT is answered with MISSION_ITEM_INT; the deprecated
  MISSION_REQUEST with MISSION_ITEM (float32 lat/lon, about 0.4 m resolution: the
  protocol's own limit), as ArduPilot does. The server never waits for MISSION_ACK
  (MAVProxy sends none).
* Only messages addressed to this system and component are answered (not broadcasts:
  component 0 belongs to the autopilot's own mission). Uploads are refused with
  MISSION_ACK DENIED; fence and rally lists are empty.
* The items are :class:`missions.Waypoint` records (the hole's id in
  ``properties["hole_id"]``); degE7 exists only in the messages.
* Each announced hole's card (best view + facts, :mod:`missions._holecards`) goes out on
  the same link under its byte budget.

The link speaks MAVLink 2 (:func:`link.open_link`): MISSION_ITEM_INT's
``mission_type`` and MAVProxy's wp module need it.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from typing import Any

from holescan.errors import InputError
from holescan.geotag import Hole
from holescan.link import SigningKey, hole_text, mavlink
from holescan.missions._holecards import (
    NO_PICTURE,
    CardAssembler,
    CardSender,
    TileSource,
    card_facts,
    make_card,
)
from holescan.missions._mapinventory import (
    TYPE_INVENTORY,
    TileInventory,
    held_by,
    read_inventory,
)
from holescan.missions._protocol import MissionError
from holescan.missions._vehicle import MissionReceiver, MissionServer
from holescan.missions._waypoint import MAV_FRAME_GLOBAL, MAV_FRAME_GLOBAL_RELATIVE_ALT, Waypoint
from holescan.missions.errors import MissionServerError

__all__ = [
    "HoleMissionServer",
    "MissionServerError",
    "hole_statustext",
    "hole_waypoints",
    "radio_budget",
]

_log = logging.getLogger(__name__)

_INVENTORY_S = 10.0
"""A station's inventory counts for the request for everything within this long after it."""

MAV_COMP_ID_ONBOARD_COMPUTER: int = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER


def hole_waypoints(
    holes: Iterable[Hole],
    *,
    home: tuple[float, float, float] | None = None,
    rel_alt_m: float = 10.0,
    clearance_m: float = 5.0,
) -> tuple[Waypoint, ...]:
    """The mission served for ``holes``: home at seq 0, then holes by confidence.

    Parameters
    ----------
    holes : holes to serve (those passing the announce gate).
    home : (lat_deg, lon_deg, alt_m MSL) of the vehicle's home, or None when unknown.
    rel_alt_m : waypoint altitude above home, metres.
    clearance_m : when ``home`` is known, a waypoint is at least this high above its hole.

    Returns
    -------
    Waypoints: item 0 the home (MAV_FRAME_GLOBAL, MSL; 0/0/0 when unknown), then one
    NAV_WAYPOINT (MAV_FRAME_GLOBAL_RELATIVE_ALT) per hole with ``properties["hole_id"]``.
    """
    ordered = sorted(holes, key=lambda h: (-h.score, -h.sightings, h.id))
    lat0, lon0, alt0 = home if home is not None else (0.0, 0.0, 0.0)
    items = [Waypoint(lat0, lon0, alt0, name="home", frame=MAV_FRAME_GLOBAL)]
    for h in ordered:
        alt_rel = rel_alt_m
        if home is not None and math.isfinite(h.alt_m):
            alt_rel = max(rel_alt_m, h.alt_m - home[2] + clearance_m)
        items.append(
            Waypoint(
                h.lat_deg,
                h.lon_deg,
                alt_rel,
                name=f"hole {h.id}",
                properties={"hole_id": h.id},
                frame=MAV_FRAME_GLOBAL_RELATIVE_ALT,
            )
        )
    return tuple(items)


def hole_statustext(hole: Hole, tier: str = "announced") -> str:
    """``HOLE <id> p<p_hole> <lat> <lon>`` (``REVIEW ...`` for a hole sent for review) of
    ``hole``, with its hole-level ``p_hole``, through the link's one codec
    (:func:`link.hole_text`).

    >>> from holescan.geotag import Hole
    >>> h = Hole(3, 43.65331, -79.38312, 120.0, 0.5, 0.88, 4, 0, 10, 1, (0, 0, 9, 9), 1.0, 0.7,
    ...          p_hole=0.97)
    >>> hole_statustext(h), hole_statustext(h, "review")
    ('HOLE 3 p0.97 43.6533100 -79.3831200', 'REVIEW 3 p0.97 43.6533100 -79.3831200')
    """
    return hole_text(hole.id, hole.p_hole, hole.lat_deg, hole.lon_deg, tier)


_MIN_CARD_BYTES_PER_S = 50.0


def radio_budget(current: float, ceiling: float, txbuf_pct: int) -> float:
    """The hole cards' byte budget after a RADIO_STATUS, B/s.

    ``txbuf_pct`` is how much of the radio's transmit buffer is free (SiK radios report it;
    ArduPilot slows its own streams on it the same way): under 20 % the link is
    overrun, the budget halves; under 50 % it shrinks by a fifth; over 90 % it grows by a
    tenth, up to ``ceiling`` (the configured budget); between, it stays. Never under
    50 B/s (a card still gets through, slowly).
    """
    if txbuf_pct < 20:
        new = current * 0.5
    elif txbuf_pct < 50:
        new = current * 0.8
    elif txbuf_pct > 90:
        new = current * 1.1
    else:
        new = current
    return max(min(new, ceiling), min(_MIN_CARD_BYTES_PER_S, ceiling))


RELAYED_S: dict[str, float] = {
    "HEARTBEAT": 1.0,
    "GLOBAL_POSITION_INT": 0.5,
    "ATTITUDE": 0.5,
    "SYS_STATUS": 2.0,
    "BATTERY_STATUS": 2.0,
    "HOME_POSITION": 10.0,
    "MOUNT_ORIENTATION": 1.0,
}
"""The autopilot's messages :meth:`HoleMissionServer.relay` forwards on the server's own
link, each at most once per this many seconds (about 250 B/s in all)."""


class HoleMissionServer(MissionServer):
    """Live MAVLink mission server for found holes (a background thread).

    Parameters
    ----------
    connection_string : pymavlink connection, e.g. ``udpout:127.0.0.1:14550`` (towards a
        GCS or router), ``udpin:0.0.0.0:14560``, ``tcp:HOST:PORT``, a serial device; None
        with ``sender``: the companion's one link to the autopilot, which routes the
        announcements, the mission and the cards to the GCS on its other port (see
        :class:`missions.MissionServer`; the link's owner feeds it with :meth:`feed`).
    sysid : the vehicle's system id (GCS modules only listen to their target system).
    compid : our component id (191 = onboard computer).
    home : (lat_deg, lon_deg, alt_m MSL) of the vehicle's home, if known (see
        :meth:`set_home`).
    rel_alt_m, clearance_m : waypoint altitude, see :func:`hole_waypoints`.
    heartbeat_period_s : HEARTBEAT interval (MAV_TYPE_ONBOARD_CONTROLLER).
    card_bytes_per_s : byte budget of the hole cards (best view + facts, see
        :mod:`missions._holecards`) sent by :meth:`send_card`: the most they may take. A
        radio on the way that reports RADIO_STATUS (a SiK radio, seen through the
        autopilot's routing) adapts it to what the link carries (:func:`radio_budget`).

    Use as a context manager; the link opens on enter and closes on exit. Errors of the
    background thread are raised as :class:`MissionServerError` by :meth:`close`.
    """

    tick_s = 0.1

    def __init__(
        self,
        connection_string: str | None,
        sysid: int,
        compid: int = MAV_COMP_ID_ONBOARD_COMPUTER,
        *,
        home: tuple[float, float, float] | None = None,
        rel_alt_m: float = 10.0,
        clearance_m: float = 5.0,
        heartbeat_period_s: float = 1.0,
        card_bytes_per_s: float = 1000.0,
        sender: Callable[[Callable[[Any], None]], None] | None = None,
        signing: SigningKey | None = None,
    ) -> None:
        if not (1 <= sysid <= 255 and 1 <= compid <= 255):
            raise InputError(f"sysid and compid must be 1..255, got {sysid}, {compid}")
        receiver = MissionReceiver(
            system_id=sysid, component_id=compid, read_only=True, broadcast=False
        )
        super().__init__(
            connection_string,
            receiver,
            heartbeat_period_s=heartbeat_period_s,
            mav_type=mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
            autopilot=mavlink.MAV_AUTOPILOT_INVALID,
            sender=sender,
            signing=signing,
        )
        self.connection_string = connection_string
        self.sysid = sysid
        self.compid = compid
        self.rel_alt_m = rel_alt_m
        self.clearance_m = clearance_m
        self._home = home
        self._holes: tuple[Hole, ...] = ()
        self.cards = CardSender(bytes_per_s=card_bytes_per_s)
        self._inventory = CardAssembler()  # a station's inventory (missions._mapinventory)
        self._inventory_from: tuple[int, int] | None = None
        self._held: TileInventory | None = None
        self._held_at = -math.inf
        self._card_revs: dict[int, int] = {}
        self._said: dict[int, str] = {}  # hole id -> its last STATUSTEXT
        self.card_ceiling_bytes_per_s = card_bytes_per_s
        self.radio_status_seen = 0
        self.relayed = 0
        self._relayed_at: dict[tuple[int, int, str], float] = {}
        self._rebuild()

    # -- lifecycle -----------------------------------------------------------------------
    def __enter__(self) -> HoleMissionServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Open the link and start answering."""
        try:
            super().start()
        except MissionError as err:
            raise MissionServerError(str(err)) from err
        _log.info(
            "hole mission server on %s as %d/%d%s",
            self.connection_string or "the autopilot link",
            self.sysid,
            self.compid,
            "" if self.signing is None else f", MAVLink signed ({self.signing})",
        )

    def close(self) -> None:
        """Stop the thread and close the link; raise the thread's error if it had one."""
        self.stop()
        if self._error is not None:
            err, self._error = self._error, None
            raise MissionServerError(f"mission server failed: {err}") from err

    @property
    def items_sent(self) -> int:
        return self.receiver.items_sent

    # -- what we serve -------------------------------------------------------------------
    def update_holes(self, holes: Iterable[Hole]) -> None:
        """Replace the served holes (downloads already under way keep their snapshot)."""
        holes = tuple(holes)
        with self._lock:
            self._holes = holes
            self._rebuild()

    def set_home(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Set the vehicle's home (MSL altitude), e.g. from HOME_POSITION."""
        with self._lock:
            self._home = (lat_deg, lon_deg, alt_m)
            self._rebuild()

    def _rebuild(self) -> None:
        self.receiver.mission = hole_waypoints(
            self._holes, home=self._home, rel_alt_m=self.rel_alt_m, clearance_m=self.clearance_m
        )

    def items(self) -> tuple[Waypoint, ...]:
        """The mission a new download gets now (seq 0 = home)."""
        with self._lock:
            return self.receiver.mission

    def announce(self, hole: Hole, tier: str = "announced") -> str | None:
        """Send STATUSTEXT ``HOLE <id> p<p_hole> <lat> <lon>`` (severity NOTICE), or for a
        hole for review ``REVIEW ...`` (severity INFO); return it. None when the last
        STATUSTEXT of this hole said exactly the same (a hole told again for a smaller
        sigma or more sightings): nothing new for a GCS's message list, not sent again;
        its card carries what changed."""
        text = hole_statustext(hole, tier)
        with self._lock:
            if self._said.get(hole.id) == text:
                return None
        severity = mavlink.MAV_SEVERITY_NOTICE if tier == "announced" else mavlink.MAV_SEVERITY_INFO
        self._send_or_fail(lambda mav: mav.statustext_send(severity, text.encode("ascii")))
        with self._lock:
            self._said[hole.id] = text
        _log.info("announced %s", text)
        return text

    def send_card(self, hole: Hole, jpeg: bytes, why: str = "", tier: str = "announced") -> int:
        """Queue hole ``hole``'s card (its best view ``jpeg`` and facts, ``tier`` among
        them); return its size.

        Sent under the byte budget by the server's thread, announced holes' cards before
        those of holes for review; a newer card of the same hole replaces one not yet
        started. When this very picture already went out whole in an earlier card of the
        hole, the card is facts-only (:data:`missions._holecards.NO_PICTURE`: a few hundred
        bytes instead of a few kB); its repeats carry the picture again.
        """
        with self._lock:
            rev = self._card_revs.get(hole.id, 0) + 1
            self._card_revs[hole.id] = rev
            facts = card_facts(hole, why, rev, tier)
            full = make_card(jpeg, facts)
            card = full
            if self.cards.picture_sent(hole.id) == jpeg:
                card = make_card(NO_PICTURE, facts)
            self.cards.put(hole.id, card, priority=0 if tier == "announced" else 1, full=full)
        return len(card)

    def card_revisions(self) -> dict[int, int]:
        """Hole id -> revision of the newest card queued for it (what the ground should
        end with)."""
        with self._lock:
            return dict(self._card_revs)

    def set_tiles(self, tiles: TileSource | None) -> None:
        """Send the live map's tiles from ``tiles`` with what the cards leave of the budget
        (:mod:`missions._maptiles`); None stops them."""
        with self._lock:
            self.cards.tiles = tiles

    def flush_cards(self, timeout_s: float = 10.0) -> bool:
        """Wait (at most ``timeout_s``) until every queued card (and the map tile under
        way) is sent; True when done."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                if self.cards.queued == 0:
                    return True
            time.sleep(0.1)
        return False

    def relay(self, msg: Any) -> bool:
        """Forward an autopilot message (:data:`RELAYED_S`, at most that often) unchanged
        on the server's own link (``connection_string``), so that a ground station on that
        link sees the vehicle (position, attitude, mode, battery, home) without the
        autopilot's radio, as the autopilot's routing would; True when sent. A server on
        the autopilot's link (no own link) relays nothing: the autopilot routes."""
        kind = msg.get_type()
        period = RELAYED_S.get(kind)
        if period is None or self.connection_string is None:
            return False
        key = (msg.get_srcSystem(), msg.get_srcComponent(), kind)
        now = time.monotonic()
        if now - self._relayed_at.get(key, -math.inf) < period:
            return False
        self._relayed_at[key] = now
        buf = bytes(msg.get_msgbuf())
        try:
            self.send_with(lambda mav: mav.file.write(buf))
        except (MissionError, OSError) as err:
            _log.debug("relay of %s failed: %s", kind, err)
            return False
        self.relayed += 1
        return True

    def _send_or_fail(self, fn: Any) -> None:
        try:
            self.send_with(fn)
        except MissionError as err:
            raise MissionServerError(str(err)) from err

    # -- hooks of the server's thread ----------------------------------------------------
    def on_message(self, msg: Any) -> None:
        kind = msg.get_type()  # no target fields: any peer
        if kind == "RADIO_STATUS":
            with self._lock:
                self.radio_status_seen += 1
                old = self.cards.bytes_per_s
                self.cards.bytes_per_s = radio_budget(
                    old, self.card_ceiling_bytes_per_s, int(msg.txbuf)
                )
            if self.cards.bytes_per_s != old:
                _log.debug(
                    "radio tx buffer %d %% free: card budget %.0f B/s",
                    msg.txbuf,
                    self.cards.bytes_per_s,
                )
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "ENCAPSULATED_DATA":
            if src == self._inventory_from and (data := self._inventory.add(msg)) is not None:
                self._held = read_inventory(data)
                self._inventory_from = None
                if self._held is not None:
                    self._held_at = time.monotonic()
                    _log.info("%s holds %d map tiles", src, len(self._held.have))
            return
        if kind != "DATA_TRANSMISSION_HANDSHAKE":
            return
        if msg.type == TYPE_INVENTORY and msg.size > 0:  # what the station holds comes next
            self._inventory_from = src
            self._inventory.add(msg)
        elif msg.size == 0 and msg.packets == 0:  # a ground station asks for every card
            held = self._held
            fresh = held is not None and time.monotonic() - self._held_at < _INVENTORY_S
            _log.info(
                "hole cards requested again by %s (%s)",
                src,
                "tiles it holds not sent" if fresh else "every map tile too",
            )
            with self._lock:
                self.cards.resend_all(held_by(held) if fresh and held is not None else None)
            self._held = None

    def tick(self) -> None:
        with self._lock:
            self.cards.pump(self.send_with)
