"""The ground station's copy of the flight's live map: the tiles as they came, on disk.

Each map tile a vehicle sends (:mod:`missions._maptiles`: coverage PNG, orthophoto JPEG,
each carrying its own facts) is kept as received in ``DIR/map/`` as
``v<sysid>-m<map>-<layer>-<tx>_<ty>.png|jpg`` (``sysid``: the vehicle's MAVLink system id;
a folder of an older station holds ``m<map>-...`` files, whose vehicle is not known: 0,
and a vehicle's newer tile of the same place takes over from such a file), written through
the output-path rule (:func:`outputs.atomic_output`: ``.part``, fsync, rename), only when
it is newer than the one kept. There is no index to keep consistent: a restarted station
reads the folder back (each file names itself in its facts); a damaged or foreign file
there is skipped with one log line.

Several flights are drawn on the grid of the first tile kept (the *base*,
:mod:`ground.station.mapcombine`). A tile whose place on that grid would make the
combined map larger than :data:`MAX_COMBINED_CELLS` cells (a 290 m square at 10 cm: far
more than an Xtion survey covers) is refused and counted (``rejected``), as is one of a
map whose cell or tile size differs from its own first tile's: each tile's size is
bounded by the protocol (:func:`missions.tile_facts_of`), but two valid maps of very
different cells could still ask for a combined raster of billions of cells.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from holescan.geotag import LocalFrame
from holescan.missions import TileFacts, TileInventory, coverage_from_levels, read_tile
from holescan.outputs import atomic_output

__all__ = [
    "MAX_COMBINED_CELLS",
    "MapStore",
    "StoredTile",
    "base_tiles",
    "map_shift",
    "tile_file_name",
    "tile_sysid",
]

_log = logging.getLogger(__name__)

MAX_COMBINED_CELLS = 4096 * 2048
"""Most cells the station's combined map may span (its bounding box on the base grid)."""


def map_shift(base: TileFacts, f: TileFacts) -> tuple[float, float]:
    """Where map ``f``'s origin lies in the base map's metres (east, north)."""
    if (f.lat0_deg, f.lon0_deg) == (base.lat0_deg, base.lon0_deg):
        return 0.0, 0.0
    e, n = LocalFrame(base.lat0_deg, base.lon0_deg).to_en(f.lat0_deg, f.lon0_deg)
    return float(e), float(n)


def base_tiles(base: TileFacts, f: TileFacts, shift: tuple[float, float]) -> tuple[range, range]:
    """Base tile (columns, rows) that tile ``f`` overlaps."""
    side = base.n * base.cell_m
    x0, y0, x1, y1 = f.bounds_m
    dx, dy = shift
    eps = 1e-6 * side
    return (
        range(math.floor((x0 + dx + eps) / side), math.floor((x1 + dx - eps) / side) + 1),
        range(math.floor((y0 + dy + eps) / side), math.floor((y1 + dy - eps) / side) + 1),
    )


def tile_file_name(f: TileFacts, sysid: int = 0) -> str:
    """``v<sysid>-m<map>-<layer>-<tx>_<ty>.png`` (coverage) or ``.jpg`` (orthophoto);
    without the ``v<sysid>-`` part when the vehicle is not known (``sysid`` 0).

    >>> from holescan.missions import TileFacts
    >>> tile_file_name(TileFacts(3, "cov", -1, 2, 64, 0.1, 43.6, -79.4, 9))
    'm3-cov--1_2.png'
    >>> tile_file_name(TileFacts(3, "ortho", 0, 0, 64, 0.1, 43.6, -79.4, 9), 2)
    'v2-m3-ortho-0_0.jpg'
    """
    ext = "png" if f.layer == "cov" else "jpg"
    name = f"m{f.map_id}-{f.layer}-{f.tx}_{f.ty}.{ext}"
    return f"v{sysid}-{name}" if sysid else name


def tile_sysid(name: str) -> int:
    """The vehicle of a tile file's name (0: not known, or not a name of ours).

    >>> tile_sysid("v2-m3-cov-0_0.png"), tile_sysid("m3-cov-0_0.png"), tile_sysid("v-m3")
    (2, 0, 0)
    """
    head, _, rest = name.partition("-")
    if head[:1] != "v" or not head[1:].isdigit() or not rest.startswith("m"):
        return 0
    sysid = int(head[1:])
    return sysid if 1 <= sysid <= 255 else 0


