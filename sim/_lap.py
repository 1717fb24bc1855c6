"""Pre-rendered laps: a survey lap rendered once (in parallel) to an ``.oni`` file and
replayed through libOpenNI2 at the camera rate, for benchmarks that need 30 fps."""

from __future__ import annotations

import concurrent.futures
import logging
import math
import multiprocessing as mp
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from holescan.capture import OniSource, OniWriter, openni2_library
from holescan.detect import CameraIntrinsics, Frame
from holescan.geotag import CameraMount
from holescan.sim._autopilot import SimAutopilot
from holescan.sim._camera_model import Conditions, random_conditions
from holescan.sim._render import render
from holescan.sim._sortie import SortieParams, lap_frames, make_sortie_world
from holescan.sim._source import camera_pose_in_world
from holescan.sim._trajectory import SimPath
from holescan.sim._world import RubbleWorld

_log = logging.getLogger(__name__)

__all__ = ["LapReplay", "prerender_lap"]

# -- pre-rendered laps ------------------------------------------------------------------------


@dataclass(frozen=True)
class _LapJob:
    params: SortieParams
    path: SimPath
    camera: CameraIntrinsics
    mount: CameraMount
    n_frames: int


_JOB: _LapJob | None = None
_WORLD: RubbleWorld | None = None
_AUTOPILOT: SimAutopilot | None = None


def _lap_init(job: _LapJob) -> None:
    global _JOB, _WORLD, _AUTOPILOT
    _JOB = job
    _WORLD = make_sortie_world(job.params)
    # Never entered: no link, used for its deterministic truth only.
    _AUTOPILOT = SimAutopilot(
        "udpout:127.0.0.1:9", job.path, uptime_at_start_s=job.params.clock_offset_s
    )


def _render_lap_frame(k: int) -> tuple[int, np.ndarray, np.ndarray, float]:
    assert _JOB is not None and _WORLD is not None and _AUTOPILOT is not None
    job = _JOB
    t0 = time.perf_counter()
    t_boot = round(job.params.clock_offset_s * 1e9) + round(k * 1e9 / job.params.fps)
    pose = _AUTOPILOT.truth_pose(t_boot)
    cam_pose = camera_pose_in_world(pose, job.mount, job.params.anchor)
    rng = np.random.default_rng((job.params.noise_seed, k))
    cond = random_conditions(rng, Conditions())
    rgb, depth, _ = render(_WORLD, cam_pose, job.camera, rng, cond)
    return k, rgb, depth, (time.perf_counter() - t0) * 1000.0


def prerender_lap(
    params: SortieParams,
    path: SimPath,
    out: Path,
    *,
    camera: CameraIntrinsics | None = None,
    mount: CameraMount | None = None,
    workers: int = 2,
) -> tuple[int, list[float]]:
    """Render one lap of ``path`` (see :func:`lap_frames`) into the ``.oni`` file ``out``.

    Frame ``k`` is rendered from the autopilot's true pose ``k / fps`` seconds into its loop;
    its sensor timestamp is ``k / fps``. Rendering runs in ``workers`` processes.

    Returns
    -------
    n_frames : frames written (one lap).
    render_ms : per-frame render time, ms (in the worker processes).
    """
    cam = camera or CameraIntrinsics.xtion()
    path, n = lap_frames(path, params.fps)
    job = _LapJob(params, path, cam, mount or CameraMount(), n)
    period_ns = 1e9 / params.fps
    render_ms: list[float] = []
    ctx = mp.get_context("spawn")
    with (
        OniWriter(out, cam, fps=round(params.fps)) as writer,
        concurrent.futures.ProcessPoolExecutor(
            max_workers=workers, mp_context=ctx, initializer=_lap_init, initargs=(job,)
        ) as pool,
    ):
        for k, rgb, depth, ms in pool.map(_render_lap_frame, range(n), chunksize=8):
            writer.write(Frame(k, rgb, depth, 0, round(k * period_ns)))
            render_ms.append(ms)
            if k % 500 == 0:
                _log.info("pre-rendered %d of %d frames", k, n)
    return n, render_ms


