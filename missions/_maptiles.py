"""Map tiles for the radio: the flight's coarse map cut into self-describing pictures.

The live map goes down the same MAVLink image transmission protocol as the hole cards
(:mod:`missions._holecards`: DATA_TRANSMISSION_HANDSHAKE + ENCAPSULATED_DATA from component
191, paced by the same :class:`~missions._holecards.CardSender`, cards first), one tile per
transfer, and like a card each tile carries its own facts, so a lost tile is simply sent
again and a station that restarts reads its folder back without an index:

* **coverage** tiles are 8-bit grayscale **PNG** (handshake type
  ``MAVLINK_DATA_STREAM_IMG_PNG``): 0 = not seen, else the coverage (0, 1] quantised to
  sixteenths (``17 * ceil(15 c)``, so runs compress); the facts in a ``tEXt`` chunk
  (keyword ``holescan``) right after ``IHDR``;
* **orthophoto** tiles are small **JPEG** (``MAVLINK_DATA_STREAM_IMG_JPEG``, as cards),
  cells not seen filled with a neutral colour; the facts in a COM segment after SOI
  (:func:`missions.make_card`), which a ground station tells from a card's by the key
  ``"map"``.

Any image viewer opens either. Geometry (the facts): the map's origin ``lat0``/``lon0``
(:class:`geotag.LocalFrame`), ``cell`` metres per cell, ``n`` cells per tile side; tile
``(tx, ty)`` spans east ``[tx n cell, (tx + 1) n cell)`` and north ``[ty n cell,
(ty + 1) n cell)`` from the origin; image row 0 is the tile's north edge (north up).
``m`` names the map (a flight's origin), ``v`` is the tile's version (higher = newer).
"""

from __future__ import annotations

import json
import math
import struct
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np
import numpy.typing as npt

from holescan.errors import InputError
from holescan.link import mavlink
from holescan.missions._holecards import make_card, read_card

__all__ = [
    "CELL_M_RANGE",
    "MAP_LAYERS",
    "MAP_RADIUS_MAX_M",
    "TILE_CELLS_RANGE",
    "TYPE_COVERAGE",
    "TYPE_ORTHO",
    "MapLayer",
    "TileFacts",
    "coverage_from_levels",
    "coverage_levels",
    "encode_coverage_tile",
    "encode_ortho_tile",
    "is_map_tile",
    "read_tile",
    "tile_facts",
    "tile_facts_of",
    "tiles_per_hectare",
]

MapLayer = Literal["cov", "ortho"]
MAP_LAYERS: tuple[MapLayer, ...] = ("cov", "ortho")
TYPE_COVERAGE: int = mavlink.MAVLINK_DATA_STREAM_IMG_PNG
"""Handshake ``type`` of a coverage tile (PNG)."""
TYPE_ORTHO: int = mavlink.MAVLINK_DATA_STREAM_IMG_JPEG
"""Handshake ``type`` of an orthophoto tile (JPEG, as the cards)."""
CELL_M_RANGE = (0.01, 5.0)
"""Cell sides a live map may have, metres (the vehicle's settings and what a tile may say)."""
TILE_CELLS_RANGE = (8, 256)
"""Cells per tile side a live map may have."""
MAP_RADIUS_MAX_M = 2000.0
"""How far a live map reaches from its origin at most, metres (a tile beyond is refused)."""
_PNG_SIG = b"\x89PNG\r\n\x1a\n"
_KEYWORD = b"holescan"
_UNSEEN_RGB = (244, 241, 234)  # the live page's background: unseen cells disappear