@dataclass(frozen=True)
class StoredTile:
    """A tile kept: its facts, its file name in the map folder, its arrival order
    (``seq``: the store's version when it was kept; for a folder read back, its order of
    modification time) and the vehicle that sent it (``sysid``; 0: not known)."""

    facts: TileFacts
    name: str
    seq: int = 0
    sysid: int = 0


@dataclass
class MapStore:
    """The tiles received so far (thread-safe); :meth:`open` reads a folder back.

    folder : ``DIR/map``. version : counts accepted tiles (the page polls it).
    listeners : called with the new version after each accepted tile (lock not held).
    """

    folder: Path
    version: int = 0
    rejected: int = 0
    listeners: list[Callable[[int], None]] = field(default_factory=list)
    _tiles: dict[str, StoredTile] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _base: TileFacts | None = None
    _grids: dict[tuple[int, int], tuple[int, float]] = field(default_factory=dict)
    _box: tuple[int, int, int, int] | None = None  # base tiles: west, east, south, north

    def _fits(self, f: TileFacts, sysid: int) -> bool:
        """Whether tile ``f`` of vehicle ``sysid`` keeps the combined map within
        :data:`MAX_COMBINED_CELLS` and has its map's grid; if so, it is accounted (call
        with the lock held)."""
        grid = self._grids.get((sysid, f.map_id))
        if grid is not None and grid != (f.n, f.cell_m):
            return False
        base = self._base if self._base is not None else f
        cols, rows = base_tiles(base, f, map_shift(base, f))
        box = (cols.start, cols.stop - 1, rows.start, rows.stop - 1)
        if self._box is not None:
            w0, e0, s0, n0 = self._box
            box = (min(w0, box[0]), max(e0, box[1]), min(s0, box[2]), max(n0, box[3]))
        cells = (box[1] - box[0] + 1) * (box[3] - box[2] + 1) * base.n * base.n
        if cells > MAX_COMBINED_CELLS:
            return False
        self._base, self._box = base, box
        self._grids.setdefault((sysid, f.map_id), (f.n, f.cell_m))
        return True

    @classmethod
    def open(cls, folder: Path) -> MapStore:
        """The store of ``folder`` (created if missing), with every readable tile in it."""
        folder.mkdir(parents=True, exist_ok=True)
        store = cls(folder)
        paths = []
        for path in (*folder.glob("m*-*"), *folder.glob("v*-m*-*")):
            with contextlib.suppress(OSError):
                paths.append((path.stat().st_mtime_ns, path.name, path))
        for seq, (_, _, path) in enumerate(sorted(paths), start=1):
            if ".part" in path.name:
                continue
            try:
                got = read_tile(path.read_bytes())
            except OSError as err:
                _log.warning("map tile %s not read: %s", path.name, err)
                continue
            sysid = tile_sysid(path.name)
            if got is None or tile_file_name(got[0], sysid) != path.name:
                _log.warning("%s is not a map tile of this station; skipped", path.name)
                continue
            if not store._fits(got[0], sysid):
                _log.warning("%s lies outside the station's map (too far or too big); skipped",
                             path.name)  # fmt: skip
                continue
            store._tiles[path.name] = StoredTile(got[0], path.name, seq, sysid)
        store.version = max((t.seq for t in store._tiles.values()), default=0)
        return store

    def put(self, data: bytes, sysid: int = 0) -> TileFacts | None:
        """Keep a tile received from vehicle ``sysid`` (0: not known) if it is one and
        newer than the one kept; its facts, or None (not a tile, or stale)."""
        got = read_tile(data)
        if got is None:
            self.rejected += 1
            return None
        facts = got[0]
        name = tile_file_name(facts, sysid)
        with self._lock:
            old = self._tiles.get(name)
            # an older station's file of this place (vehicle not known) is this one's
            unnamed = self._tiles.get(tile_file_name(facts)) if sysid else None
            old = old if old is not None else unnamed
            if old is not None and old.facts.version >= facts.version:
                return None
            if not self._fits(facts, sysid):
                self.rejected += 1
                if self.rejected <= 20 or self.rejected % 1000 == 0:
                    _log.warning("map tile %s refused: outside the station's map (too far "
                                 "or too big); %d refused", name, self.rejected)  # fmt: skip
                return None
            with atomic_output(self.folder / name, force=True) as f:
                f.write(data)
            if unnamed is not None:  # taken over: one file per place and vehicle
                del self._tiles[unnamed.name]
                with contextlib.suppress(OSError):
                    (self.folder / unnamed.name).unlink()
            self.version += 1
            self._tiles[name] = StoredTile(facts, name, self.version, sysid)
            version = self.version
        for fn in list(self.listeners):
            try:
                fn(version)
            except Exception:  # a listener's bug must not lose tiles
                _log.exception("map listener failed")
        return facts

    def tiles(self) -> list[StoredTile]:
        """Every tile kept, by file name."""
        with self._lock:
            return [self._tiles[k] for k in sorted(self._tiles)]

    def get(self, name: str) -> StoredTile | None:
        with self._lock:
            return self._tiles.get(name)

    def read(self, name: str) -> bytes | None:
        """The bytes of a kept tile (None: no such tile; names are looked up, never
        opened as given)."""
        t = self.get(name)
        if t is None:
            return None
        try:
            return (self.folder / t.name).read_bytes()
        except OSError:
            return None

    def coverage(self, map_id: int) -> tuple[npt.NDArray[np.float64], TileFacts] | None:
        """Map ``map_id``'s coverage tiles in one raster: (H, W) coverage 0..1 (row 0 the
        north edge), and the facts of its south-west tile (origin, cell, n); None: none."""
        tiles = [t for t in self.tiles() if t.facts.map_id == map_id and t.facts.layer == "cov"]
        if not tiles:
            return None
        tx0 = min(t.facts.tx for t in tiles)
        ty0 = min(t.facts.ty for t in tiles)
        tx1 = max(t.facts.tx for t in tiles)
        ty1 = max(t.facts.ty for t in tiles)
        n = tiles[0].facts.n
        out = np.zeros(((ty1 - ty0 + 1) * n, (tx1 - tx0 + 1) * n))
        for t in tiles:
            data = self.read(t.name)
            got = read_tile(data) if data is not None else None
            if got is None or got[0].n != n:
                continue
            r0 = (ty1 - t.facts.ty) * n
            c0 = (t.facts.tx - tx0) * n
            out[r0 : r0 + n, c0 : c0 + n] = coverage_from_levels(got[1])
        sw = min(tiles, key=lambda t: (t.facts.ty, t.facts.tx)).facts
        origin = TileFacts(
            sw.map_id, "cov", tx0, ty0, n, sw.cell_m, sw.lat0_deg, sw.lon0_deg, sw.version
        )
        return out, origin

    def vehicles(self) -> list[int]:
        """The vehicles (system ids) whose tiles are kept (0: a tile whose vehicle is not
        known), in order."""
        return sorted({t.sysid for t in self.tiles()})

    def inventory(self, sysid: int | None = None) -> TileInventory | None:
        """What is held of vehicle ``sysid``'s newest map (that of its tile kept last;
        None: of every vehicle; tiles whose vehicle is not known count as any vehicle's):
        each tile's version, for its companion to re-send only the others (None: no
        tile)."""
        tiles = [t for t in self.tiles() if sysid is None or t.sysid in (sysid, 0)]
        if not tiles:
            return None
        newest = max(tiles, key=lambda t: t.seq).facts.map_id
        have = {
            (t.facts.layer, t.facts.tx, t.facts.ty): t.facts.version
            for t in tiles
            if t.facts.map_id == newest
        }
        return TileInventory(newest, have)

    def summary(self) -> dict[str, Any]:
        """Counts for logs and tests: tiles per layer, version, rejected pictures."""
        tiles = self.tiles()
        return {
            "version": self.version,
            "cov": sum(t.facts.layer == "cov" for t in tiles),
            "ortho": sum(t.facts.layer == "ortho" for t in tiles),
            "rejected": self.rejected,
        }
