"""The live map on board: a coarse search map kept current beside capture, sent down as tiles.

:class:`LiveMap` fuses a subsample of the flight's posed frames into a coarse
:class:`mapping.SearchMap` (default 10 cm cells, every 8th pixel of every 8th row) on its
own thread, and cuts what changed into tiles for the radio (:mod:`missions._maptiles`),
which it hands to the hole server's picture sender as its :class:`missions.TileSource`.

Capture never waits: :meth:`LiveMap.offer` (the capture thread, per frame) only replaces
the one frame waiting, by reference. The map thread lowers its own priority
(``nice`` +15 on Linux, below the detection worker's +10) and keeps a **CPU budget**:
each offered frame adds ``budget_ms`` of credit (at most ``budget_burst_ms`` saved), each
fused frame spends its measured thread CPU time, and a frame is fused only when the credit
is positive and at least ``frame_every`` frames have passed. So the map's cost stays
within ``budget_ms`` per captured frame amortised whatever the machine, and on a slow
one it simply fuses fewer frames.

Tiles: every ``publish_s`` the tiles changed since the last cut are encoded (coverage
PNG and orthophoto JPEG, :func:`missions.encode_coverage_tile` /
:func:`missions.encode_ortho_tile`) into an outbox holding the newest bytes of each.
:meth:`next_tile` (the server thread) gives **coverage first**: the coverage tile waiting
longest whose last send is ``cov_resend_s`` old, then orthophoto tiles likewise with
``ortho_resend_s``; pictures of holes go before any tile (the sender's rule).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import InputError
from holescan.geotag import CameraMount, LocalFrame, VehiclePose, camera_pose_local
from holescan.mapping import FuseParams, MapGrid, SearchMap
from holescan.missions import (
    CELL_M_RANGE,
    MAP_RADIUS_MAX_M,
    TILE_CELLS_RANGE,
    TYPE_COVERAGE,
    TYPE_ORTHO,
    MapLayer,
    TileFacts,
    encode_coverage_tile,
    encode_ortho_tile,
)

__all__ = ["SAMPLES", "LiveMap", "LiveMapConfig", "LiveMapStats"]

_log = logging.getLogger(__name__)
_NICE = 15
SAMPLES = 100_000
"""How many recent samples :class:`LiveMapStats` keeps of each kind."""


@dataclass(frozen=True)
class LiveMapConfig:
    """How the on-board map is kept and sent.

    cell_m : cell side, metres. tile_cells : cells per tile side.
    radius_m : the map reaches this far east/west/north/south of the first posed frame
        (rounded up to whole tiles); samples beyond are dropped and counted.
    pixel_stride : every n-th pixel of every n-th row is fused.
    frame_every : at most every n-th frame is fused.
    budget_ms : CPU per captured frame, amortised (thread CPU time of the map thread:
        fusing and tile encoding). budget_burst_ms : most credit saved up.
    publish_s : how often changed tiles are cut and encoded.
    cov_resend_s, ortho_resend_s : a tile that keeps changing is sent at most this often.
    """

    cell_m: float = 0.1
    tile_cells: int = 64
    radius_m: float = 50.0
    pixel_stride: int = 8
    frame_every: int = 4
    budget_ms: float = 2.0
    budget_burst_ms: float = 60.0
    publish_s: float = 3.0
    cov_resend_s: float = 4.0
    ortho_resend_s: float = 15.0

    def __post_init__(self) -> None:
        checks = (
            CELL_M_RANGE[0] <= self.cell_m <= CELL_M_RANGE[1],
            TILE_CELLS_RANGE[0] <= self.tile_cells <= TILE_CELLS_RANGE[1],
            1.0 <= self.radius_m <= MAP_RADIUS_MAX_M,
            1 <= self.pixel_stride <= 64,
            1 <= self.frame_every <= 1000,
            0.0 < self.budget_ms <= 1000.0,
            self.budget_burst_ms >= self.budget_ms,
            0.0 < self.publish_s <= 600.0,
            self.cov_resend_s >= 0.0 and self.ortho_resend_s >= 0.0,
        )
        if not all(checks):
            raise InputError(f"live map settings out of range: {self}")

    @property
    def tile_m(self) -> float:
        return self.cell_m * self.tile_cells


@dataclass
class LiveMapStats:
    """Counters of one live map (read them any time; they only grow).

    offered : frames offered by capture. fused : frames fused. unposed : offered without a
    pose. skipped_budget : frames passed over for lack of CPU credit or ``frame_every``.
    dropped : frames taken for the map that :meth:`LiveMap.close` came before (the one
    waiting, and one the map thread had not fused yet). Every offered frame is one of
    fused, unposed, skipped_budget and dropped (a frame whose fusing failed is logged).
    fuse_cpu_ms : thread CPU of each fused frame (fusing only). publish_cpu_ms : of each
    tile cut (layers + encoding). offer_ns : wall time of each :meth:`LiveMap.offer`.
    tile_bytes : the sizes of the tiles encoded, by layer. These four keep the last
    ``SAMPLES`` values (a long flight's memory stays bounded); the totals are exact.
    tiles_encoded : tiles put in the outbox. fused_t_mono_ns : the capture time
    (:attr:`detect.Frame.t_mono_ns`) of each fused frame, so what the map was made of can be
    checked against the sensor's truth (the last ``SAMPLES`` too).
    """

    offered: int = 0
    fused: int = 0
    unposed: int = 0
    skipped_budget: int = 0
    dropped: int = 0
    outside: int = 0
    fuse_cpu_ms: deque[float] = field(default_factory=lambda: deque(maxlen=SAMPLES))
    publish_cpu_ms: deque[float] = field(default_factory=lambda: deque(maxlen=SAMPLES))
    offer_ns: deque[int] = field(default_factory=lambda: deque(maxlen=SAMPLES))
    tiles_encoded: int = 0
    tile_bytes: dict[str, deque[int]] = field(
        default_factory=lambda: {"cov": deque(maxlen=SAMPLES), "ortho": deque(maxlen=SAMPLES)}
    )
    fused_t_mono_ns: deque[int] = field(default_factory=lambda: deque(maxlen=SAMPLES))
    cpu_ms: float = 0.0
    """The map thread's CPU time so far (fusing and tile cutting), ms."""


@dataclass
class _Out:
    data: bytes
    changed_at: float
    sent_at: float = -math.inf
    sent: bool = False


class LiveMap:
    """The on-board live map (see the module docstring). Use as a context manager.

    camera, mount : the frames' intrinsics and the camera's mounting.
    config : :class:`LiveMapConfig`.
    """

    def __init__(
        self,
        camera: CameraIntrinsics,
        mount: CameraMount,
        config: LiveMapConfig | None = None,
    ) -> None:
        self.camera = camera
        self.mount = mount
        self.config = config or LiveMapConfig()
        self.stats = LiveMapStats()
        self.map: SearchMap | None = None
        self.map_id = 0
        self._clock = time.monotonic
        self._tiles_k = math.ceil(self.config.radius_m / self.config.tile_m)
        self._slot: tuple[Frame, VehiclePose] | None = None
        self._cond = threading.Condition()
        self._lock = threading.Lock()  # the map
        self._out_lock = threading.Lock()  # the outbox (the sender's thread)
        self._stop = False
        self._sealed = False  # closed: nothing more is fused (the last cut holds it all)
        self._credit_ms = 0.0
        self._since_fused = 0
        self._published = 0
        self._next_publish = 0.0
        self._outbox: dict[tuple[MapLayer, int, int], _Out] = {}
        self._final = False
        self._thread = threading.Thread(target=self._run, name="live-map", daemon=True)

    # -- lifecycle --------------------------------------------------------------------
    def __enter__(self) -> LiveMap:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the thread (the frame waiting is dropped and counted); the last changes are cut.

        A frame the thread (low priority: a loaded machine may not run it for seconds) has
        not fused by then never is: every frame :attr:`LiveMapStats.fused` counts is in
        the last cut's tiles.
        """
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        with self._lock:
            self._sealed = True
            with self._cond:
                if self._slot is not None:
                    self._slot = None
                    self.stats.dropped += 1
        self.publish()

    # -- the capture thread -----------------------------------------------------------
    def offer(self, frame: Frame, pose: VehiclePose | None) -> None:
        """Offer one captured frame and its pose (None: unposed); never waits."""
        t0 = time.perf_counter_ns()
        s = self.stats
        s.offered += 1
        with self._cond:
            self._credit_ms = min(
                self._credit_ms + self.config.budget_ms, self.config.budget_burst_ms
            )
            self._since_fused += 1
            if pose is None:
                s.unposed += 1
            elif self._credit_ms > 0 and self._since_fused >= self.config.frame_every:
                if self._slot is not None:
                    s.skipped_budget += 1
                self._slot = (frame, pose)
                self._since_fused = 0
                self._cond.notify()
            else:
                s.skipped_budget += 1
        s.offer_ns.append(time.perf_counter_ns() - t0)

    # -- the map thread ---------------------------------------------------------------
    def _run(self) -> None:
        with contextlib.suppress(OSError, AttributeError):  # not Linux: default priority
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), _NICE)
        while True:
            with self._cond:
                while self._slot is None and not self._stop:
                    self._cond.wait(timeout=self.config.publish_s)
                    if self._slot is None and not self._stop:
                        break
                if self._stop:
                    return
                item, self._slot = self._slot, None
                if item is not None and self._credit_ms <= 0:
                    # Offered while the frame before was being fused, on the credit before
                    # that frame's cost was spent: the credit decides again now.
                    self.stats.skipped_budget += 1
                    item = None
            if item is not None:
                try:
                    self.fuse(*item)
                except Exception:  # the map is nice to have; never stop the flight
                    _log.exception("live map: frame %d not fused", item[0].index)
            if self._stop:  # close() cuts the last tiles
                return
            if self._clock() >= self._next_publish:
                t0 = time.thread_time()
                try:
                    self.publish()
                except Exception:
                    _log.exception("live map: tiles not cut")
                cost = (time.thread_time() - t0) * 1000.0
                with self._cond:
                    self._credit_ms -= cost
                self._next_publish = self._clock() + self.config.publish_s

    def _make_map(self, pose: VehiclePose) -> SearchMap:
        cfg = self.config
        k = self._tiles_k
        n = 2 * k * cfg.tile_cells
        grid = MapGrid(-k * cfg.tile_m, k * cfg.tile_m, cfg.cell_m, n, n, cfg.tile_cells)
        frame = LocalFrame(pose.lat_deg, pose.lon_deg, pose.alt_m - pose.rel_alt_m)
        key = f"{pose.lat_deg:.7f},{pose.lon_deg:.7f},{time.time_ns()}".encode()
        self.map_id = zlib.crc32(key) & 0x7FFFFFFF
        return SearchMap(grid, frame, params=FuseParams(pixel_stride=cfg.pixel_stride))

    def fuse(self, frame: Frame, pose: VehiclePose) -> None:
        """Fuse one frame now (the map thread calls it; a benchmark may call it directly);
        after :meth:`close` nothing is fused."""
        t0 = time.thread_time()
        with self._lock:
            if self._sealed:
                self.stats.dropped += 1
                return
            if self.map is None:
                self.map = self._make_map(pose)
            m = self.map
            cam = camera_pose_local(m.frame, self.mount, pose)
            done = m.add_frame(frame.depth, frame.rgb, self.camera, cam)
        cost = (time.thread_time() - t0) * 1000.0
        self.stats.fused += 1
        self.stats.fused_t_mono_ns.append(frame.t_mono_ns)
        self.stats.outside += done.outside
        self.stats.fuse_cpu_ms.append(cost)
        self.stats.cpu_ms += cost
        with self._cond:
            self._credit_ms -= cost

    def publish(self) -> int:
        """Cut and encode the tiles changed since the last cut; return how many."""
        t0 = time.thread_time()
        with self._lock:
            m = self.map
            if m is None:
                return 0
            changed = m.changed_tiles(self._published)
            if not changed:
                return 0
            layers = m.layers()
            version = m.version
            frame = m.frame
        cfg, k = self.config, self._tiles_k
        now = self._clock()
        out: dict[tuple[MapLayer, int, int], bytes] = {}
        for row, col in changed:
            w = layers.window(*layers.grid.tile_slices(row, col))
            tx, ty = col - k, k - 1 - row
            seen = w.seen

            def facts(layer: MapLayer, tx: int = tx, ty: int = ty) -> TileFacts:
                return TileFacts(
                    self.map_id,
                    layer,
                    tx,
                    ty,
                    cfg.tile_cells,
                    cfg.cell_m,
                    frame.lat0_deg,
                    frame.lon0_deg,
                    version,
                )

            # a seen cell is never sent as unseen, whatever its coverage
            cov = np.where(seen, np.maximum(w.coverage, 1e-3), 0.0)
            out[("cov", tx, ty)] = encode_coverage_tile(cov, facts("cov"))
            out[("ortho", tx, ty)] = encode_ortho_tile(w.rgb, seen, facts("ortho"))
        with self._out_lock:
            self._published = version
            for key, data in out.items():
                o = self._outbox.get(key)
                if o is None:
                    self._outbox[key] = _Out(data, now)
                else:  # keeps its last send time: the resend period holds
                    if o.sent:
                        o.changed_at = now
                    o.data, o.sent = data, False
                self.stats.tile_bytes[key[0]].append(len(data))
            self.stats.tiles_encoded += len(out)
        cost = (time.thread_time() - t0) * 1000.0
        self.stats.publish_cpu_ms.append(cost)
        self.stats.cpu_ms += cost
        return len(out)

    # -- the sender (missions.TileSource) ---------------------------------------------
    def next_tile(self) -> tuple[int, bytes] | None:
        """The next tile due: coverage first, then orthophoto (see the module docstring)."""
        now = self._clock()
        with self._out_lock:
            for layer, period, kind in (
                ("cov", self.config.cov_resend_s, TYPE_COVERAGE),
                ("ortho", self.config.ortho_resend_s, TYPE_ORTHO),
            ):
                due = [
                    (o.changed_at, key)
                    for key, o in self._outbox.items()
                    if key[0] == layer and not o.sent and (self._final or now - o.sent_at >= period)
                ]
                if due:
                    _, key = min(due)
                    o = self._outbox[key]
                    o.sent, o.sent_at = True, now
                    return kind, o.data
        return None

    def finish(self) -> None:
        """The flight is over: every tile not sent yet is due at once (no resend wait)."""
        with self._out_lock:
            self._final = True

    def flush(self, timeout_s: float = 30.0) -> bool:
        """Wait (at most ``timeout_s``) until every tile's newest bytes went out."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.pending_tiles == 0:
                return True
            time.sleep(0.1)
        return self.pending_tiles == 0

    def resend_all(self, held: Callable[[bytes], bool] | None = None) -> None:
        """Every tile is sent again (a ground station asked), but those whose newest bytes
        ``held`` says the station holds already."""
        with self._out_lock:
            for o in self._outbox.values():
                if o.sent and held is not None and held(o.data):
                    continue
                o.sent, o.sent_at = False, -math.inf

    def outbox(self) -> dict[tuple[MapLayer, int, int], bytes]:
        """The newest encoded bytes of every tile (what the ground should end up holding)."""
        with self._out_lock:
            return {k: o.data for k, o in self._outbox.items()}

    @property
    def pending_tiles(self) -> int:
        """Tiles whose newest bytes are not sent yet."""
        with self._out_lock:
            return sum(not o.sent for o in self._outbox.values())
