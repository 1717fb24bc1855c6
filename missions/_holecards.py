"""Hole cards: each announced hole's best view and facts, sent over MAVLink alone.

A *card* is a small JPEG (the best view of the hole, ~2-3 kB) whose JPEG comment (COM
segment) carries the hole's facts as compact JSON: id, revision, position, uncertainty,
score, size, depth, sightings and the detector's "why" line. A ground station that gets
the picture gets everything it shows with it, and any JPEG viewer still opens the file.

Transport: the MAVLink **image transmission protocol** (DATA_TRANSMISSION_HANDSHAKE, then
ENCAPSULATED_DATA packets of 253 bytes, ``seqnr`` from 0), from component 191. Chosen over
MAVLink FTP because (1) it is a push: the picture reaches the ground when the hole is
announced, without a client polling a directory over a lossy radio; (2) it is two
messages, so the vehicle side stays ~100 lines and a ground station needs no FTP session
state; (3) every card is self-contained (the JPEG carries the facts), so a lost card is
simply sent again. Its weaknesses and what is done about them: no acknowledgement (a card
is repeated after ``repeat_s`` while the budget allows, and a ground station can ask for
all cards again by sending DATA_TRANSMISSION_HANDSHAKE with ``size = 0`` to component
191, e.g. after a link drop), and one picture at a time (cards are queued).

**Facts-only cards.** A hole told again whose best view did not change (its sigma shrank,
it was seen again) goes down as a card without the picture: the facts in the COM segment
of an empty JPEG (SOI, COM, EOI: ~300-600 bytes, 2-3 packets instead of ~12). The ground
keeps the picture it holds and takes the new facts (:func:`card_picture`,
:func:`with_picture`). Only after the hole's picture went out whole is a facts-only card
made (:meth:`CardSender.picture_sent`); repeats and a ground station's request for every card
send the newest facts *with* the picture, so a station that missed it still gets it.

Byte budget: :class:`CardSender` paces packets with a token bucket of ``bytes_per_s``
(default 1,000 B/s, counting whole MAVLink 2 frames: 12 bytes of header and CRC plus the
payload), so telemetry on the same radio is never starved.

The live map's tiles (:mod:`missions._maptiles`) share that bucket at lower priority: when
no card is queued, :class:`CardSender` asks its ``tiles`` source (a :class:`TileSource`)
for the next tile and sends it the same way, with the tile's handshake type. A card that
arrives meanwhile waits for at most the one tile under way (tiles are small: <= 1.2 kB).
"""

from __future__ import annotations

import collections
import functools
import json
import math
import struct
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from holescan.errors import InputError
from holescan.link import mavlink

__all__ = [
    "CARD_PAYLOAD",
    "NO_PICTURE",
    "CardAssembler",
    "CardSender",
    "TileSource",
    "card_facts",
    "card_picture",
    "make_card",
    "read_card",
    "with_picture",
]

CARD_PAYLOAD = 253
"""Bytes of picture per ENCAPSULATED_DATA packet (the message's data field)."""
_FRAME_OVERHEAD = 12  # MAVLink 2: 10 header bytes + 2 CRC (unsigned)
_HANDSHAKE_BYTES = _FRAME_OVERHEAD + 13
_PACKET_BYTES = _FRAME_OVERHEAD + 2 + CARD_PAYLOAD
_JPEG = mavlink.MAVLINK_DATA_STREAM_IMG_JPEG
NO_PICTURE = b"\xff\xd8\xff\xd9"
"""The JPEG of a facts-only card: SOI and EOI, no image (the ground keeps the one it has)."""


def make_card(jpeg: bytes, facts: Mapping[str, Any]) -> bytes:
    """``jpeg`` with ``facts`` (JSON-able) in a COM segment right after its SOI marker.

    >>> card = make_card(b"\\xff\\xd8\\xff\\xd9", {"id": 3})
    >>> read_card(card)
    {'id': 3}
    """
    if jpeg[:2] != b"\xff\xd8":
        raise InputError("not a JPEG (no SOI marker)")
    text = json.dumps(dict(facts), separators=(",", ":"), allow_nan=False).encode("utf-8")
    if len(text) > 65533:
        raise InputError("hole facts too long for a JPEG comment")
    return jpeg[:2] + b"\xff\xfe" + struct.pack(">H", len(text) + 2) + text + jpeg[2:]


