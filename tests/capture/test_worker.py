"""The detection worker process: same answers as in-process, newest frame first, no blocking."""

from __future__ import annotations

import time

import numpy as np

from holescan.capture import DetectionWorker
from holescan.detect import DEFAULT, CameraIntrinsics, Frame, detect_holes

CAM = CameraIntrinsics.xtion()


def _frame(i: int, hole_u: int) -> Frame:
    depth = np.full((480, 640), 2800, np.uint16)
    depth[200:300, hole_u : hole_u + 150] = 0  # a hole deeper than the range
    rgb = np.full((480, 640, 3), 90, np.uint8)
    return Frame(i, rgb, depth, time.monotonic_ns(), i * 33_333_333)


def test_worker_matches_in_process_detection_and_skips_stale_frames() -> None:
    frames = [_frame(i, 100 + 20 * i) for i in range(12)]
    with DetectionWorker(CAM, DEFAULT) as worker:
        for f in frames:  # offered far faster than detection runs
            worker.offer(f)
        results = worker.drain(timeout=30.0)
        stats = worker.stats()
    # Offering never waits for detection: the skipped frames are the evidence that offers
    # outran it (an offer that waited would let every frame be detected). What an offer
    # costs the capture thread: benchmarks/bench_livemap.py (offer median and p99, us).
    assert stats.offered == 12
    assert stats.done + stats.skipped == 12  # every frame either detected or counted skipped
    assert stats.skipped > 0
    assert results[-1].frame_index == 11  # the newest frame is always processed
    by_index = {f.index: f for f in frames}
    for r in results:
        assert r.error is None
        f = by_index[r.frame_index]
        assert r.t_sensor_ns == f.t_sensor_ns
        expected = detect_holes(f.rgb, f.depth, CAM, DEFAULT)
        assert [d.box for d in r.detections] == [d.box for d in expected]


def test_worker_reports_errors_and_goes_on() -> None:
    bad = Frame(0, np.zeros((480, 640, 3), np.uint8), np.zeros((480, 640), np.uint16), 0, 0)
    with DetectionWorker(CAM, DEFAULT) as worker:
        worker.offer(bad)
        first = worker.drain(timeout=30.0)
        worker.offer(_frame(1, 200))
        second = worker.drain(timeout=30.0)
        assert worker.alive
    # no depth at all (on the ground, under the Xtion's range): reported, not an error
    assert first and first[0].no_depth and first[0].error is None and not first[0].detections
    assert second and second[-1].error is None and second[-1].detections
