"""Splitting received bytes into MAVLink packets so that garbage costs only itself.

pymavlink's parser trusts the first start byte it sees: a 0xFD inside garbage makes it wait
for the length that follows, swallowing the real packets behind it into one bad packet, and
it hands out one message per UDP datagram, so a backlog builds up. Here:

* a packet that fails (bad CRC, bad flags, impossible length) costs one byte: the search
  for the next start byte begins right after the failed one;
* on datagram links (UDP) a datagram is a unit: bytes left at its end are garbage, never
  joined to the next datagram (MAVLink packets never span datagrams);
* a packet of a message id the dialect does not know cannot be CRC-checked: it is accepted
  only when it ends where the data ends or where another start byte follows;
* every message of a datagram or read is returned at once.
"""

from __future__ import annotations

from typing import Any

from holescan.link._connection import mavlink

__all__ = ["MavlinkStream"]

_V1, _V2 = mavlink.PROTOCOL_MARKER_V1, mavlink.PROTOCOL_MARKER_V2
_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_MAX_BUFFER = 1 << 16


class MavlinkStream:
    """Frame and decode MAVLink 1/2 packets from bytes with a pymavlink ``MAVLink`` object
    (from :func:`link.parser` or a link's ``conn.mav``: its signing setup applies).

    ``bad_bytes`` counts bytes skipped (garbage, failed packets' start bytes, datagram
    tails); ``bad_packets`` counts framed packets that failed their checks.
    """

    def __init__(self, mav: Any, *, datagrams: bool) -> None:
        self.mav = mav
        self.datagrams = datagrams
        self.bad_bytes = 0
        self.bad_packets = 0
        self.last_error: str | None = None
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Any]:
        """Messages completed by ``data`` (a whole datagram on datagram links)."""
        self._buf += data
        out = self._parse(final=self.datagrams)
        if len(self._buf) > _MAX_BUFFER:  # cannot happen with real framing; bound it
            self.bad_bytes += len(self._buf)
            self._buf.clear()
        return out

    def _parse(self, *, final: bool) -> list[Any]:
        buf = self._buf
        out: list[Any] = []
        pos = 0
        n = len(buf)
        shadow = 0  # bytes before this belong to a packet that failed (not garbage)
        while pos < n:
            start = _next_magic(buf, pos)
            self._skip(pos, start, shadow)
            pos = start
            if pos >= n:
                break
            size = _frame_size(buf, pos)
            if size is None:  # header not complete yet
                break
            if size < 0:  # impossible header: not a start byte after all
                self._skip(pos, pos + 1, shadow)
                pos += 1
                continue
            if n - pos < size:
                if final:  # a datagram cut inside: try from the next byte
                    self._skip(pos, pos + 1, shadow)
                    pos += 1
                    continue
                break
            end = pos + size
            try:
                msg = self.mav.decode(bytearray(buf[pos:end]))
            except Exception as err:  # MAVError, struct.error: not a packet here
                if pos >= shadow:
                    self.bad_packets += 1
                self.last_error = str(err)
                shadow = max(shadow, end)
                pos += 1  # resync: the next start byte may be inside the failed frame
                continue
            if msg.get_type().startswith("UNKNOWN_"):
                # Unverifiable (no CRC seed for an unknown id): a packet only when another
                # starts right after it. On a stream whose bytes end there, wait for the
                # next byte (garbage ending in a start byte could otherwise take the first
                # bytes of the real packet behind it as its CRC); a datagram ends there.
                if end == n and not final:
                    break
                if not (end == n or buf[end] in (_V1, _V2)):
                    self._skip(pos, pos + 1, shadow)  # not followed by a packet
                    pos += 1
                    continue
            out.append(msg)
            pos = end
        if final:
            self._skip(pos, n, shadow)
            pos = n
        del buf[:pos]
        return out

    def _skip(self, start: int, end: int, shadow: int) -> None:
        """Count bytes start..end as garbage, except those inside a failed packet."""
        self.bad_bytes += max(0, end - max(start, shadow))


def _next_magic(buf: bytearray, pos: int) -> int:
    a, b = buf.find(_V2, pos), buf.find(_V1, pos)
    if a < 0:
        return len(buf) if b < 0 else b
    return a if b < 0 else min(a, b)


def _frame_size(buf: bytearray, pos: int) -> int | None:
    """Total bytes of the packet starting at ``pos``; None if the header is incomplete,
    -1 if the header is impossible."""
    if buf[pos] == _V1:
        if len(buf) - pos < 2:
            return None
        return 6 + buf[pos + 1] + 2
    if len(buf) - pos < 3:
        return None
    incompat = buf[pos + 2]
    if incompat & ~_SIGNED:
        return -1
    return 10 + buf[pos + 1] + 2 + (13 if incompat & _SIGNED else 0)
