"""What :class:`sim.SimAutopilot` streams and how it answers a COMMAND_LONG (ArduPilot's way).

Kept apart from the autopilot's clock and motion: the messages it can stream
(:data:`STREAMED`), ArduPilot's REQUEST_DATA_STREAM groups of them (:data:`STREAM_GROUPS`)
and :func:`command_result`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from holescan.link import mavlink

__all__ = ["STREAMED", "STREAM_GROUPS", "command_result", "is_reboot", "param_value", "set_streams"]

STREAMED = (
    "HEARTBEAT",
    "GLOBAL_POSITION_INT",
    "ATTITUDE",
    "ATTITUDE_QUATERNION",
    "GPS_RAW_INT",
    "EKF_STATUS_REPORT",
    "SYSTEM_TIME",
)
# ArduPilot's REQUEST_DATA_STREAM groups, restricted to what we stream.
STREAM_GROUPS: Mapping[int, tuple[str, ...]] = {
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: ("GPS_RAW_INT",),
    mavlink.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT",),
    mavlink.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    mavlink.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "EKF_STATUS_REPORT"),
}


def is_reboot(msg: Any) -> bool:
    """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN asking for a reboot (param1 = 1)."""
    return bool(msg.command == mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN and msg.param1 == 1)


def command_result(
    msg: Any,
    *,
    message_interval: bool,
    set_rate: Callable[[str, float], None],
    send: Callable[[str], None],
) -> int:
    """Carry out COMMAND_LONG ``msg`` and return its MAV_RESULT: SET_MESSAGE_INTERVAL (when
    ``message_interval``), REQUEST_MESSAGE, a reboot (accepted; the caller reboots after
    the ACK); anything else UNSUPPORTED."""
    cls = mavlink.mavlink_map.get(int(msg.param1))
    name = str(cls.msgname) if cls is not None else ""
    if msg.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL and message_interval:
        if name not in STREAMED:
            return int(mavlink.MAV_RESULT_DENIED)
        interval_us = msg.param2
        if interval_us < 0:
            set_rate(name, 0)
        elif interval_us == 0:  # default rate: only the heartbeat streams by default
            set_rate(name, 1.0 if name == "HEARTBEAT" else 0)
        else:
            set_rate(name, 1e6 / interval_us)
        return int(mavlink.MAV_RESULT_ACCEPTED)
    if is_reboot(msg):
        return int(mavlink.MAV_RESULT_ACCEPTED)
    if msg.command == mavlink.MAV_CMD_REQUEST_MESSAGE:
        if name not in STREAMED:
            return int(mavlink.MAV_RESULT_DENIED)
        send(name)
        return int(mavlink.MAV_RESULT_ACCEPTED)
    return int(mavlink.MAV_RESULT_UNSUPPORTED)


def param_value(params: Mapping[str, float] | None, msg: Any) -> list[Any]:
    """PARAM_VALUE answering PARAM_REQUEST_READ ``msg`` (by name, or by index when
    ``param_index`` >= 0), as ArduPilot does; nothing while initialising (``params`` None)
    or for a name it does not have."""
    if params is None:
        return []
    names = sorted(params)
    index = int(msg.param_index)
    if index >= 0:
        if index >= len(names):
            return []
        name = names[index]
    else:
        raw = msg.param_id
        name = (raw.decode(errors="replace") if isinstance(raw, bytes) else str(raw)).rstrip("\0")
        if name not in params:
            return []
        index = names.index(name)
    real32 = mavlink.MAV_PARAM_TYPE_REAL32
    return [
        mavlink.MAVLink_param_value_message(
            name.encode(), float(params[name]), real32, len(names), index
        )
    ]


def set_streams(msg: Any, set_rate: Callable[[str, float], None]) -> None:
    """Carry out REQUEST_DATA_STREAM ``msg``: start or stop its group's messages (all groups
    for MAV_DATA_STREAM_ALL) at its rate."""
    groups = (
        list(STREAM_GROUPS)
        if msg.req_stream_id == mavlink.MAV_DATA_STREAM_ALL
        else [msg.req_stream_id]
    )
    for group in groups:
        for name in STREAM_GROUPS.get(group, ()):
            set_rate(name, msg.req_message_rate if msg.start_stop else 0)
