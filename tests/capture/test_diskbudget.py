"""The disk budget before take-off, the image reserve in flight, and the retention rule,
each on a small fake disk (a :class:`DiskSpace` whose capacity is a few MB and whose used
bytes are the real files in the log folder)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from holescan.capture import (
    DiskBudgetError,
    disk_budget,
    expected_bytes_per_s,
    parse_fly_config,
    preflight_disk_budget,
)
from holescan.detect import CameraIntrinsics, Frame
from holescan.flightlog import (
    DiskSpace,
    FlightLogWriter,
    LoggedDetections,
    LoggedFrame,
    LoggedHealth,
    LoggedHoles,
    LoggedPose,
    LogOptions,
    flight_logs,
    log_info,
    measured_rate,
    read_flight_log,
    remove_oldest_finished,
)
from holescan.geotag import VehiclePose

REPO = Path(__file__).resolve().parents[2]
SMALL = CameraIntrinsics(80, 60, 71.3, 71.3, 39.5, 29.5)
MB = 1_000_000


class FolderDisk:
    """A disk of ``capacity`` bytes holding only the files in the folders asked about."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.asked = 0

    def free_bytes(self, folder: str | os.PathLike[str]) -> int:
        self.asked += 1
        used = sum(p.stat().st_size for p in Path(folder).iterdir() if p.is_file())
        return max(self.capacity - used, 0)


class FixedDisk:
    """A disk whose free space the test sets."""

    def __init__(self, free: int) -> None:
        self.free = free

    def free_bytes(self, folder: str | os.PathLike[str]) -> int:
        return self.free


def frame(i: int) -> Frame:
    rng = np.random.default_rng(i)
    depth = rng.integers(1000, 3000, (SMALL.height, SMALL.width)).astype(np.uint16)
    rgb = rng.integers(0, 256, (SMALL.height, SMALL.width, 3), dtype=np.uint8)
    return Frame(i, rgb, depth, i * 33_333_333, i * 33_333_333)


def pose(i: int) -> VehiclePose:
    return VehiclePose(
        t_boot_ns=10**9 + i * 10**8,
        lat_deg=43.6532 + i * 1e-6,
        lon_deg=-79.3832,
        alt_m=120.0,
        rel_alt_m=3.0,
        roll=0.0,
        pitch=0.0,
        yaw=0.1,
    )


def config(log_dir: Path, **disk: Any) -> Any:
    return parse_fly_config({"log_dir": str(log_dir), "disk": disk})


def test_the_fake_disks_are_disk_spaces() -> None:
    assert isinstance(FolderDisk(1), DiskSpace) and isinstance(FixedDisk(1), DiskSpace)


def test_budget_says_how_long_the_disk_lasts_and_whether_the_plan_fits(tmp_path: Path) -> None:
    rate = 5 * MB
    cfg = config(tmp_path, expected_bytes_per_s=rate, planned_flight_s=1800.0)
    reserve = cfg.flight.log_options.image_reserve_bytes
    roomy = disk_budget(cfg, reserve + 10_000 * MB)
    assert roomy.rate_source == "configured"
    assert roomy.usable_bytes == 10_000 * MB
    assert roomy.lasts_s == pytest.approx(2000.0)
    assert roomy.needed_bytes == 9_000 * MB
    assert roomy.fits is True
    assert "lasts 33 min" in roomy.describe() and ": fits" in roomy.describe()
    tight = disk_budget(cfg, reserve + 8_000 * MB)
    assert tight.fits is False and "does NOT fit" in tight.describe()
    # --duration is the plan when given; with no plan at all there is no verdict
    short = disk_budget(parse_fly_config({**_doc(tmp_path, rate), "duration_s": 60.0}), reserve)
    assert short.planned_s == 60.0 and short.fits is False  # nothing usable above the reserve
    unplanned = disk_budget(config(tmp_path, expected_bytes_per_s=rate), 10**12)
    assert unplanned.fits is None and "planned" not in unplanned.describe()


def _doc(log_dir: Path, rate: float) -> dict[str, Any]:
    return {"log_dir": str(log_dir), "disk": {"expected_bytes_per_s": rate}}


def test_the_expected_rate_of_the_default_images_is_within_the_goal() -> None:
    # 30 fps VGA: JPEG q90 colour + zstd depth, telemetry included (docs/flight-log.md)
    jpeg = expected_bytes_per_s(LogOptions())
    raw = expected_bytes_per_s(LogOptions(color="raw", depth="raw"))
    assert jpeg < 6 * MB < 18e9 / 1800  # a 30-minute flight in 18 GB, with room
    assert raw > 4 * jpeg
    assert expected_bytes_per_s(LogOptions(jpeg_quality=75)) < jpeg


