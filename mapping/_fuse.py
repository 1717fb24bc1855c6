"""Fuse posed RGB-D frames into the search map, one frame at a time (vectorised numpy).

Per frame (``pixel_stride`` s: every s-th pixel of every s-th row):


0. ``pixel_stride`` is by default the largest step that leaves no cell in view without a
   sample: a cell's width at the frame's median range, times the cosine of the off-nadir
   angle of the most oblique edge midpoint (oblique rays spread on the ground).
1. Each read pixel is back-projected (:class:`detect.CameraIntrinsics`) and moved into the
   local frame by the camera's pose (:func:`geotag.camera_pose_local`). Its **view angle**
   is the angle between the line of sight and the terrain's normal there, the normal taken
   from the points ``normal_span_m`` (0.75 m) either side: the scale of the terrain plane
   around a hole's box that ``benchmarks/bench_recall.py`` measured the angle to; where
   those are not read, the normal is up.
2. An unread pixel is a look too when enough of the image around it (``void_window_m``,
   1.6 m: wider than the largest access hole, so a void's centre sees its rim) was read:
   an access hole's void has no reading, but its rim has, and that is what the detector
   finds it by. It is placed where its ray meets the height of the lowest reading around
   it (inside a hole the ray runs down past the rim; at an occluding edge it runs on to the
   ground beyond); its view angle is to the vertical. Unread far field or sheet metal without
   readings around it is not a look, nor an unread pixel beside a surface over 0.5 m
   nearer than that (a dropout at an occluding edge: its ray stops there).
3. **Z-buffer per cell**: of the samples falling in one cell, the highest read one is the
   cell's surface in this frame (then the highest unread-void one): a wall or a floor below
   the rim seen in the same cell is not the cell's look. A cell behind a slab receives no
   sample and is not looked at; a 2.5-D map cannot tell a surface under an overhang.
4. The look's probability of detection is the measured recall at its range and angle
   (:class:`RecallTable`); for a sample 0.2 m or more below the mean height of the readings
   around it (a hole's floor, a void) at the range where its ray crosses that level, and
   the angle to the vertical: a look into a hole is a look at its opening. Looks from
   camera positions within ``independent_m`` of where a cell's current pass began are one
   pass (their best POD: consecutive frames miss alike); passes combine as
   POD = 1 - prod(1 - POD_pass).
5. The best look (least range / cos(off-nadir)) gives the cell's height and colour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect import BAND_MAX_PX, CameraIntrinsics, unread_bands
from holescan.geotag import LocalCameraPose, LocalFrame
from holescan.mapping._grid import MapGrid
from holescan.mapping._layers import MapLayers
from holescan.mapping._recall import RecallTable, default_recall_table
from holescan.mapping.errors import MapError

__all__ = ["FrameFused", "FuseParams", "SearchMap"]

F32 = npt.NDArray[np.float32]

_MAX_POD = 0.999  # one pass never proves a cell empty (and ln(1 - POD) stays finite)
_OCCLUDER_WINDOW_M = 0.3  # an unread pixel's neighbourhood searched for a nearer surface
_OCCLUDER_GAP_M = 0.5  # that much nearer than the terrain behind: an occluding edge
_BELOW_TERRAIN_M = 0.2  # a sample this far below the terrain's level around it is in a hole


@dataclass(frozen=True)
class FuseParams:
    """How frames are fused (see the module's docstring).

    pixel_stride : default sampling step, pixels; None (default): the largest step whose
        samples at the frame's median range are no farther apart than a cell (2 cm cells,
        Xtion at 3 m: 3), so every cell in view gets a sample.
    normal_span_m : the terrain normal from points this far either side (at the frame's
        median range).
    void_window_m : side of the window around an unread pixel whose read fraction decides
        whether it is a look; void_min_read : that fraction.
    independent_m : camera displacement after which a new look at a cell is independent.
    """

    pixel_stride: int | None = None
    normal_span_m: float = 0.75
    void_window_m: float = 1.6
    void_min_read: float = 0.25
    independent_m: float = 1.0

    def __post_init__(self) -> None:
        if self.pixel_stride is not None and not 1 <= self.pixel_stride <= 64:
            raise MapError(f"pixel_stride must be 1-64, got {self.pixel_stride}")
        if not (0.0 < self.normal_span_m <= 10.0 and 0.0 < self.void_window_m <= 10.0):
            raise MapError("normal_span_m and void_window_m must be 0-10 metres")
        if not 0.0 < self.void_min_read <= 1.0:
            raise MapError(f"void_min_read must be in (0, 1], got {self.void_min_read}")
        if not (math.isfinite(self.independent_m) and self.independent_m >= 0.0):
            raise MapError(f"independent_m must be >= 0 metres, got {self.independent_m}")


@dataclass(frozen=True)
class FrameFused:
    """What one :meth:`SearchMap.add_frame` did.

    version : the map's version after it (1 after the first frame).
    samples : pixels sampled; read : of them with a depth reading; voids : unread looks.
    cells : cells looked at (inside the grid); outside : samples that fell off the grid.
    """

    version: int
    samples: int
    read: int
    voids: int
    cells: int
    outside: int


class SearchMap:
    """The search picture being built: height, colour, looks and coverage on a grid.

    Parameters
    ----------
    grid : the cells (local east/north metres of ``frame``).
    frame : the local frame the grid and the poses are in (kept for georeferencing).
    recall : per-look probability of detection (default: the measured table).
    params : fusing choices (:class:`FuseParams`).

    Examples
    --------
    >>> from holescan.geotag import LocalFrame
    >>> m = SearchMap(MapGrid.covering(0, 0, 10, 10, 0.05), LocalFrame(47.0, 8.0))
    >>> m.version, bool(m.layers().coverage.any())  # nothing fused yet: nothing covered
    (0, False)
    """

    def __init__(
        self,
        grid: MapGrid,
        frame: LocalFrame,
        recall: RecallTable | None = None,
        params: FuseParams | None = None,
    ) -> None:
        self.grid = grid
        self.frame = frame
        self.recall = recall if recall is not None else default_recall_table()
        self.params = params if params is not None else FuseParams()
        shape = grid.shape
        self._layers = MapLayers.empty(grid)
        self._pass_pod = np.zeros(shape, np.float32)
        self._pass_e = np.zeros(shape, np.float32)
        self._pass_n = np.zeros(shape, np.float32)
        self._tile_version = np.zeros(grid.tiles_shape, np.int64)
        self._rays: dict[tuple[CameraIntrinsics, int], tuple[F32, F32]] = {}
        self.version = 0

    # -------------------------------------------------------------------- results

    def layers(self) -> MapLayers:
        """A snapshot of every raster (copies; open passes counted)."""
        lay = self._layers
        log_miss = lay.log_miss + np.log1p(-self._pass_pod)
        return MapLayers(
            self.grid,
            lay.height_m.copy(),
            lay.rgb.copy(),
            lay.best_cost.copy(),
            lay.looks.copy(),
            log_miss.astype(np.float32),
        )

    def seen_window(self) -> MapLayers | None:
        """The layers of the smallest window holding every cell seen (None: nothing seen);
        what :meth:`layers` then :meth:`MapLayers.seen_window` give, without copying the
        whole grid first."""
        looks = self._layers.looks
        rows = np.flatnonzero(looks.any(axis=1))
        if len(rows) == 0:
            return None
        cols = np.flatnonzero(looks[rows[0] : rows[-1] + 1].any(axis=0))
        r, c = slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)
        win = self._layers.window(r, c)
        win.log_miss[...] += np.log1p(-self._pass_pod[r, c])
        return win

    def changed_tiles(self, since_version: int) -> list[tuple[int, int]]:
        """(tile row, tile column) of every tile changed after ``since_version``, row-major."""
        rows, cols = np.nonzero(self._tile_version > since_version)
        return [(int(r), int(c)) for r, c in zip(rows, cols, strict=True)]

    def tile_version(self, tile_row: int, tile_col: int) -> int:
        """The map version that last changed one tile (0: never)."""
        self.grid.tile_slices(tile_row, tile_col)  # validates
        return int(self._tile_version[tile_row, tile_col])

    # -------------------------------------------------------------------- fusing

    def _camera_rays(self, camera: CameraIntrinsics, stride: int) -> tuple[F32, F32]:
        key = (camera, stride)
        if key not in self._rays:
            v, u = np.mgrid[0 : camera.height : stride, 0 : camera.width : stride]
            x = (u - camera.cx) / camera.fx
            y = (v - camera.cy) / camera.fy
            rays = np.stack([x, y, np.ones_like(x)], axis=-1).astype(np.float32)
            self._rays[key] = (rays, np.linalg.norm(rays, axis=-1).astype(np.float32))
        return self._rays[key]

    def add_frame(
        self,
        depth: npt.NDArray[np.uint16],
        rgb: npt.NDArray[np.uint8],
        camera: CameraIntrinsics,
        pose: LocalCameraPose,
        *,
        pixel_stride: int | None = None,
    ) -> FrameFused:
        """Fuse one registered RGB-D frame.

        Parameters
        ----------
        depth : (H, W) uint16, depth along the optical axis in ``camera.depth_unit_m``
            units (millimetres), 0 = no reading.
        rgb : (H, W, 3) uint8, registered to ``depth``.
        camera : intrinsics of both images (H = camera.height, W = camera.width).
        pose : the camera's pose in this map's local frame (:func:`geotag.camera_pose_local`).
        pixel_stride : sampling step, pixels (default ``params.pixel_stride``; None: a
            cell's width at the frame's median range, at most 64).

        Raises
        ------
        MapError
            On images of the wrong shape or dtype, or a bad stride.
        """
        hw = (camera.height, camera.width)
        if depth.shape != hw or depth.dtype != np.uint16:
            raise MapError(f"depth must be {hw} uint16, got {depth.shape} {depth.dtype}")
        if rgb.shape != (*hw, 3) or rgb.dtype != np.uint8:
            raise MapError(f"rgb must be {(*hw, 3)} uint8, got {rgb.shape} {rgb.dtype}")
        coarse = depth[::8, ::8]
        coarse = coarse[coarse > 0]
        z_med = float(np.median(coarse)) * camera.depth_unit_m if coarse.size else 3.0
        px_per_m = camera.fx / max(z_med, 0.1)
        stride = pixel_stride if pixel_stride is not None else self.params.pixel_stride
        if stride is None:
            # Oblique rays spread their samples on the ground: by 1 / cos(off-nadir) at the
            # edges' midpoints, the most oblique part of the image that matters.
            mids = np.array(
                [
                    [camera.width / 2, 0.0],
                    [camera.width / 2, camera.height - 1.0],
                    [0.0, camera.height / 2],
                    [camera.width - 1.0, camera.height / 2],
                ]
            )
            rays_e = (
                np.column_stack(
                    [
                        (mids[:, 0] - camera.cx) / camera.fx,
                        (mids[:, 1] - camera.cy) / camera.fy,
                        np.ones(4),
                    ]
                )
                @ pose.rotation.T
            )
            spread = float(np.min(np.abs(rays_e[:, 2]) / np.linalg.norm(rays_e, axis=1)))
            stride = min(64, max(1, math.floor(self.grid.cell_m * px_per_m * max(spread, 0.2))))
        s = int(stride)
        if not 1 <= s <= 64:
            raise MapError(f"pixel_stride must be 1-64, got {s}")
        rays, ray_len = self._camera_rays(camera, s)
        z = depth[::s, ::s].astype(np.float32) * np.float32(camera.depth_unit_m)
        read = z > 0
        r = pose.rotation.astype(np.float32)
        c = pose.position_m.astype(np.float32)
        dirs = rays @ r.T  # ENU per metre of optical depth
        pts = dirs * z[..., None] + c
        up_cos = np.abs(dirs[..., 2]) / ray_len  # cos of the line of sight's off-nadir angle

        k = max(1, round(self.params.normal_span_m * px_per_m / s))
        cos_view = self._cos_view(pts, read, dirs, ray_len, k)
        window = max(3, round(self.params.void_window_m * px_per_m / s) | 1)
        near = max(3, round(_OCCLUDER_WINDOW_M * px_per_m / s) | 1)
        void, void_pts, void_t, level = self._voids(pts, z, read, dirs, c, window, near)
        t_pt = np.where(read, z, void_t)
        rng = t_pt * ray_len
        pts = np.where(read[..., None], pts, void_pts)
        # A sample well below the terrain around it (a hole's floor, a void placed on the
        # lowest reading) is a look at the opening: its range is where its ray crosses the
        # terrain's level, its angle the line of sight's to the vertical.
        with np.errstate(divide="ignore", invalid="ignore"):
            t_level = (level - c[2]) / dirs[..., 2]
        in_hole = (pts[..., 2] < level - _BELOW_TERRAIN_M) & np.isfinite(t_level) & (t_level > 0)
        rng_pod = np.where(in_hole, np.minimum(t_level, t_pt), t_pt) * ray_len
        cos_view = np.where(read & ~in_hole, cos_view, up_cos)
        # Where in the image: distance from the edge of the read area (the frame without
        # its unread border bands: no look at all there), pixels at 640 wide.
        border = self._border_px(depth, camera, s, z.shape)
        looked = (read | void) & (border >= 0)
        ang = np.degrees(np.arccos(np.clip(cos_view, 0.0, 1.0)))

        rows, cols = self.grid.cell_of(pts[..., 0][looked], pts[..., 1][looked])
        inside = rows >= 0
        n_out = int(np.count_nonzero(~inside))
        sel = np.flatnonzero(looked.ravel())[inside]
        idx = rows[inside] * self.grid.nx + cols[inside]
        is_read = read.ravel()[sel]
        h = pts[..., 2].ravel()[sel]
        # Z-buffer per cell: the highest read sample, else the highest unread void.
        order = np.lexsort((h, is_read, idx))
        idx_s = idx[order]
        last = np.ones(len(idx_s), bool)
        last[:-1] = idx_s[1:] != idx_s[:-1]
        top = order[last]
        cell = idx[top]
        src = sel[top]
        pod = self.recall.pod(rng_pod.ravel()[src], ang.ravel()[src], border.ravel()[src])
        pod = np.minimum(pod, _MAX_POD)
        self.version += 1
        self._update(cell, src, is_read[top], pod, pts, rgb[::s, ::s], rng, up_cos, c)
        return FrameFused(
            self.version,
            int(z.size),
            int(np.count_nonzero(read)),
            int(np.count_nonzero(void)),
            len(cell),
            n_out,
        )

    @staticmethod
    def _border_px(
        depth: npt.NDArray[np.uint16], camera: CameraIntrinsics, s: int, shape: tuple[int, ...]
    ) -> F32:
        """Per sample, its distance (pixels at 640 wide) from the nearest edge of the frame's
        read area; negative in an unread border band."""
        k = 640.0 / camera.width
        left, top, right, bottom = unread_bands(depth == 0, max(1, round(BAND_MAX_PX / k)))
        u = np.arange(shape[1], dtype=np.float32) * s
        v = np.arange(shape[0], dtype=np.float32) * s
        du = np.minimum(u - left, camera.width - 1 - right - u)
        dv = np.minimum(v - top, camera.height - 1 - bottom - v)
        return (np.minimum(du[None, :], dv[:, None]) * np.float32(k)).astype(np.float32)

    @staticmethod
    def _cos_view(pts: F32, read: npt.NDArray[np.bool_], dirs: F32, ray_len: F32, k: int) -> F32:
        """|cos| of the angle between each line of sight and the terrain normal there."""
        h, w = read.shape
        jp = np.minimum(np.arange(w) + k, w - 1)
        jm = np.maximum(np.arange(w) - k, 0)
        ip = np.minimum(np.arange(h) + k, h - 1)
        im = np.maximum(np.arange(h) - k, 0)
        dx = pts[:, jp] - pts[:, jm]
        dy = pts[ip] - pts[im]
        ok = read[:, jp] & read[:, jm] & read[ip] & read[im]
        n = np.cross(dx, dy)
        nn = np.linalg.norm(n, axis=-1)
        ok &= nn > 1e-9
        n = np.where(
            ok[..., None],
            n / np.maximum(nn, 1e-9)[..., None],
            np.array([0.0, 0.0, 1.0], np.float32),
        )
        return np.asarray(np.abs(np.einsum("ijk,ijk->ij", n, dirs)) / ray_len, dtype=np.float32)

    def _voids(
        self,
        pts: F32,
        z: F32,
        read: npt.NDArray[np.bool_],
        dirs: F32,
        c: F32,
        ks: int,
        near: int,
    ) -> tuple[npt.NDArray[np.bool_], F32, F32, F32]:
        """Unread samples that are looks: their mask, points and optical depth; and the
        terrain's level around every sample (the mean height of the readings).

        Not a look: an unread pixel beside a surface much nearer than where its ray would
        meet the terrain (a dropout or projector shadow at an occluding edge: its ray ends
        on that surface, not behind it)."""
        rf = read.astype(np.float32)
        frac = cv2.blur(rf, (ks, ks), borderType=cv2.BORDER_REPLICATE)
        # The lowest read surface around: inside a hole the ray runs down past the rim; at
        # an occluding edge it runs on to the ground beyond.
        kernel = np.ones((ks, ks), np.uint8)
        zloc = cv2.erode(np.where(read, pts[..., 2], np.float32(1e4)).astype(np.float32), kernel)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (zloc - c[2]) / dirs[..., 2]
        zmin = cv2.erode(np.where(read, z, np.float32(1e4)), np.ones((near, near), np.uint8))
        void = ~read & (frac >= self.params.void_min_read) & np.isfinite(t) & (t > 0)
        void &= t <= zmin + _OCCLUDER_GAP_M
        t = np.where(void, t, 0.0).astype(np.float32)
        hsum = cv2.blur(
            np.where(read, pts[..., 2], 0.0).astype(np.float32),
            (ks, ks),
            borderType=cv2.BORDER_REPLICATE,
        )
        level = (hsum / np.maximum(frac, 1e-6)).astype(np.float32)
        return void, (dirs * t[..., None] + c).astype(np.float32), t, level

    def _update(
        self,
        cell: npt.NDArray[np.int64],
        src: npt.NDArray[np.int64],
        is_read: npt.NDArray[np.bool_],
        pod: F32,
        pts: F32,
        rgb: npt.NDArray[np.uint8],
        rng: F32,
        up_cos: F32,
        cam: F32,
    ) -> None:
        lay = self._layers
        # Best look: height and colour.
        rc, rs = cell[is_read], src[is_read]
        cost = rng.ravel()[rs] / np.maximum(up_cos.ravel()[rs], 0.05)
        best = lay.best_cost.ravel()
        better = cost < best[rc]
        bc, bs = rc[better], rs[better]
        best[bc] = cost[better]
        lay.height_m.ravel()[bc] = pts[..., 2].ravel()[bs]
        lay.rgb.reshape(-1, 3)[bc] = rgb.reshape(-1, 3)[bs]
        # Looks and passes.
        looks = lay.looks.ravel()
        pe, pn, pp = self._pass_e.ravel(), self._pass_n.ravel(), self._pass_pod.ravel()
        d2 = (pe[cell] - cam[0]) ** 2 + (pn[cell] - cam[1]) ** 2
        new = (looks[cell] == 0) | (d2 >= self.params.independent_m**2)
        nc = cell[new]
        lay.log_miss.ravel()[nc] += np.log1p(-pp[nc])
        pp[nc] = pod[new]
        pe[nc] = cam[0]
        pn[nc] = cam[1]
        oc = cell[~new]
        pp[oc] = np.maximum(pp[oc], pod[~new])
        looks[cell] = np.minimum(looks[cell].astype(np.uint32) + 1, 65535).astype(np.uint16)
        t = self.grid.tile_cells
        tiles = np.unique(
            (cell // self.grid.nx // t) * self.grid.tiles_shape[1] + (cell % self.grid.nx) // t
        )
        self._tile_version.ravel()[tiles] = self.version
