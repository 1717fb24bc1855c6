"""What a ground station already holds of a live map: so a link-up re-sends only the rest.

After a link drop the station asks the companion for everything again
(DATA_TRANSMISSION_HANDSHAKE with ``size = 0``, :mod:`missions._holecards`). Just before
that request it now sends its *inventory* of the vehicle's map, over the same image
transmission protocol in the other direction: a handshake of type
:data:`TYPE_INVENTORY` (``MAVLINK_DATA_STREAM_IMG_RAW8U``: raw bytes) and ENCAPSULATED_DATA
packets carrying :func:`encode_inventory`'s bytes. The companion then re-sends the cards
and only the tiles whose version the station does not hold; without an inventory (lost on
the radio, an older station) it re-sends every tile, as before.

Bytes: ``HSINV1``, then zlib of ``>I`` map id and, per tile, ``>Bhhi`` (layer 0 coverage
/ 1 orthophoto, tx, ty, version): 9 bytes a tile before compression; a fully seen
hectare (244 places, both layers) is about 2-4 kB, once, on the uplink.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from holescan.link import mavlink
from holescan.missions._holecards import CARD_PAYLOAD as PAYLOAD_BYTES
from holescan.missions._maptiles import MAP_LAYERS, MapLayer, tile_facts

__all__ = [
    "TYPE_INVENTORY",
    "TileInventory",
    "encode_inventory",
    "held_by",
    "read_inventory",
    "send_inventory",
]

TYPE_INVENTORY: int = mavlink.MAVLINK_DATA_STREAM_IMG_RAW8U
"""Handshake ``type`` of a station's inventory (raw bytes, never a picture)."""
_MAGIC = b"HSINV1"
_ENTRY = struct.Struct(">Bhhi")
MAX_INVENTORY_BYTES = 64 * 1024
"""Bound on an inventory, compressed and not (a hostile peer's cannot blow up memory)."""


@dataclass(frozen=True)
class TileInventory:
    """The tiles a station holds of one map: (layer, tx, ty) -> version."""

    map_id: int
    have: Mapping[tuple[MapLayer, int, int], int] = field(default_factory=dict)


def encode_inventory(inv: TileInventory) -> bytes:
    """The inventory's bytes (see the module docstring)."""
    body = struct.pack(">I", inv.map_id & 0xFFFFFFFF) + b"".join(
        _ENTRY.pack(MAP_LAYERS.index(layer), tx, ty, min(v, 2**31 - 1))
        for (layer, tx, ty), v in sorted(inv.have.items())
        if -(2**15) <= tx < 2**15 and -(2**15) <= ty < 2**15
    )
    return _MAGIC + zlib.compress(body, 9)


def held_by(inv: TileInventory) -> Callable[[bytes], bool]:
    """``held(tile bytes)``: True when the station of ``inv`` holds that very tile (same
    map, place, layer and version), for :meth:`missions.TileSource.resend_all`."""

    def held(data: bytes) -> bool:
        f = tile_facts(data)
        return (
            f is not None
            and f.map_id == inv.map_id
            and inv.have.get((f.layer, f.tx, f.ty)) == f.version
        )

    return held


def read_inventory(data: bytes) -> TileInventory | None:
    """Bytes from a peer -> the inventory, or None when they are not one (bounded)."""
    if not data.startswith(_MAGIC) or len(data) > MAX_INVENTORY_BYTES:
        return None
    try:
        d = zlib.decompressobj()
        body = d.decompress(data[len(_MAGIC) :], MAX_INVENTORY_BYTES)
        if not d.eof or d.unconsumed_tail or d.unused_data:  # cut, too big or trailing
            return None
    except zlib.error:
        return None
    if len(body) < 4 or (len(body) - 4) % _ENTRY.size:
        return None
    (map_id,) = struct.unpack_from(">I", body)
    have: dict[tuple[MapLayer, int, int], int] = {}
    for layer, tx, ty, v in _ENTRY.iter_unpack(body[4:]):
        if layer >= len(MAP_LAYERS):
            return None
        have[(MAP_LAYERS[layer], tx, ty)] = v
    return TileInventory(map_id, have)


def send_inventory(mav: Any, inv: TileInventory, send: Callable[[Any], None] | None = None) -> int:
    """Send ``inv`` on ``mav`` (a pymavlink ``MAVLink``): handshake, then its packets.

    Returns the bytes of the inventory. ``send`` (None: ``mav.send``) is for tests.
    """
    data = encode_inventory(inv)
    n = -(-len(data) // PAYLOAD_BYTES)
    out = send or mav.send
    out(
        mav.data_transmission_handshake_encode(TYPE_INVENTORY, len(data), 0, 0, n, PAYLOAD_BYTES, 0)
    )
    for i in range(n):
        chunk = data[i * PAYLOAD_BYTES : (i + 1) * PAYLOAD_BYTES]
        out(mav.encapsulated_data_encode(i, chunk.ljust(PAYLOAD_BYTES, b"\0")))
    return len(data)