def test_preflight_refuses_or_warns_as_configured(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    disk = FixedDisk(2 * 1024**3)  # 2 GiB, 1 GiB of it the reserve
    refuse = config(tmp_path, expected_bytes_per_s=1 * MB, planned_flight_s=1800.0)
    with pytest.raises(DiskBudgetError, match="does NOT fit"):
        preflight_disk_budget(refuse, disk)
    warn = config(tmp_path, expected_bytes_per_s=1 * MB, planned_flight_s=1800.0, when_short="warn")
    budget = preflight_disk_budget(warn, disk)
    assert budget.fits is False
    assert "does NOT fit" in caplog.text
    ok = config(tmp_path, expected_bytes_per_s=1 * MB, planned_flight_s=600.0)
    assert preflight_disk_budget(ok, disk).fits is True


def test_fly_refuses_a_flight_that_does_not_fit_in_one_line(tmp_path: Path) -> None:
    cfg = tmp_path / "fly.toml"
    cfg.write_text("[disk]\nexpected_bytes_per_s = 1e15\n")
    logs = tmp_path / "logs"
    done = subprocess.run(
        [sys.executable, "-m", "holescan.cli", "fly", "--sensor", "sim", "--log-dir", str(logs),
         "--config", str(cfg), "--duration", "1800"],
        capture_output=True, text=True, timeout=120, cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    assert done.returncode != 0
    errors = [ln for ln in done.stderr.splitlines() if "error" in ln]
    assert len(errors) == 1 and "does NOT fit" in errors[0], done.stderr
    assert "Traceback" not in done.stderr
    assert not list(logs.glob("*.mcap"))  # refused before anything was written


def _write_log(prefix: Path, n: int, options: LogOptions | None = None) -> list[Path]:
    with FlightLogWriter(prefix, SMALL, options=options) as w:
        for i in range(n):
            assert w.write_frame(frame(i), time.time_ns())
    return list(w.paths)


def test_the_rate_is_measured_on_the_last_finished_log_of_the_same_images(
    tmp_path: Path,
) -> None:
    raw = LogOptions(color="raw", depth="raw")
    config_of = {"log.color": '"raw"', "log.depth": '"raw"'}
    with FlightLogWriter(tmp_path / "flight-a", SMALL, options=raw, config=_flat(raw)) as w:
        for i in range(4):
            w.write_frame(frame(i), time.time_ns())
            time.sleep(0.1)
    found = measured_rate(tmp_path, config_of, min_span_s=0.2)
    assert found is not None
    rate, log_set = found
    span_s = 0.3  # four frames 0.1 s apart, at least
    assert log_set.prefix == tmp_path / "flight-a"
    assert 0 < rate <= log_set.bytes / span_s
    # other image settings: not this log's rate
    assert measured_rate(tmp_path, {"log.color": '"jpeg"'}, min_span_s=0.2) is None
    assert measured_rate(tmp_path, config_of, min_span_s=60.0) is None  # too short to tell


def _flat(options: LogOptions) -> dict[str, Any]:
    return {"log.color": options.color, "log.depth": options.depth}


def test_near_full_stops_frames_and_keeps_everything_else(tmp_path: Path) -> None:
    disk = FixedDisk(10 * MB)
    options = LogOptions(image_reserve_bytes=5 * MB, sync_interval_s=0.05)
    with FlightLogWriter(tmp_path / "full", SMALL, options=options, disk=disk) as w:
        for i in range(5):
            assert w.write_frame(frame(i), time.time_ns())
            assert w.write_pose(pose(i), time.time_ns())
        deadline = time.monotonic() + 30  # written first (the reserve is read before each)
        while w.stats().written.get("frames", 0) < 5 and time.monotonic() < deadline:
            time.sleep(0.01)
        disk.free = 4 * MB  # under the reserve from now on
        deadline = time.monotonic() + 10
        while w.stats().images_stopped_t_unix_ns is None and time.monotonic() < deadline:
            time.sleep(0.01)
        stopped = w.stats().images_stopped_t_unix_ns
        assert stopped is not None
        for i in range(5, 10):
            assert w.write_frame(frame(i), time.time_ns())  # not logged, not a drop
            assert w.write_pose(pose(i), time.time_ns())
        assert w.write_detections(7, [], time.time_ns())
        assert w.write_holes([], time.time_ns())
    st = w.stats()
    assert st.frames_not_logged == 5 and st.written["frames"] == 5
    assert st.dropped == {}
    records = list(read_flight_log(w.paths))
    assert len([r for r in records if isinstance(r, LoggedFrame)]) == 5
    assert len([r for r in records if isinstance(r, LoggedPose)]) == 10
    assert [r.frame_index for r in records if isinstance(r, LoggedDetections)] == [7]
    assert len([r for r in records if isinstance(r, LoggedHoles)]) == 1
    health = [r.values for r in records if isinstance(r, LoggedHealth)]
    (event,) = [h for h in health if h.get("event") == "images_stopped"]
    assert event["images_stopped_t_unix_ns"] == stopped
    assert event["free_bytes"] == 4 * MB and event["reserve_bytes"] == 5 * MB
    assert health[-1]["frames_not_logged"] == 5
    info = log_info(w.paths)
    assert info.frames == 5 and info.dropped_frames == ()  # no gap: nothing was dropped


class FullAfter:
    """A disk that has room for ``calls`` answers, then is under any reserve."""

    def __init__(self, calls: int) -> None:
        self.calls = calls

    def free_bytes(self, folder: str | os.PathLike[str]) -> int:
        self.calls -= 1
        return 10 * MB if self.calls >= 0 else MB


def test_frames_queued_past_the_reserve_are_not_logged(tmp_path: Path) -> None:
    # However far behind capture the writer is, the reserve is read before each frame is
    # written: the writer is asked once when it opens, then once per frame (no periodic
    # sync in this test), so exactly the 3 frames before the disk fell under it are logged.
    options = LogOptions(image_reserve_bytes=5 * MB, sync_interval_s=3600.0)
    with FlightLogWriter(tmp_path / "q", SMALL, options=options, disk=FullAfter(4)) as w:
        for i in range(8):  # all queued at once: the writer thread has not caught up
            assert w.write_frame(frame(i), time.time_ns())
    st = w.stats()
    assert st.written["frames"] == 3 and st.frames_not_logged == 5, st
    assert st.dropped == {} and w.frames_queued == 0
    info = log_info(w.paths)
    assert info.frames == 3 and info.dropped_frames == ()


def test_a_disk_already_under_the_reserve_logs_no_frame(tmp_path: Path) -> None:
    options = LogOptions(image_reserve_bytes=5 * MB)
    with FlightLogWriter(tmp_path / "f", SMALL, options=options, disk=FixedDisk(MB)) as w:
        assert w.write_frame(frame(0), time.time_ns())
        assert w.write_pose(pose(0), time.time_ns())
    assert w.stats().written.get("frames", 0) == 0 and w.stats().frames_not_logged == 1


def test_retention_removes_only_the_oldest_finished_logs(tmp_path: Path) -> None:
    old = [_write_log(tmp_path / f"flight-{k}", 6) for k in range(3)]
    now = time.time()
    for k, files in enumerate(old):  # flight-0 is the oldest
        for f in files:
            os.utime(f, (now - 3000 + k * 100, now - 3000 + k * 100))
    # an unfinished log (cut off by a crash), older than all, and a .part
    cut = _write_log(tmp_path / "flight-crashed", 6)[0]
    cut.write_bytes(cut.read_bytes()[:-100])
    os.utime(cut, (now - 9000, now - 9000))
    (tmp_path / "flight-x_0000.mcap.part").write_bytes(b"partial")
    sets = {s.prefix.name: s for s in flight_logs(tmp_path)}
    assert sets["flight-crashed"].finished is False
    assert all(sets[f"flight-{k}"].finished for k in range(3))
    size = sets["flight-0"].bytes

    used = sum(p.stat().st_size for p in tmp_path.iterdir())
    disk = FolderDisk(used + size // 2)  # half a log free
    removed = remove_oldest_finished(tmp_path, size, disk, keep=[tmp_path / "flight-1"])
    assert [s.prefix.name for s in removed] == ["flight-0"]  # one was enough
    removed = remove_oldest_finished(tmp_path, 10 * size, disk, keep=[tmp_path / "flight-1"])
    assert [s.prefix.name for s in removed] == ["flight-2"]  # flight-1 kept; then none left
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ["flight-1_0000.mcap", "flight-crashed_0000.mcap", "flight-x_0000.mcap.part"]


def test_preflight_removes_old_logs_only_when_configured(tmp_path: Path) -> None:
    files = [_write_log(tmp_path / f"flight-{k}", 6) for k in range(2)]
    size = sum(f.stat().st_size for f in files[0])
    used = sum(p.stat().st_size for p in tmp_path.iterdir())
    reserve = 1000
    rate = 1000.0
    planned = (size + 500) / rate  # fits once one old log is gone, not before
    doc = {
        "expected_bytes_per_s": rate,
        "planned_flight_s": planned,
        "image_reserve_bytes": reserve,
    }
    disk = FolderDisk(used + reserve + 600)
    with pytest.raises(DiskBudgetError):
        preflight_disk_budget(config(tmp_path, **doc), disk)
    assert len(flight_logs(tmp_path)) == 2  # nothing removed unless configured
    budget = preflight_disk_budget(config(tmp_path, **doc, remove_oldest_finished=True), disk)
    assert budget.fits is True
    assert [s.prefix.name for s in flight_logs(tmp_path)] == ["flight-1"]