@dataclass(frozen=True)
class TileFacts:
    """What a tile says about itself (see the module docstring).

    map_id : the map (flight) it belongs to. layer : ``cov`` or ``ortho``.
    tx, ty : tile indices east / north of the origin. n : cells per side. cell_m : metres.
    lat0_deg, lon0_deg : the map's origin. version : higher is newer.
    """

    map_id: int
    layer: MapLayer
    tx: int
    ty: int
    n: int
    cell_m: float
    lat0_deg: float
    lon0_deg: float
    version: int

    def to_json(self) -> dict[str, Any]:
        return {
            "map": self.map_id,
            "layer": self.layer,
            "tx": self.tx,
            "ty": self.ty,
            "n": self.n,
            "cell": self.cell_m,
            "lat0": round(self.lat0_deg, 8),
            "lon0": round(self.lon0_deg, 8),
            "v": self.version,
        }

    @property
    def bounds_m(self) -> tuple[float, float, float, float]:
        """(east0, north0, east1, north1) of the tile in the map's local metres."""
        side = self.n * self.cell_m
        return (self.tx * side, self.ty * side, (self.tx + 1) * side, (self.ty + 1) * side)


def tile_facts_of(d: Mapping[str, Any]) -> TileFacts | None:
    """The :class:`TileFacts` of a picture's JSON facts; None when they are not a tile's
    (a hole card's, or malformed, or out of what a live map can be: :data:`CELL_M_RANGE`,
    :data:`TILE_CELLS_RANGE`, tiles within :data:`MAP_RADIUS_MAX_M` of the origin)."""
    try:
        layer = d["layer"]
        if "map" not in d or layer not in MAP_LAYERS:
            return None
        facts = TileFacts(
            int(d["map"]),
            layer,
            int(d["tx"]),
            int(d["ty"]),
            int(d["n"]),
            float(d["cell"]),
            float(d["lat0"]),
            float(d["lon0"]),
            int(d["v"]),
        )
    except (KeyError, TypeError, ValueError):
        return None
    side = facts.n * facts.cell_m
    reach = MAP_RADIUS_MAX_M + side  # the map's radius, rounded up to whole tiles
    ok = (
        TILE_CELLS_RANGE[0] <= facts.n <= TILE_CELLS_RANGE[1]
        and CELL_M_RANGE[0] <= facts.cell_m <= CELL_M_RANGE[1]  # finite too
        and 0 <= facts.map_id <= 0x7FFFFFFF
        and 0 <= facts.version <= 2**63 - 1
        and abs(facts.tx * side) <= reach
        and abs(facts.ty * side) <= reach
        and -90.0 <= facts.lat0_deg <= 90.0
        and -180.0 <= facts.lon0_deg <= 180.0
    )
    return facts if ok else None


def coverage_levels(coverage: npt.ArrayLike) -> npt.NDArray[np.uint8]:
    """Coverage 0..1 (0 or NaN = not seen) -> the tile's uint8 levels: 0, or 17 * ceil(15 c).

    >>> coverage_levels([0.0, 0.01, 0.5, 1.0]).tolist()
    [0, 17, 136, 255]
    """
    c = np.nan_to_num(np.asarray(coverage, dtype=np.float64), nan=0.0)
    q = np.ceil(np.clip(c, 0.0, 1.0) * 15.0)
    return (q * 17).astype(np.uint8)