class LapReplay:
    """Play a pre-rendered lap (``.oni``) lap after lap, in step with the autopilot.

    Frame ``k`` of lap ``m`` is delivered when the autopilot's boot clock reaches
    ``loop_origin + (m * N + k) / fps`` (the instant the vehicle is where it was rendered
    from), stamped with that monotonic time. Frames are never skipped once delivery started;
    when the reader falls behind, frames come late (:attr:`late_frames`, :attr:`max_late_ms`)
    but keep their true time. At open, the frames of the lap already past are read through
    and not delivered (:attr:`startup_skipped`): the camera was not on yet.

    Parameters
    ----------
    path : the ``.oni`` lap from :func:`prerender_lap`.
    autopilot : the running simulator, flying the :func:`lap_frames` path.
    fps : the lap's frame rate.
    loop_origin_boot_ns : the autopilot's boot time at the start of its loop (its
        ``uptime_at_start_s`` in ns).
    """

    def __init__(
        self, path: Path, autopilot: SimAutopilot, fps: float, loop_origin_boot_ns: int
    ) -> None:
        self.path = Path(path)
        self._ap = autopilot
        self.fps = fps
        self._origin = loop_origin_boot_ns
        # Initialise OpenNI2 on this (long-lived) thread: the players are opened on the
        # daemon's frame-pump thread, and a library initialised on a thread that has exited
        # crashes in oniShutdown at interpreter exit (measured: segfault 1 of 1 without).
        openni2_library()
        probe = OniSource(self.path)
        self.camera = probe.camera
        self.n_frames = probe.info.stream("depth").frames_found
        # The autopilot's boot clock is linear in the monotonic clock: boot = b0 + rate * mono.
        self._b0 = autopilot.boot_ns_at_mono(0)
        self._rate = (autopilot.boot_ns_at_mono(10**12) - self._b0) / 1e12
        self._closed = False
        self.late_frames = 0
        self.max_late_ms = 0.0
        self.startup_skipped = 0
        self.laps = 0
        self.numbers: list[int] = []  # per delivered frame: its frame number since tau = 0
        self._lock = threading.Lock()  # the player is read or closed, never both at once
        self._player: OniSource | None = None
        self._frames: Iterator[Frame] | None = None

    def truth_boot_ns(self, index: int) -> int:
        """The autopilot boot time whose true pose delivered frame ``index`` shows."""
        return self._origin + round(self.numbers[index] * 1e9 / self.fps)

    def __enter__(self) -> LapReplay:
        self._closed = False
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop, and close the playback now (from any thread, never while a frame is read)."""
        self._closed = True
        with self._lock:
            self._close_player()

    def _close_player(self) -> None:
        if self._frames is not None:
            close = getattr(self._frames, "close", None)
            if close is not None:
                close()  # ends OniSource's generator before its device closes
            self._frames = None
        if self._player is not None:
            self._player.close()
            self._player = None

    def due_mono_ns(self, number: int) -> int:
        """Monotonic time when the autopilot's clock reads ``loop_origin + number / fps``."""
        t_boot = self._origin + round(number * 1e9 / self.fps)
        return round((t_boot - self._b0) / self._rate)

    def _next_frame(self, lap: int) -> tuple[int, Frame | None]:
        """The next frame of the lap (opening the file as needed), under the lock."""
        with self._lock:
            if self._closed:
                return lap, None
            if self._frames is None:
                self._player = OniSource(self.path)
                self._player.open()
                self._frames = iter(self._player)
            frame = next(self._frames, None)
            if frame is None:  # end of the lap
                self._close_player()
                self.laps += 1
                return lap + 1, None
            return lap, frame

    def __iter__(self) -> Iterator[Frame]:
        n = self.n_frames
        period_ns = 1e9 / self.fps
        now_boot = self._ap.boot_ns_at_mono(time.monotonic_ns())
        lap, k0 = divmod(max(0, math.ceil((now_boot - self._origin) / period_ns)), n)
        index = 0
        k = 0
        started = False
        try:
            while not self._closed:
                next_lap, frame = self._next_frame(lap)
                if frame is None:
                    lap, k, k0 = next_lap, 0, 0
                    continue
                number = lap * n + k
                k += 1
                due = self.due_mono_ns(number)
                if not started:
                    if k - 1 < k0 or due < time.monotonic_ns() - period_ns:
                        self.startup_skipped += 1
                        continue
                    started = True
                now = time.monotonic_ns()
                if now < due:
                    time.sleep((due - now) / 1e9)
                else:
                    late_ms = (now - due) / 1e6
                    self.max_late_ms = max(self.max_late_ms, late_ms)
                    if late_ms * 1e6 > period_ns:
                        self.late_frames += 1
                self.numbers.append(number)
                yield replace(
                    frame, index=index, t_mono_ns=due, t_sensor_ns=round(number * period_ns)
                )
                index += 1
        finally:
            with self._lock:
                self._close_player()
