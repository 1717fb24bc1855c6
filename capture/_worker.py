"""The detection worker: a separate process fed through shared memory, newest frame first.

Capture must never wait for detection. Frames go into a ring of three shared-memory slots:
one the worker is reading, one published and not yet taken, one free for the next frame.
``offer()`` copies the frame into the free slot (one memcpy, no pickling) and publishes it;
a published frame that the worker had not taken yet is overwritten by a newer one and
counted as skipped. The worker process maps the slots once and reads frames in place.
Results come back on a queue as :class:`WorkerResult`.

The worker is stopped by its parent only: it ignores SIGINT and SIGTERM (Ctrl-C and
``systemctl stop`` reach the whole process group; the daemon then drains and stops it),
and it dies with its parent: ``PR_SET_PDEATHSIG`` (SIGKILL) on Linux, and a check of the
parent's pid every 0.1 s as a fallback, so a killed daemon leaves no orphan (the
multiprocessing resource tracker exits once the worker has gone).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import multiprocessing as mp
import os
import queue
import signal
import sys
import time
from dataclasses import dataclass
from multiprocessing import resource_tracker, shared_memory
from multiprocessing.synchronize import Event as EventT
from types import TracebackType
from typing import Any, cast

import numpy as np

from holescan.capture.errors import CaptureError
from holescan.detect import CameraIntrinsics, Detection, DetectParams, Frame

log = logging.getLogger(__name__)

N_SLOTS = 3
# The detection process runs at this lower priority than capture and logging.
WORKER_NICE = 10
# Control words in the shared int64 array.
_BUSY, _LATEST, _OFFERED, _SKIPPED, _DONE = range(5)
_META = 4  # per slot: frame index, t_mono_ns, t_sensor_ns, sequence
_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}
_PR_SET_PDEATHSIG = 1


@dataclass(frozen=True)
class WorkerResult:
    """Detections of one frame. ``detect_ms`` is the worker's time on it."""

    frame_index: int
    t_mono_ns: int
    t_sensor_ns: int
    detections: tuple[Detection, ...]
    detect_ms: float
    error: str | None = None
    no_depth: bool = False  # no depth reading at all (too close, nothing ranged): no error


@dataclass(frozen=True)
class WorkerStats:
    offered: int
    skipped: int
    done: int


def _slot_views(
    buf: memoryview, h: int, w: int
) -> list[tuple[np.ndarray[Any, Any], np.ndarray[Any, Any]]]:
    size = h * w * 5
    out = []
    for i in range(N_SLOTS):
        rgb = np.ndarray((h, w, 3), np.uint8, buf, i * size)
        depth = np.ndarray((h, w), np.uint16, buf, i * size + h * w * 3)
        out.append((rgb, depth))
    return out