def coverage_from_levels(levels: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """A coverage tile's uint8 levels -> coverage 0..1 (the upper edge of each sixteenth)."""
    return np.asarray(levels, dtype=np.float64) / 255.0


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def _facts_bytes(facts: TileFacts) -> bytes:
    return json.dumps(facts.to_json(), separators=(",", ":")).encode("ascii")


def _check_shape(a: npt.NDArray[Any], n: int, what: str) -> None:
    if a.shape[:2] != (n, n):
        raise InputError(f"{what} tile must be {n} x {n} cells, got {a.shape[:2]}")


def encode_coverage_tile(coverage: npt.ArrayLike, facts: TileFacts) -> bytes:
    """A coverage tile as PNG bytes with its facts.

    coverage : (n, n) float ndarray, 0..1, 0 or NaN = not seen; row 0 is the north edge.
    """
    levels = coverage_levels(coverage)
    _check_shape(levels, facts.n, "coverage")
    ok, buf = cv2.imencode(".png", levels, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise InputError("PNG encoding of a coverage tile failed")
    png = buf.tobytes()
    ihdr_end = 8 + 12 + 13
    text = _png_chunk(b"tEXt", _KEYWORD + b"\x00" + _facts_bytes(facts))
    return png[:ihdr_end] + text + png[ihdr_end:]


def encode_ortho_tile(
    rgb: npt.NDArray[np.uint8],
    seen: npt.NDArray[np.bool_],
    facts: TileFacts,
    *,
    max_bytes: int = 1200,
    qualities: Sequence[int] = (60, 45, 32, 22, 15),
) -> bytes:
    """An orthophoto tile as JPEG bytes with its facts: the best of ``qualities`` that fits
    ``max_bytes`` (or the last one).

    rgb : (n, n, 3) uint8 ndarray, RGB order, row 0 the north edge. seen : (n, n) bool,
    cells with colour (the others are filled with the page's background colour).
    """
    _check_shape(rgb, facts.n, "orthophoto")
    img = np.array(rgb, dtype=np.uint8)
    img[~np.asarray(seen, dtype=bool)] = _UNSEEN_RGB
    bgr = cv2.cvtColor(np.ascontiguousarray(img, dtype=np.uint8), cv2.COLOR_RGB2BGR)
    data = b""
    overhead = len(_facts_bytes(facts)) + 4  # the COM segment make_card adds
    for q in qualities:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(q)])
        if not ok:
            raise InputError("JPEG encoding of an orthophoto tile failed")
        data = buf.tobytes()
        if len(data) + overhead <= max_bytes:
            break
    return make_card(data, facts.to_json())


def _png_facts(data: bytes) -> dict[str, Any] | None:
    pos = 8
    while pos + 12 <= len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"tEXt" and body.startswith(_KEYWORD + b"\x00"):
            try:
                d = json.loads(body[len(_KEYWORD) + 1 :].decode("ascii"))
            except (UnicodeDecodeError, json.JSONDecodeError):
                return None
            return d if isinstance(d, dict) else None
        if kind in (b"IDAT", b"IEND"):
            return None
        pos += 12 + length
    return None


def is_map_tile(data: bytes) -> bool:
    """The received picture claims to be a map tile (a PNG, or a JPEG whose facts have
    ``"map"``); a hole card is not. Cheap: nothing is decoded but the facts."""
    if data.startswith(_PNG_SIG):
        return True
    facts = read_card(data)
    return facts is not None and "map" in facts


def tile_facts(data: bytes) -> TileFacts | None:
    """The facts of a map tile's bytes (None: not a tile). Cheap: no pixel is decoded."""
    d = _png_facts(data) if data.startswith(_PNG_SIG) else read_card(data)
    return tile_facts_of(d) if d is not None else None


def read_tile(data: bytes) -> tuple[TileFacts, npt.NDArray[Any]] | None:
    """A received picture -> (facts, pixels) when it is a map tile, else None.

    Pixels: coverage levels (n, n) uint8 (:func:`coverage_from_levels`), or the
    orthophoto (n, n, 3) uint8 RGB. A card, a damaged file or one of the wrong size is None.
    """
    if data.startswith(_PNG_SIG):
        d = _png_facts(data)
        flags = cv2.IMREAD_GRAYSCALE
    elif data.startswith(b"\xff\xd8"):
        d = read_card(data)
        flags = cv2.IMREAD_COLOR
    else:
        return None
    facts = tile_facts_of(d) if d is not None else None
    if facts is None:
        return None
    if (facts.layer == "cov") != data.startswith(_PNG_SIG):
        return None
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if img is None or img.shape[:2] != (facts.n, facts.n):
        return None
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return facts, img


def tiles_per_hectare(n: int, cell_m: float) -> float:
    """How many tiles of ``n`` cells of ``cell_m`` a hectare holds."""
    return 10_000.0 / (n * cell_m) ** 2 if n > 0 and math.isfinite(cell_m) else math.nan
