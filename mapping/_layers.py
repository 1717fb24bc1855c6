"""A map's rasters as a record: what one chunk of frames saw, mergeable with any other."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from holescan.mapping._grid import MapGrid
from holescan.mapping.errors import MapError

__all__ = ["MapLayers", "merge_layers"]

F32 = npt.NDArray[np.float32]


@dataclass(frozen=True, eq=False)
class MapLayers:
    """The rasters of a :class:`SearchMap` (or of a window of one), north up, (ny, nx).

    grid : the cells these arrays cover.
    height_m : float32, the surface's height (up, metres in the local frame) from the best
        look; NaN where no depth reading fell.
    rgb : uint8 (ny, nx, 3), the colour from the best look (nearest and most nadir);
        0 where unseen.
    best_cost : float32, that look's cost, range / cos(off-nadir), metres (inf: none).
    looks : uint16, how many frames saw the cell (a reading or an unread void inside rim).
    log_miss : float32, sum over independent looks of ln(1 - POD_i) (0: never looked);
        coverage = 1 - exp(log_miss).
    """

    grid: MapGrid
    height_m: F32
    rgb: npt.NDArray[np.uint8]
    best_cost: F32
    looks: npt.NDArray[np.uint16]
    log_miss: F32

    def __post_init__(self) -> None:
        shape = self.grid.shape
        for name in ("height_m", "best_cost", "looks", "log_miss"):
            if getattr(self, name).shape != shape:
                raise MapError(f"map layer {name} must be {shape}, got {getattr(self, name).shape}")
        if self.rgb.shape != (*shape, 3):
            raise MapError(f"map layer rgb must be {(*shape, 3)}, got {self.rgb.shape}")

    @classmethod
    def empty(cls, grid: MapGrid) -> MapLayers:
        shape = grid.shape
        return cls(
            grid,
            np.full(shape, np.nan, np.float32),
            np.zeros((*shape, 3), np.uint8),
            np.full(shape, np.inf, np.float32),
            np.zeros(shape, np.uint16),
            np.zeros(shape, np.float32),
        )

    @property
    def coverage(self) -> F32:
        """float32 0..1: the probability an access hole in the cell would have been detected."""
        return np.asarray(-np.expm1(self.log_miss), dtype=np.float32)

    @property
    def seen(self) -> npt.NDArray[np.bool_]:
        return np.asarray(self.looks > 0)

    def window(self, rows: slice, cols: slice) -> MapLayers:
        """The layers of a window of cells (copies), on its own grid."""
        g = self.grid
        r0, r1, _ = rows.indices(g.ny)
        c0, c1, _ = cols.indices(g.nx)
        if r1 <= r0 or c1 <= c0:
            raise MapError("map window is empty")
        sub = MapGrid(
            g.west_m + c0 * g.cell_m,
            g.north_m - r0 * g.cell_m,
            g.cell_m,
            c1 - c0,
            r1 - r0,
            g.tile_cells,
        )
        s = (slice(r0, r1), slice(c0, c1))
        return MapLayers(
            sub,
            self.height_m[s].copy(),
            self.rgb[s].copy(),
            self.best_cost[s].copy(),
            self.looks[s].copy(),
            self.log_miss[s].copy(),
        )

    def seen_window(self) -> MapLayers | None:
        """The smallest window holding every seen cell, or None when nothing was seen."""
        rows = np.flatnonzero(self.looks.any(axis=1))
        cols = np.flatnonzero(self.looks.any(axis=0))
        if len(rows) == 0:
            return None
        return self.window(slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))


def _offset(grid: MapGrid, part: MapGrid) -> tuple[int, int]:
    if abs(part.cell_m - grid.cell_m) > 1e-9 * grid.cell_m:
        raise MapError(f"cannot merge {part.cell_m} m cells into {grid.cell_m} m cells")
    c = (part.west_m - grid.west_m) / grid.cell_m
    r = (grid.north_m - part.north_m) / grid.cell_m
    if abs(c - round(c)) > 1e-6 or abs(r - round(r)) > 1e-6:
        raise MapError("map windows are not aligned on the same cells")
    r0, c0 = round(r), round(c)
    if r0 < 0 or c0 < 0 or r0 + part.ny > grid.ny or c0 + part.nx > grid.nx:
        raise MapError("map window lies outside the grid it is merged into")
    return r0, c0


def merge_layers(grid: MapGrid, parts: Sequence[MapLayers]) -> MapLayers:
    """Merge maps of the same cells (chunks of one flight, or flights of a campaign).

    Looks add, independent looks combine as POD = 1 - prod(1 - POD_i) (their ``log_miss``
    add), height and colour come from the best look of any part. ``parts`` may be windows
    of ``grid`` (:meth:`MapLayers.seen_window`); the result covers ``grid``.
    """
    out = MapLayers.empty(grid)
    for p in parts:
        r0, c0 = _offset(grid, p.grid)
        s = (slice(r0, r0 + p.grid.ny), slice(c0, c0 + p.grid.nx))
        better = p.best_cost < out.best_cost[s]
        out.best_cost[s] = np.where(better, p.best_cost, out.best_cost[s])
        out.height_m[s] = np.where(better, p.height_m, out.height_m[s])
        out.rgb[s] = np.where(better[..., None], p.rgb, out.rgb[s])
        total = out.looks[s].astype(np.uint32) + p.looks
        out.looks[s] = np.minimum(total, np.iinfo(np.uint16).max).astype(np.uint16)
        out.log_miss[s] += p.log_miss
    return out
