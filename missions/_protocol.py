"""The MAVLink mission protocol, client side, and the wire format of items.

Client (ground or companion side): :func:`upload_mission` sends MISSION_COUNT, answers
each MISSION_REQUEST_INT (or legacy MISSION_REQUEST) with MISSION_ITEM_INT (MISSION_ITEM),
resends on silence, and waits for MISSION_ACK. :func:`download_mission` pulls a mission.
The vehicle side is :mod:`missions._vehicle`. :class:`missions.Waypoint` is the one item
record; degE7 exists only in the messages built and read here.

pymavlink picks MAVLink 1 or 2 from the environment when first imported; links opened here
always speak MAVLink 2 (MAVProxy needs it) whatever that choice was.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from holescan.link import SigningKey, mavlink, open_link
from holescan.missions._waypoint import (
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_MISSION,
    Waypoint,
)
from holescan.missions.errors import MissionError, MissionRejectedError, MissionTimeoutError

__all__ = [
    "MAV_MISSION_ACCEPTED",
    "MissionError",
    "MissionRejectedError",
    "MissionTimeoutError",
    "UploadReport",
    "connect",
    "download_mission",
    "upload_mission",
    "waypoint_from_mission_item",
]

log = logging.getLogger(__name__)

MAV_MISSION_ACCEPTED: int = mavlink.MAV_MISSION_ACCEPTED
_NS = 1_000_000_000

# Frames whose x/y are latitude/longitude.
_MISSION_FRAMES_WITHOUT_POSITION = {MAV_FRAME_MISSION}


def _result_name(result: int) -> str:
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name if entry is not None else f"MAV_MISSION_RESULT {result}"


def connect(
    link: str,
    *,
    source_system: int = 255,
    source_component: int = mavlink.MAV_COMP_ID_MISSIONPLANNER,
    signing: SigningKey | None = None,
) -> Any:
    """Open a pymavlink link (``udpout:HOST:PORT``, ``udpin:...``, ``tcp:...``) speaking MAVLink 2.

    Raises :class:`MissionError` when the link cannot be opened.
    """
    try:
        return open_link(
            link,
            source_system=source_system,
            source_component=source_component,
            signing=signing,
            autoreconnect=False,
        )
    except Exception as err:  # pymavlink raises OSError, ValueError, SerialException ...
        raise MissionError(f"cannot open MAVLink link {link!r}: {err}") from err


def item_message(
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


def waypoint_from_message(msg: Any) -> Waypoint:
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


def waypoint_from_mission_item(msg: Any) -> Waypoint:
    """A received MISSION_ITEM_INT (or MISSION_ITEM) as the one item record, degE7 converted
    here: for code that runs the mission protocol on its own link (the ground station)."""
    return waypoint_from_message(msg)


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
    target_component: int = mavlink.MAV_COMP_ID_AUTOPILOT1,
    source_system: int = 255,
    source_component: int = mavlink.MAV_COMP_ID_MISSIONPLANNER,
    heartbeat_timeout_s: float = 5.0,
    item_timeout_s: float = 1.0,
    retries: int = 5,
    no_space_wait_s: float = 10.0,
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
    no_space_wait_s : an autopilot just after boot answers MISSION_COUNT with
        MAV_MISSION_NO_SPACE until its mission storage is sized (ArduPilot SITL did, seconds
        after boot): ask again each second for this long before giving up (0: at once).

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
            was_silent, silent = silent, 0
            if getattr(msg, "mission_type", 0) != 0:
                continue
            if msg.get_type() == "MISSION_ACK":
                if msg.type == mavlink.MAV_MISSION_INVALID_SEQUENCE and highest >= 0:
                    # Not final: ArduPilot answers an item out of sequence (our resend that
                    # crossed its next request, on a busy link) so and keeps the transfer open.
                    log.debug("the autopilot refused an item out of sequence; going on")
                    silent = was_silent  # no answer to what we wait for: still silence
                    continue
                waited = time.monotonic() - t0
                no_space = msg.type == mavlink.MAV_MISSION_NO_SPACE
                if no_space and highest < 0 and waited < no_space_wait_s:
                    log.info("MAV_MISSION_NO_SPACE: the autopilot is still initialising?")
                    time.sleep(min(1.0, no_space_wait_s - waited))
                    conn.mav.send(last)  # MISSION_COUNT again
                    continue
                if msg.type != MAV_MISSION_ACCEPTED:
                    still = (
                        f" (still after {waited:.0f} s: {len(rows)} items, more than it stores?)"
                        if no_space and no_space_wait_s > 0
                        else ""
                    )
                    raise MissionRejectedError(
                        f"the autopilot rejected the mission: {_result_name(msg.type)}{still}",
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
            last = item_message(
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
    target_component: int = mavlink.MAV_COMP_ID_AUTOPILOT1,
    source_system: int = 255,
    source_component: int = mavlink.MAV_COMP_ID_MISSIONPLANNER,
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
        request: Any = m.MAVLink_mission_request_list_message(
            target_system, target_component, m.MAV_MISSION_TYPE_MISSION
        )
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
                items.append(waypoint_from_message(msg))
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