def _ignore_stop_signals() -> None:
    """SIGINT/SIGTERM are for the parent, which stops the worker (blocked since the spawn)."""
    for sig in _STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def die_with_parent(parent_pid: int) -> None:
    """Have the kernel SIGKILL this process when its parent dies (Linux ``prctl``); exit now
    if the parent is already gone."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent_pid:
        os._exit(1)


def _worker_main(
    parent_pid: int,
    shm_name: str,
    ctrl: Any,
    meta: Any,
    wake: EventT,
    stop: EventT,
    ready: EventT,
    results: mp.Queue[WorkerResult | None],
    camera: CameraIntrinsics,
    params: DetectParams,
) -> None:
    _ignore_stop_signals()
    die_with_parent(parent_pid)

    from holescan.detect import detect_holes
    from holescan.errors import NoDepthError

    # Logging must win the CPU: detection may skip frames, the log may not drop them
    # (5-minute benchmark: 707 of 8,873 frames dropped from the log at equal priority,
    # none at nice 10).
    if hasattr(os, "nice"):
        os.nice(WORKER_NICE)

    shm = shared_memory.SharedMemory(name=shm_name)
    try:
        views = _slot_views(cast(memoryview, shm.buf), camera.height, camera.width)
        ready.set()
        while not stop.is_set():
            if not wake.wait(0.1):
                if os.getppid() != parent_pid:  # the daemon died (no prctl): exit too
                    results.cancel_join_thread()
                    return
                continue
            with ctrl.get_lock():
                slot = int(ctrl[_LATEST])
                wake.clear()
                if slot < 0:
                    continue
                ctrl[_BUSY], ctrl[_LATEST] = slot, -1
                index, t_mono, t_sensor = (int(v) for v in meta[slot * _META : slot * _META + 3])
            rgb, depth = views[slot]
            t0 = time.perf_counter()
            try:
                dets = tuple(detect_holes(rgb, depth, camera, params))
                err, no_depth = None, False
            except NoDepthError:  # on the ground, under the sensor's range: counted, not an error
                dets, err, no_depth = (), None, True
            except Exception as exc:  # reported to the daemon, which logs it; worker goes on
                dets, err, no_depth = (), f"{type(exc).__name__}: {exc}", False
            ms = (time.perf_counter() - t0) * 1000.0
            with ctrl.get_lock():
                ctrl[_BUSY] = -1
                ctrl[_DONE] += 1
            results.put(WorkerResult(index, t_mono, t_sensor, dets, ms, err, no_depth))
    finally:
        del views
        shm.close()
        results.put(None)


class DetectionWorker:
    """Run :func:`detect.detect_holes` in a child process on the newest offered frame.

    Use as a context manager. ``offer(frame)`` never blocks on detection; ``results()``
    drains what the worker finished.
    """

    def __init__(self, camera: CameraIntrinsics, params: DetectParams) -> None:
        self.camera = camera
        self.params = params
        ctx = mp.get_context("spawn")
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
        try:  # the tracker of the shared memory, started here, ignores them too
            resource_tracker.ensure_running()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        size = camera.height * camera.width * 5
        self._shm = shared_memory.SharedMemory(create=True, size=size * N_SLOTS)
        self._views = _slot_views(cast(memoryview, self._shm.buf), camera.height, camera.width)
        self._ctrl = ctx.Array("q", [-1, -1, 0, 0, 0])
        self._meta = ctx.Array("q", [0] * (_META * N_SLOTS), lock=False)
        self._wake = ctx.Event()
        self._stop = ctx.Event()
        self._ready = ctx.Event()
        self._results: mp.Queue[WorkerResult | None] = ctx.Queue()
        self._proc = ctx.Process(
            target=_worker_main,
            args=(
                os.getpid(),
                self._shm.name,
                self._ctrl,
                self._meta,
                self._wake,
                self._stop,
                self._ready,
                self._results,
                camera,
                params,
            ),
            name="holescan-detect",
            daemon=True,
        )
        self._seq = 0
        self._received = 0  # results taken off the queue (drain waits for all done)
        self._started = False

    def __enter__(self) -> DetectionWorker:
        self.start()
        return self

    def start(self, timeout_s: float = 60.0) -> None:
        """Start the process and wait until it has imported the detector (startup only)."""
        # The child inherits the blocked mask through the exec: a Ctrl-C during its
        # start-up stays pending until it ignores the signal (no KeyboardInterrupt trace).
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
        try:
            self._proc.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        self._started = True
        if not self._ready.wait(timeout_s):
            self.close()
            raise CaptureError(f"detection worker did not start within {timeout_s:.0f} s")

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def offer(self, frame: Frame) -> None:
        """Hand ``frame`` to the worker; returns at once (one copy into shared memory)."""
        if frame.depth.shape != (self.camera.height, self.camera.width):
            raise CaptureError(
                f"frame is {frame.depth.shape[::-1]}, worker expects "
                f"{self.camera.width}x{self.camera.height}"
            )
        with self._ctrl.get_lock():
            taken = {int(self._ctrl[_BUSY]), int(self._ctrl[_LATEST])}
        slot = next(i for i in range(N_SLOTS) if i not in taken)
        rgb, depth = self._views[slot]
        np.copyto(rgb, frame.rgb)
        np.copyto(depth, frame.depth)
        self._meta[slot * _META : slot * _META + 4] = [
            frame.index,
            frame.t_mono_ns,
            frame.t_sensor_ns,
            self._seq,
        ]
        self._seq += 1
        with self._ctrl.get_lock():
            if self._ctrl[_LATEST] >= 0:
                self._ctrl[_SKIPPED] += 1
            self._ctrl[_LATEST] = slot
            self._ctrl[_OFFERED] += 1
        self._wake.set()

    def results(self, timeout: float = 0.0) -> list[WorkerResult]:
        """Everything finished so far (waits up to ``timeout`` s for the first one)."""
        out: list[WorkerResult] = []
        try:
            item = self._results.get(timeout=timeout) if timeout > 0 else self._results.get_nowait()
            while item is not None:
                out.append(item)
                item = self._results.get_nowait()
        except queue.Empty:
            pass
        self._received += len(out)
        return out

    def stats(self) -> WorkerStats:
        lock = self._ctrl.get_lock()
        locked = lock.acquire(timeout=1.0)  # never hang on a lock a killed worker held
        try:
            return WorkerStats(
                int(self._ctrl[_OFFERED]), int(self._ctrl[_SKIPPED]), int(self._ctrl[_DONE])
            )
        finally:
            if locked:
                lock.release()

    @property
    def alive(self) -> bool:
        return self._proc.is_alive()

    def drain(self, timeout: float) -> list[WorkerResult]:
        """Wait until the published frame (if any) is processed, then return all results."""
        deadline = time.monotonic() + timeout
        out: list[WorkerResult] = []
        while time.monotonic() < deadline and self._proc.is_alive():
            out += self.results(timeout=0.05)
            with self._ctrl.get_lock():
                idle = self._ctrl[_LATEST] < 0 and self._ctrl[_BUSY] < 0
                done = int(self._ctrl[_DONE])
            # A result is queued after its frame counts as done: idle is not enough.
            if idle and self._received >= done:
                break
        return out + self.results()

    def close(self) -> None:
        """Stop the worker process and free the shared memory."""
        t0 = time.monotonic()
        if self._started:
            self._stop.set()
            self._wake.set()
            self._proc.join(timeout=1.0)
            if self._proc.is_alive():  # inside a detection: its result is not wanted now
                log.info("detection worker busy; killing it")
                self._proc.kill()  # (it ignores SIGTERM)
                self._proc.join(timeout=2.0)
            self._started = False
            log.debug("detection worker stopped in %.2f s", time.monotonic() - t0)
        self._views = []
        try:
            self._shm.close()
            self._shm.unlink()
        except FileNotFoundError:
            pass
