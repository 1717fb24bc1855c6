"""The flight's sensor retry on its own: back-off, USB reset, reopen, and the source closed."""

from __future__ import annotations

import contextlib
import threading

from holescan.capture import SensorError
from holescan.capture._health import SensorFailed
from holescan.capture._sensorloop import SensorRetry
from tests.capture.test_daemon import ScriptedSource


def test_failures_back_off_reset_reopen_then_frames_to_the_end() -> None:
    opened: list[ScriptedSource] = []
    failures: list[SensorFailed] = []
    resets: list[int] = []
    reopens: list[int] = []

    def factory() -> ScriptedSource:
        if len(failures) < 3:  # not plugged in yet: three failed opens
            raise SensorError("no Xtion found on USB")
        if len(opened) == 0:  # then one that fails mid-stream
            opened.append(ScriptedSource(5, fps=1000.0, fail_at=2))
        else:
            opened.append(ScriptedSource(4, fps=1000.0))
        return opened[-1]

    retry = SensorRetry(
        factory,
        frame_timeout_s=30.0,
        backoff_s=(0.0, 0.01, 0.02),
        usb_reset=lambda: resets.append(1),
        on_failure=failures.append,
        on_reopen=lambda: reopens.append(1),
    )
    stop = threading.Event()
    with contextlib.closing(retry.frames(stop)) as frames:
        indices = [f.index for f in frames]
    assert indices == [0, 1, 0, 1, 2, 3]  # two frames, the fault, then the whole source
    assert not stop.is_set()  # ended by the source, not a stop
    # back-off grows with each failure in a row; a frame read resets it
    assert [f.retry_in_s for f in failures] == [0.0, 0.01, 0.02, 0.0]
    assert "USB transfer failed" in failures[-1].error
    assert len(resets) == len(reopens) == len(failures) == 4
    assert all(s.closed for s in opened)


def test_closing_the_iterator_closes_the_open_source() -> None:
    source = ScriptedSource(100, fps=1000.0)
    retry = SensorRetry(lambda: source, frame_timeout_s=30.0, backoff_s=(0.0,))
    with contextlib.closing(retry.frames(threading.Event())) as frames:
        assert next(frames).index == 0
    assert source.closed


def test_a_stop_during_the_back_off_ends_without_another_attempt() -> None:
    stop = threading.Event()
    attempts: list[int] = []

    def factory() -> ScriptedSource:
        attempts.append(1)
        raise SensorError("no Xtion found on USB")

    retry = SensorRetry(
        factory, frame_timeout_s=30.0, backoff_s=(3600.0,), on_failure=lambda _: stop.set()
    )
    assert list(retry.frames(stop)) == []
    assert attempts == [1]
