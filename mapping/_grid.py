"""The map's grid: square cells in local east/north metres, north up, split into tiles."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from holescan.mapping.errors import MapError

__all__ = ["MapGrid"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class MapGrid:
    """A north-up grid of square cells in a :class:`geotag.LocalFrame`'s east/north metres.

    west_m, north_m : east and north of the grid's north-west corner, metres.
    cell_m : side of a cell, metres (0.02 = 2 cm).
    nx, ny : columns (west to east) and rows (north to south).
    tile_cells : side of a tile, cells (the unit :meth:`SearchMap.changed_tiles` reports).

    Row ``j``, column ``i`` spans east ``[west + i cell, west + (i + 1) cell)`` and north
    ``(north - (j + 1) cell, north - j cell]``: the layout of a north-up image and GeoTIFF.
    """

    west_m: float
    north_m: float
    cell_m: float
    nx: int
    ny: int
    tile_cells: int = 128

    def __post_init__(self) -> None:
        if not (math.isfinite(self.cell_m) and 0.001 <= self.cell_m <= 100.0):
            raise MapError(f"map cell must be 0.001-100 m, got {self.cell_m!r}")
        if not (math.isfinite(self.west_m) and math.isfinite(self.north_m)):
            raise MapError("map corner must be finite metres")
        if not (1 <= self.nx <= 50_000 and 1 <= self.ny <= 50_000):
            raise MapError(f"map must be 1-50000 cells a side, got {self.nx} x {self.ny}")
        if not 8 <= self.tile_cells <= 4096:
            raise MapError(f"tile must be 8-4096 cells, got {self.tile_cells}")

    @classmethod
    def covering(
        cls,
        west_m: float,
        south_m: float,
        east_m: float,
        north_m: float,
        cell_m: float = 0.02,
        tile_cells: int = 128,
    ) -> MapGrid:
        """The grid of ``cell_m`` cells covering a box of local metres (edges on whole cells)."""
        if not all(math.isfinite(v) for v in (west_m, south_m, east_m, north_m)):
            raise MapError("map bounds must be finite metres")
        if east_m <= west_m or north_m <= south_m:
            raise MapError(f"map bounds are empty: {west_m}..{east_m} E, {south_m}..{north_m} N")
        w = math.floor(west_m / cell_m) * cell_m
        n = math.ceil(north_m / cell_m) * cell_m
        nx = max(1, math.ceil((east_m - w) / cell_m - 1e-9))
        ny = max(1, math.ceil((n - south_m) / cell_m - 1e-9))
        return cls(w, n, cell_m, nx, ny, tile_cells)

    @property
    def east_m(self) -> float:
        return self.west_m + self.nx * self.cell_m

    @property
    def south_m(self) -> float:
        return self.north_m - self.ny * self.cell_m

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) = (ny, nx)."""
        return (self.ny, self.nx)

    @property
    def tiles_shape(self) -> tuple[int, int]:
        """(tile rows, tile columns)."""
        t = self.tile_cells
        return (-(-self.ny // t), -(-self.nx // t))

    def cell_of(self, east_m: npt.ArrayLike, north_m: npt.ArrayLike) -> tuple[IntArray, IntArray]:
        """(row, column) of points; outside the grid gives -1 in both."""
        e = np.asarray(east_m, dtype=np.float64)
        n = np.asarray(north_m, dtype=np.float64)
        i = np.floor((e - self.west_m) / self.cell_m)
        j = np.floor((self.north_m - n) / self.cell_m)
        ok = (i >= 0) & (i < self.nx) & (j >= 0) & (j < self.ny)
        return np.where(ok, j, -1).astype(np.int64), np.where(ok, i, -1).astype(np.int64)

    def centres(self) -> tuple[FloatArray, FloatArray]:
        """(east (nx,), north (ny,)) of the cell centres, metres."""
        c = self.cell_m
        east = self.west_m + (np.arange(self.nx, dtype=np.float64) + 0.5) * c
        north = self.north_m - (np.arange(self.ny, dtype=np.float64) + 0.5) * c
        return np.asarray(east, np.float64), np.asarray(north, np.float64)

    def tile_slices(self, tile_row: int, tile_col: int) -> tuple[slice, slice]:
        """(rows, columns) slices of one tile (the last tiles are cut by the grid's edge)."""
        t = self.tile_cells
        tr, tc = self.tiles_shape
        if not (0 <= tile_row < tr and 0 <= tile_col < tc):
            raise MapError(f"no tile ({tile_row}, {tile_col}) in a {tr} x {tc} tile grid")
        return (
            slice(tile_row * t, min(self.ny, (tile_row + 1) * t)),
            slice(tile_col * t, min(self.nx, (tile_col + 1) * t)),
        )
