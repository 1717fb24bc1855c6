"""The flight's sensor: read through a pump with a timeout, and on a failure closed, reset on
USB when it can be, and reopened with back-off (:class:`SensorRetry`).

:func:`frames_with_timeout` turns a sensor that raises or goes silent into a
:class:`SensorError`; :func:`close_quietly` closes one that may hang. The pre-flight check
reads its one frame through the same pump.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable, Generator, Iterator
from typing import Any

from holescan.capture._health import SensorFailed
from holescan.capture.errors import SensorError
from holescan.detect import Frame, FrameSource

__all__ = ["SensorRetry", "close_quietly", "frames_with_timeout"]

log = logging.getLogger(__name__)


class SensorRetry:
    """Frames from a sensor that may fail, across as many reopens as it takes.

    Parameters
    ----------
    factory : makes a fresh (unopened) :class:`detect.FrameSource` for each attempt.
    frame_timeout_s : no frame for this long = the sensor stalled (a failure).
    backoff_s : waits before each reopen after consecutive failures (the last one repeats;
        a frame read resets the count).
    usb_reset : called after each failure (e.g. reset the Xtion on USB); a
        :class:`SensorError` from it is logged and the reopen goes on.
    on_failure : told of each failure (the daemon counts it and logs it on ``/health``),
        before the reset and the wait.
    on_reopen : told after each wait, as the sensor is opened again.
    """

    def __init__(
        self,
        factory: Callable[[], FrameSource],
        *,
        frame_timeout_s: float,
        backoff_s: tuple[float, ...],
        usb_reset: Callable[[], None] | None = None,
        on_failure: Callable[[SensorFailed], None] | None = None,
        on_reopen: Callable[[], None] | None = None,
    ) -> None:
        if not backoff_s:
            raise ValueError("backoff_s needs at least one wait, e.g. (0.5, 1.0, 2.0)")
        self._factory = factory
        self.frame_timeout_s = frame_timeout_s
        self.backoff_s = backoff_s
        self._usb_reset = usb_reset
        self._on_failure = on_failure
        self._on_reopen = on_reopen

    def frames(self, stop: threading.Event) -> Generator[Frame, None, None]:
        """Every frame of the sensor until ``stop`` is set or the source ends by itself
        (a recording's end: then ``stop`` is left unset). Use it in
        ``contextlib.closing(...)``: closing the iterator closes the open source."""
        attempt = 0
        while not stop.is_set():
            try:
                source = self._factory()
                source.__enter__()
            except SensorError as err:
                self._failed(err, attempt, stop)
                attempt += 1
                continue
            try:
                for frame in frames_with_timeout(source, self.frame_timeout_s, stop):
                    attempt = 0
                    yield frame
                close_quietly(source)
                return  # the source ended, or a stop
            except SensorError as err:
                close_quietly(source)
                self._failed(err, attempt, stop)
                attempt += 1
            except BaseException:  # also GeneratorExit: the caller closed the iterator
                close_quietly(source)
                raise

    def _failed(self, err: SensorError, attempt: int, stop: threading.Event) -> None:
        wait = self.backoff_s[min(attempt, len(self.backoff_s) - 1)]
        log.warning("sensor failure (%s); reopening in %.1f s", err, wait)
        if self._on_failure is not None:
            self._on_failure(SensorFailed(str(err), wait))
        if self._usb_reset is not None:
            try:
                self._usb_reset()
            except SensorError as reset_err:
                log.warning("USB reset failed: %s", reset_err)
        stop.wait(wait)
        if self._on_reopen is not None:
            self._on_reopen()


_END = object()


def frames_with_timeout(
    source: FrameSource, timeout_s: float, stop: threading.Event
) -> Iterator[Frame]:
    """Iterate ``source`` in a pump thread; raise :class:`SensorError` on a stall or fault."""
    q: queue.Queue[Any] = queue.Queue(maxsize=8)

    def pump() -> None:
        try:
            for frame in source:
                while not stop.is_set():
                    try:
                        q.put(frame, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            q.put(_END)
        except BaseException as exc:  # handed to the capture thread, which decides
            q.put(exc)

    threading.Thread(target=pump, name="frame-pump", daemon=True).start()
    last = time.monotonic()
    while not stop.is_set():
        try:
            item = q.get(timeout=0.1)
        except queue.Empty:
            if time.monotonic() - last > timeout_s:
                raise SensorError(f"no frame from the sensor for {timeout_s:.1f} s") from None
            continue
        last = time.monotonic()
        if item is _END:
            return
        if isinstance(item, SensorError):
            raise item
        if isinstance(item, Exception) and not isinstance(item, ValueError):
            raise SensorError(f"sensor failed: {type(item).__name__}: {item}") from item
        if isinstance(item, BaseException):
            raise item
        yield item


def close_quietly(source: FrameSource, timeout_s: float = 3.0) -> None:
    """Close a (possibly hung) source without letting it hang the flight."""

    def close() -> None:
        try:
            source.__exit__(None, None, None)
        except Exception as err:
            log.warning("closing the sensor failed: %s", err)

    t = threading.Thread(target=close, name="sensor-close", daemon=True)
    t.start()
    t.join(timeout_s)
    if t.is_alive():
        log.warning("sensor did not close in %.0f s; abandoning it", timeout_s)
