"""The one door to pymavlink: MAVLink 2, one dialect (``ardupilotmega``), links opened alike.

pymavlink picks MAVLink 1 or 2 from the ``MAVLINK20`` environment variable when
``pymavlink.mavutil`` is first imported. This module sets it (if unset) right before that
import, and every module of the project takes pymavlink from here, so it is set in one
place. ``mavlink`` is the dialect module: message classes, ``MAVError`` and every enum
value (``mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT`` ...), never typed by hand.
"""

from __future__ import annotations

import os
from typing import Any, Protocol

os.environ.setdefault("MAVLINK20", "1")  # before the first import of mavutil (see above)

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from holescan.link._signing import SigningKey

__all__ = ["MavConnection", "mavlink", "mavutil", "open_link", "parser"]


class MavConnection(Protocol):
    """What the project uses of a pymavlink connection (``mavutil.mavfile``).

    ``mav`` is the dialect's ``MAVLink`` encoder/decoder (``conn.mav.heartbeat_send(...)``);
    its message methods are generated, so it stays ``Any``.
    """

    mav: Any
    source_system: int
    source_component: int
    target_system: int
    target_component: int
    WIRE_PROTOCOL_VERSION: str

    def recv_msg(self) -> Any: ...

    def recv(self, n: int | None = None) -> bytes:
        """Raw bytes from the link (a datagram's worth on UDP), b"" when none are waiting."""
        ...

    def post_message(self, msg: Any) -> None:
        """Account a message parsed outside pymavlink (sequence losses, last messages)."""
        ...

    def recv_match(
        self,
        condition: str | None = None,
        type: str | list[str] | tuple[str, ...] | None = None,
        blocking: bool = False,
        timeout: float | None = None,
    ) -> Any: ...

    def select(self, timeout: float) -> bool: ...

    def write(self, buf: bytes) -> int | None: ...

    def setup_signing(
        self,
        secret_key: bytes,
        sign_outgoing: bool = True,
        allow_unsigned_callback: Any = None,
        initial_timestamp: int | None = None,
        link_id: int | None = None,
    ) -> None: ...

    def close(self) -> None: ...


def open_link(
    connection: str,
    *,
    source_system: int,
    source_component: int,
    signing: SigningKey | None = None,
    **kwargs: Any,
) -> MavConnection:
    """A pymavlink connection (``udpin:``/``udpout:``/``tcp:``/serial device) speaking
    MAVLink 2 with robust parsing (garbage is skipped up to the next start byte), signed
    with ``signing`` when given (:class:`link.SigningKey`: every packet sent is signed,
    every unsigned or badly signed one received is dropped).

    ``kwargs`` go to :func:`pymavlink.mavutil.mavlink_connection` (``baud``,
    ``autoreconnect`` ...). Raises what pymavlink raises (``OSError``, ``ValueError``,
    ``serial.SerialException``): callers wrap it in their package's error.
    """
    conn = mavutil.mavlink_connection(
        connection, source_system=source_system, source_component=source_component, **kwargs
    )
    if conn.WIRE_PROTOCOL_VERSION != "2.0":  # mavutil was imported before MAVLINK20 was set
        conn.mav = mavlink.MAVLink(conn, srcSystem=source_system, srcComponent=source_component)
        conn.WIRE_PROTOCOL_VERSION = "2.0"
    conn.mav.robust_parsing = True
    if signing is not None:
        signing.apply(conn)
    link: MavConnection = conn
    return link


def parser() -> Any:
    """A MAVLink 2 parser of bytes (``parse_buffer``) with no link: log replay and files."""
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    return mav
