"""Several flights on one station: their map tiles combined per cell on one grid.

Each flight's live map has its own id, origin and tile grid
(:class:`missions.TileFacts`). Drawn side by side, a second sortie's "not seen" cells
would lie over what the first one saw. :func:`combine` puts every map kept in a
:class:`~ground.station.mapstore.MapStore` on the grid of the first map received (its
origin, cell and tile size; the others are placed by :class:`geotag.LocalFrame` and
sampled at the nearest cell) and combines them per cell:

* coverage: the probability of detection of independent looks, ``1 - prod(1 - c_i)``
  (the rule :mod:`mapping` uses within a flight);
* orthophoto: the colour of the flight that saw the cell best (highest coverage; on a
  tie, the later flight).

The page draws the combined tiles (``/map/all/...``, :mod:`ground.station.maplayers`),
one image per tile place whatever the number of flights: the crew's "where did we look",
every vehicle's flights together (the live gaps are this map's: not searched by any
vehicle). Each vehicle's own flights combine the same way on the same grid
(``sysid``; ``/map/vSYSID/...``), so that its layer lies exactly over the combined one.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from holescan.ground.station.mapstore import MapStore, StoredTile, base_tiles, map_shift
from holescan.missions import TileFacts, coverage_from_levels, read_tile

__all__ = ["Combined", "CombinedCache", "combine", "combined_places"]


@dataclass(frozen=True)
class Combined:
    """Every map kept, on the base grid.

    base : facts of a tile of the first map (origin ``lat0_deg``/``lon0_deg``, ``cell_m``,
    ``n``). tx0, ty1 : the raster's west tile column and north tile row. cov : (H, W)
    float64 coverage 0..1, row 0 the north edge. rgb : (H, W, 3) uint8 colour of the best
    look; has_rgb : (H, W) bool where there is one.
    """

    base: TileFacts
    tx0: int
    ty1: int
    cov: npt.NDArray[np.float64]
    rgb: npt.NDArray[np.uint8]
    has_rgb: npt.NDArray[np.bool_]

    def tile(self, layer: str, tx: int, ty: int) -> npt.NDArray[np.float64] | None:
        """Coverage (n, n) of base tile (tx, ty), or None outside the raster."""
        sl = self._slices(tx, ty)
        return None if sl is None or layer != "cov" else self.cov[sl]

    def ortho(self, tx: int, ty: int) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.bool_]] | None:
        """Colour (n, n, 3) and where it is known (n, n) of base tile (tx, ty)."""
        sl = self._slices(tx, ty)
        return None if sl is None else (self.rgb[sl], self.has_rgb[sl])

    def _slices(self, tx: int, ty: int) -> tuple[slice, slice] | None:
        n = self.base.n
        r0, c0 = (self.ty1 - ty) * n, (tx - self.tx0) * n
        if r0 < 0 or c0 < 0 or r0 + n > self.cov.shape[0] or c0 + n > self.cov.shape[1]:
            return None
        return slice(r0, r0 + n), slice(c0, c0 + n)


def _base(tiles: list[StoredTile]) -> TileFacts:
    return min(tiles, key=lambda t: t.seq).facts


def _tiles(store: MapStore, sysid: int | None) -> tuple[TileFacts, list[StoredTile]] | None:
    """The base grid (the first tile of every vehicle's) and the tiles of vehicle
    ``sysid`` (None: every tile); None when there are none."""
    every = store.tiles()
    tiles = every if sysid is None else [t for t in every if t.sysid == sysid]
    if not tiles:
        return None
    return _base(every), tiles


def combined_places(
    store: MapStore, sysid: int | None = None
) -> tuple[TileFacts, dict[tuple[int, int], tuple[int, bool]]]:
    """The base grid and, per base tile (tx, ty) any kept tile (of vehicle ``sysid``;
    None: of any) overlaps: (the newest arrival among them, :attr:`StoredTile.seq`;
    whether an orthophoto tile is among them). Cheap (no picture decoded): what
    ``/map.json`` lists. Raises ValueError when there is no such tile."""
    got = _tiles(store, sysid)
    if got is None:
        raise ValueError("no map tiles")
    base, tiles = got
    out: dict[tuple[int, int], tuple[int, bool]] = {}
    shifts: dict[tuple[float, float], tuple[float, float]] = {}
    for t in tiles:
        key = (t.facts.lat0_deg, t.facts.lon0_deg)
        if key not in shifts:
            shifts[key] = map_shift(base, t.facts)
        cols, rows = base_tiles(base, t.facts, shifts[key])
        for tx in cols:
            for ty in rows:
                seq, ortho = out.get((tx, ty), (-1, False))
                out[(tx, ty)] = (max(seq, t.seq), ortho or t.facts.layer == "ortho")
    return base, out


def _span(rs: npt.NDArray[np.intp], cs: npt.NDArray[np.intp]) -> tuple[slice, slice]:
    """The raster block of rows ``rs`` and columns ``cs`` (each contiguous: the cell
    indices are monotonic), as slices so that it is a view."""
    return slice(int(rs[0]), int(rs[-1]) + 1), slice(int(cs[0]), int(cs[-1]) + 1)


def combine(store: MapStore, sysid: int | None = None) -> Combined | None:
    """Every map of ``store`` (of vehicle ``sysid``; None: of every vehicle) combined on
    the base grid (None: no tiles)."""
    picked = _tiles(store, sysid)
    if picked is None:
        return None
    tiles = picked[1]
    base, places = combined_places(store, sysid)
    n, cb = base.n, base.cell_m
    tx0 = min(p[0] for p in places)
    tx1 = max(p[0] for p in places)
    ty0 = min(p[1] for p in places)
    ty1 = max(p[1] for p in places)
    h, w = (ty1 - ty0 + 1) * n, (tx1 - tx0 + 1) * n
    miss = np.ones((h, w))  # prod(1 - c_i)
    best = np.full((h, w), -1.0)
    rgb = np.zeros((h, w, 3), np.uint8)
    # the base cells' centres, east and north in the base map's metres
    east = (tx0 * n + np.arange(w) + 0.5) * cb
    north = ((ty1 + 1) * n - np.arange(h) - 0.5) * cb
    by_map: dict[tuple[int, int], list[StoredTile]] = {}  # (vehicle, map): one flight
    for t in tiles:
        by_map.setdefault((t.sysid, t.facts.map_id), []).append(t)
    # the later flights last: they win ties for the orthophoto
    for _, group in sorted(by_map.items(), key=lambda kv: min(t.seq for t in kv[1])):
        f0 = group[0].facts
        dx, dy = map_shift(base, f0)
        cm, nm = f0.cell_m, f0.n
        col = np.floor((east - dx) / cm).astype(np.int64)  # the map's own cell indices
        row = np.floor((north - dy) / cm).astype(np.int64)
        cov_m = np.zeros((h, w))
        pix: dict[tuple[int, int], npt.NDArray[np.uint8]] = {}
        for t in group:
            data = store.read(t.name)
            got = read_tile(data) if data is not None else None
            if got is None or got[0].n != nm or got[0].cell_m != cm:
                continue
            f = got[0]
            cs = np.nonzero((col >= f.tx * nm) & (col < (f.tx + 1) * nm))[0]
            rs = np.nonzero((row >= f.ty * nm) & (row < (f.ty + 1) * nm))[0]
            if not len(cs) or not len(rs):
                continue
            ci = col[cs] - f.tx * nm
            ri = (f.ty + 1) * nm - 1 - row[rs]  # tile row 0 is its north edge
            block = _span(rs, cs)
            if f.layer == "cov":
                cov_m[block] = coverage_from_levels(got[1])[np.ix_(ri, ci)]
            else:  # colour is taken below, once this map's coverage is known
                pix[(f.tx, f.ty)] = got[1]
        miss *= 1.0 - cov_m
        for (ttx, tty), img in pix.items():
            cs = np.nonzero((col >= ttx * nm) & (col < (ttx + 1) * nm))[0]
            rs = np.nonzero((row >= tty * nm) & (row < (tty + 1) * nm))[0]
            if not len(cs) or not len(rs):
                continue
            block = _span(rs, cs)  # views: written in place
            c = cov_m[block]
            b = best[block]
            take = (c > 0) & (c >= b)
            colours = img[np.ix_((tty + 1) * nm - 1 - row[rs], col[cs] - ttx * nm)]
            rgb[block][take] = colours[take]
            b[take] = c[take]
    return Combined(base, tx0, ty1, 1.0 - miss, rgb, best > 0)


class CombinedCache:
    """:func:`combine` of a store (of vehicle ``sysid``; None: every vehicle), computed
    again only when the store changed."""

    def __init__(self, store: MapStore, sysid: int | None = None) -> None:
        self.store = store
        self.sysid = sysid
        self._lock = threading.Lock()
        self._version = -1
        self._combined: Combined | None = None

    def get(self) -> Combined | None:
        with self._lock:
            if self._version != self.store.version:
                version = self.store.version
                self._combined = combine(self.store, self.sysid)
                self._version = version
            return self._combined