def read_card(card: bytes) -> dict[str, Any] | None:
    """The facts of a card (None when the JPEG has no JSON comment right after SOI)."""
    if card[:4] != b"\xff\xd8\xff\xfe" or len(card) < 6:
        return None
    (n,) = struct.unpack(">H", card[4:6])
    try:
        facts = json.loads(card[6 : 4 + n].decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    return facts if isinstance(facts, dict) else None


def card_picture(card: bytes) -> bytes:
    """The card's JPEG without its facts (the COM segment after SOI taken out);
    :data:`NO_PICTURE` for a facts-only card; ``card`` itself when it carries no facts.

    >>> card_picture(make_card(b"\\xff\\xd8\\xff\\xdbDQT\\xff\\xd9", {"id": 3}))
    b'\\xff\\xd8\\xff\\xdbDQT\\xff\\xd9'
    >>> card_picture(make_card(NO_PICTURE, {"id": 3})) == NO_PICTURE
    True
    """
    if card[:4] != b"\xff\xd8\xff\xfe" or len(card) < 6:
        return card
    (n,) = struct.unpack(">H", card[4:6])
    return card[:2] + card[4 + n :]


def with_picture(card: bytes, picture: bytes) -> bytes:
    """The facts of ``card`` with the picture of ``picture`` (a card or a bare JPEG): what
    the ground keeps when a facts-only card comes for a hole whose picture it holds.

    >>> kept = make_card(b"\\xff\\xd8\\xff\\xdbDQT\\xff\\xd9", {"id": 3, "sigma": 1.2})
    >>> newer = make_card(NO_PICTURE, {"id": 3, "sigma": 1.05})
    >>> both = with_picture(newer, kept)
    >>> read_card(both), card_picture(both) == card_picture(kept)
    ({'id': 3, 'sigma': 1.05}, True)
    """
    facts_end = len(card) - len(card_picture(card)) + 2  # SOI + COM segment
    return card[:facts_end] + card_picture(picture)[2:]


def card_facts(hole: Any, why: str, revision: int, tier: str = "announced") -> dict[str, Any]:
    """The facts a card carries for a :class:`geotag.Hole` (7 decimals: 1 cm): ``tier``
    (``announced`` or ``review``) and ``p`` (the hole-level ``p_hole``) among them."""

    def r(v: float, nd: int) -> float | None:
        return round(float(v), nd) if math.isfinite(v) else None

    return {
        "id": hole.id,
        "rev": revision,
        "lat": round(hole.lat_deg, 7),
        "lon": round(hole.lon_deg, 7),
        "alt": r(hole.alt_m, 2),
        "sigma": r(hole.sigma_h_m, 2),
        "score": r(hole.score, 3),
        "p": r(getattr(hole, "p_hole", math.nan), 3),
        "tier": tier,
        "n": hole.sightings,
        "major": r(hole.major_m, 2),
        "minor": r(hole.minor_m, 2),
        "t0": hole.t_first_boot_ns // 1_000_000,
        "t1": hole.t_last_boot_ns // 1_000_000,
        "why": why,
    }


def _handshake(size: int, packets: int, mav: Any, kind: int = _JPEG) -> None:
    mav.data_transmission_handshake_send(kind, size, 0, 0, packets, CARD_PAYLOAD, 0)


def _packet(seqnr: int, data: bytes, mav: Any) -> None:
    mav.encapsulated_data_send(seqnr, data)


class TileSource(Protocol):
    """Where :class:`CardSender` takes map tiles from when no card waits."""

    def next_tile(self) -> tuple[int, bytes] | None:
        """(handshake type, picture bytes) of the next tile to send, or None: none due."""
        ...

    def resend_all(self, held: Callable[[bytes], bool] | None = None) -> None:
        """Send every tile again (a ground station asked for everything), but those
        ``held(tile bytes)`` says the station already holds (None: every tile)."""
        ...


_TILE_PRIORITY = 2  # after every card: a tile goes only when no card waits


@dataclass
class _Outgoing:
    key: int
    card: bytes
    sent: int = -1  # -1: handshake not sent yet; else packets sent
    priority: int = 0  # lower goes first (0: announced holes, 1: for review, 2: map tiles)
    kind: int = _JPEG
    tile: bool = False


@dataclass
class CardSender:
    """Queue of cards paced into MAVLink messages under a byte budget.

    ``send(fn)`` is called with a function of the link's ``mav`` (as
    :meth:`missions.HoleMissionServer._send` takes it). Call :meth:`pump` often (the
    server's loop does, every 0.1 s); it sends what the budget allows.

    bytes_per_s : the budget (MAVLink frames of this protocol, bytes per second).
    burst_bytes : most the bucket holds (a pause does not allow a flood afterwards).
    repeat_s : a card sent whole is queued again after this long (None: never), the newest
        revision; at most ``repeats`` times.
    tiles : map tiles sent with what the budget leaves when no card is queued (None: none).
    """

    bytes_per_s: float = 1000.0
    burst_bytes: float = 600.0
    repeat_s: float | None = 60.0
    repeats: int = 2
    clock: Callable[[], float] = time.monotonic
    tiles: TileSource | None = None
    bytes_sent: int = 0
    cards_sent: int = 0
    tile_bytes_sent: int = 0
    tiles_sent: int = 0
    _queue: collections.deque[_Outgoing] = field(default_factory=collections.deque)
    _latest: dict[int, bytes] = field(default_factory=dict)
    _whole: dict[int, bytes] = field(default_factory=dict)
    _priority: dict[int, int] = field(default_factory=dict)
    _repeat_at: dict[int, tuple[float, int]] = field(default_factory=dict)
    _tokens: float = 0.0
    _t_last: float | None = None

    def __post_init__(self) -> None:
        if not self.bytes_per_s >= _PACKET_BYTES / 10.0:
            raise InputError(f"card byte budget must be >= 27 B/s, got {self.bytes_per_s}")

    def put(self, key: int, card: bytes, priority: int = 0, *, full: bytes | None = None) -> None:
        """Queue ``card`` for hole ``key``; an unsent older card of the same hole is dropped.

        Cards go out by ``priority`` (lower first: 0 announced holes, 1 holes for review),
        in order of arrival within one; the card being sent is never cut off. ``full``:
        the same facts with the picture when ``card`` is facts-only; repeats and
        :meth:`resend_all` send it (a ground station that lost the picture gets it again).
        """
        self._latest[key] = full if full is not None else card
        self._priority[key] = priority
        for item in list(self._queue):
            if item.key == key and item.sent < 0 and not item.tile:
                if item.priority == priority:
                    item.card = card
                    return
                self._queue.remove(item)
        self._enqueue(_Outgoing(key, card, priority=priority))
        self._repeat_at[key] = (math.inf, 0)

    def _enqueue(self, item: _Outgoing) -> None:
        at = len(self._queue)
        while (
            at > 0 and self._queue[at - 1].sent < 0 and self._queue[at - 1].priority > item.priority
        ):
            at -= 1
        self._queue.insert(at, item)

    def resend_all(self, held: Callable[[bytes], bool] | None = None) -> None:
        """Queue every hole's newest card again (a ground station asked for them), and
        every map tile after them but those ``held`` (see :meth:`TileSource.resend_all`)."""
        if self.tiles is not None:
            self.tiles.resend_all(held)
        queued = {item.key for item in self._queue if item.sent < 0}  # not started yet
        for key, card in sorted(self._latest.items()):
            if key not in queued:
                self._enqueue(_Outgoing(key, card, priority=self._priority.get(key, 0)))

    def picture_sent(self, key: int) -> bytes | None:
        """The picture (JPEG without facts) of the last card of hole ``key`` that went out
        whole with one (None: none yet)."""
        return self._whole.get(key)

    @property
    def pending(self) -> int:
        """Cards queued or under way (tiles not counted)."""
        return sum(not item.tile for item in self._queue)

    @property
    def queued(self) -> int:
        """Pictures queued or under way: cards, and the tile being sent."""
        return len(self._queue)

    def _next_tile(self) -> bool:
        if self.tiles is None:
            return False
        got = self.tiles.next_tile()
        if got is None:
            return False
        kind, data = got
        self._queue.append(_Outgoing(-1, data, priority=_TILE_PRIORITY, kind=kind, tile=True))
        return True

    def pump(self, send: Callable[[Callable[[Any], None]], None]) -> None:
        """Send handshakes and packets while the budget has tokens for them."""
        now = self.clock()
        if self._t_last is not None:
            self._tokens = min(
                self.burst_bytes, self._tokens + (now - self._t_last) * self.bytes_per_s
            )
        self._t_last = now
        if self.repeat_s is not None:
            for key, (t, n) in list(self._repeat_at.items()):
                if now >= t and all(item.key != key for item in self._queue):
                    card = self._latest[key]
                    self._enqueue(_Outgoing(key, card, priority=self._priority.get(key, 0)))
                    self._repeat_at[key] = (math.inf, n)
        while self._queue or (self._tokens >= _HANDSHAKE_BYTES and self._next_tile()):
            item = self._queue[0]
            cost = _HANDSHAKE_BYTES if item.sent < 0 else _PACKET_BYTES
            if self._tokens < cost:
                return
            self._tokens -= cost
            if item.tile:
                self.tile_bytes_sent += cost
            else:
                self.bytes_sent += cost
            card = item.card
            n_packets = -(-len(card) // CARD_PAYLOAD)
            if item.sent < 0:
                send(functools.partial(_handshake, len(card), n_packets, kind=item.kind))
            else:
                chunk = card[item.sent * CARD_PAYLOAD : (item.sent + 1) * CARD_PAYLOAD]
                send(functools.partial(_packet, item.sent, chunk.ljust(CARD_PAYLOAD, b"\x00")))
            item.sent += 1
            if item.sent >= n_packets:
                self._queue.popleft()
                if item.tile:
                    self.tiles_sent += 1
                    continue
                self.cards_sent += 1
                if (picture := card_picture(card)) != NO_PICTURE:
                    self._whole[item.key] = picture
                _, n = self._repeat_at.get(item.key, (math.inf, 0))
                if self.repeat_s is not None and n < self.repeats:
                    self._repeat_at[item.key] = (now + self.repeat_s, n + 1)


class CardAssembler:
    """Ground side: DATA_TRANSMISSION_HANDSHAKE + ENCAPSULATED_DATA -> whole cards.

    Feed every such message of one sender to :meth:`add`; it returns a card when its last
    packet arrived, else None. Packets before a handshake, of a different image, or a card
    with packets missing when the next handshake comes are dropped (counted).
    """

    def __init__(self) -> None:
        self._size = 0
        self._packets: dict[int, bytes] = {}
        self._n = 0
        self.dropped = 0
        self.completed = 0

    def add(self, msg: Any) -> bytes | None:
        kind = msg.get_type()
        if kind == "DATA_TRANSMISSION_HANDSHAKE":
            if msg.size == 0 or msg.packets == 0:
                return None  # a request, not an image
            if self._n and len(self._packets) < self._n:
                self.dropped += 1
            self._size, self._n, self._packets = int(msg.size), int(msg.packets), {}
            return None
        if kind != "ENCAPSULATED_DATA" or not self._n:
            return None
        seq = int(msg.seqnr)
        if seq >= self._n:
            return None
        data = msg.data
        self._packets[seq] = bytes(data) if not isinstance(data, bytes) else data
        if len(self._packets) < self._n:
            return None
        card = b"".join(self._packets[i] for i in range(self._n))[: self._size]
        self._n, self._packets = 0, {}
        self.completed += 1
        return card
