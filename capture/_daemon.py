"""The capture daemon: frames -> flight log and detection worker -> geotags -> ground crew.

Threads and processes of one flight:

- **capture** (the caller's thread): reads frames from the source through a pump thread
  with a timeout, stamps each on the autopilot's clock, queues it to the log writer and
  offers it to the detection worker. Neither ever makes it wait.
- **log writer** thread (:class:`flightlog.FlightLogWriter`); **detection worker**
  process (:class:`capture._worker.DetectionWorker`); **telemetry** receiver thread
  (:class:`capture._mavlink.Telemetry`): each message logged raw, each position also as a pose.
- **results** thread: logs detections, poses the frame they came from (interpolated, once
  the telemetry after it has arrived), geotags, merges sightings into holes, logs the holes,
  serves them to the ground station and announces them; writes ``/health`` every second.

A sensor that fails (raises, or nothing for ``frame_timeout_s``) is closed, reset on USB
when it can be, and reopened with back-off; telemetry and logging go on. Frames that cannot
be posed (MAVLink silent, clock not synchronised, or a position the autopilot does not have:
no 3-D fix, EKF without horizontal position, lat = lon = 0, a jump) are logged, marked
unposed, detected and counted, never placed, so nothing is announced from them (a pose not
there *yet* is waited for, ``pose_wait_s``). Frames without depth are counted apart.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

from holescan.capture._flightrecords import (
    FlightConfig,
    FlightCounters,
    FlightSummary,
    close_quietly,
    frames_with_timeout,
)
from holescan.capture._mavlink import Telemetry
from holescan.capture._worker import DetectionWorker, WorkerResult
from holescan.capture.errors import ClockUnavailable, SensorError
from holescan.detect import CameraIntrinsics, Frame, FrameSource
from holescan.flightlog import FlightLogError
from holescan.flightlog.diskspace import DiskSpace
from holescan.flightlog.writer import FlightLogWriter
from holescan.geotag import BestViews, Hole, HolePipeline, HoleView, Tier, VehiclePose, local_en_m
from holescan.link import PoseInvalid, PoseUnavailable, TelemetryTimeoutError

log = logging.getLogger(__name__)

SourceFactory = Callable[[], FrameSource]
FrameListener = Callable[[Frame, VehiclePose | None], None]
"""``on_frame(frame, pose)``: each captured frame and its pose (None: unposed), on the
capture thread, after the log and the detector have it; must never wait (the live map)."""
HoleListener = Callable[[list[Hole], list[Hole], Mapping[int, HoleView], Mapping[int, Tier]], None]
"""``on_holes(served, news, views, tiers)``: every announced hole (the waypoints), the
holes new or changed enough to tell the ground now (announced and for review), the best
view of each hole in ``news`` whose best view is known (hole id -> :class:`HoleView`), and
the tier of each hole in ``news`` (``announced``/``review``, :meth:`geotag.AnnounceGate.tier`)."""


class Flight:
    """One capture run; see the module docstring. ``run()`` blocks until the end."""

    def __init__(
        self,
        config: FlightConfig,
        source_factory: SourceFactory,
        camera: CameraIntrinsics,
        *,
        mavlink: str | None = None,
        telemetry_factory: Callable[..., Telemetry] = Telemetry,
        usb_reset: Callable[[], None] | None = None,
        on_holes: HoleListener | None = None,
        before_close: Callable[[], None] | None = None,
        on_frame: FrameListener | None = None,
        disk: DiskSpace | None = None,
    ) -> None:
        self.config = config
        self._disk = disk
        self._on_frame_hook = on_frame
        self.camera = camera
        self._source_factory = source_factory
        self._mavlink = mavlink
        self._telemetry_factory = telemetry_factory
        self._usb_reset = usb_reset
        self._on_holes = on_holes
        self._before_close = before_close  # e.g. the last pictures out on the shared link
        self.counters = FlightCounters()
        self.hole_pipeline = HolePipeline(camera, config.mount, errors=config.errors)
        self.tracker = self.hole_pipeline.tracker
        self.stop = threading.Event()
        self._writer: FlightLogWriter | None = None
        self._telemetry: Telemetry | None = None
        self._worker: DetectionWorker | None = None
        self._announced: dict[int, tuple[float, float, float]] = {}
        self._reviewed: dict[int, tuple[float, float, float]] = {}
        self._gate = config.gate
        self._views = BestViews()
        self._lock = threading.Lock()
        self._unix_minus_mono = time.time_ns() - time.monotonic_ns()
        self._finished = False  # ended by a limit or the source's end, not by a stop
        self.invalid = ""  # why the last frame refused as PoseInvalid was

    # -- clocks ---------------------------------------------------------------------------

    def unix_ns(self, t_mono_ns: int) -> int:
        """Unix time of a companion monotonic time: the autopilot's UTC when known."""
        tel = self._telemetry
        if tel is not None:
            try:
                return tel.clock.mono_to_unix_ns(t_mono_ns)
            except ClockUnavailable:
                pass
        return t_mono_ns + self._unix_minus_mono

    def pose(
        self, t_mono_ns: int, wait_s: float = 0.0, invalid: list[str] | None = None
    ) -> VehiclePose | None:
        """The vehicle pose at a frame time, or None: no telemetry, not synchronised, or a
        position the autopilot does not have (:class:`PoseInvalid`: no fix, EKF without a
        position, 0/0, a jump; the reason appended to ``invalid``, kept in :attr:`invalid`)."""
        tel = self._telemetry
        if tel is None:
            return None
        try:
            return tel.pose_at_mono(t_mono_ns, wait_s=wait_s)
        except PoseInvalid as err:
            if str(err) != self.invalid:
                log.info("frames not posed: %s", err)
            self.invalid = str(err)
            if invalid is not None:
                invalid.append(str(err))
            return None
        except PoseUnavailable as err:
            log.debug("frame at mono %d not posed: %s", t_mono_ns, err)
            return None

    # -- telemetry --------------------------------------------------------------------------

    def _on_mavlink(self, msg: Any, t_mono_ns: int) -> None:
        writer = self._writer
        if writer is None:
            return
        t_unix = self.unix_ns(t_mono_ns)
        try:
            writer.write_mavlink(msg.get_msgbuf(), t_unix, msg.get_type())
        except Exception as err:  # never let logging kill the receiver thread
            log.debug("raw MAVLink not logged: %s", err)
        if msg.get_type() == "GLOBAL_POSITION_INT" and self._telemetry is not None:
            try:
                pose = self._telemetry.pose_at(int(msg.time_boot_ms) * 1_000_000)
            except PoseUnavailable:
                return
            writer.write_pose(pose, t_unix)

    # -- results ----------------------------------------------------------------------------

    def _handle_result(self, r: WorkerResult) -> None:
        # The results thread and the final drain in run() both hand results here: one at a
        # time, so the tracker sees (and the log records) the results in one order.
        with self._lock:
            self._handle_result_locked(r)

    def _tiers(self, holes: list[Hole]) -> tuple[list[Hole], dict[int, Tier]]:
        """The holes to serve, and every hole's tier (the gate's select and review)."""
        served = self._gate.select(holes, announced=self._announced)
        return served, self._gate.tiers(holes, announced=self._announced)

    def _handle_result_locked(self, r: WorkerResult) -> None:
        assert self._writer is not None
        c = self.counters
        c.frames_detected += 1
        c.detect_ms_total += r.detect_ms
        if r.no_depth:  # too close for the sensor (on the ground) or nothing ranged
            c.frames_no_depth += 1
            return
        if r.error:
            c.detect_errors += 1
            log.warning("detection failed on frame %d: %s", r.frame_index, r.error)
            return
        c.detections += len(r.detections)
        self._writer.write_detections(r.frame_index, r.detections, self.unix_ns(r.t_mono_ns))
        invalid: list[str] = []
        step = self.hole_pipeline.add(
            r.frame_index,
            r.detections,
            lambda: self.pose(r.t_mono_ns, wait_s=self.config.pose_wait_s, invalid=invalid),
        )
        if step.refused:  # logged and detected, never placed: nothing announced from it
            c.pose_refusals += 1
            c.pose_invalid += bool(invalid)
            return
        changed = step.changed
        if not changed:
            return
        holes = self.tracker.holes()
        served, now = self._tiers(holes)
        self._writer.write_holes(holes, self.unix_ns(r.t_mono_ns), now, self._gate)
        self._views.update(r.frame_index, r.detections, changed)
        tiers: dict[int, Tier] = {}
        news = []
        for h in changed:
            tier = now[h.id]
            if tier != "candidate" and self._worth_telling(h, tier):
                tiers[h.id] = tier
                news.append(h)
        for h in news:
            if tiers[h.id] == "announced":
                self._announced[h.id] = (h.lat_deg, h.lon_deg, h.score)
                c.announcements += 1
            else:
                self._reviewed[h.id] = (h.lat_deg, h.lon_deg, h.score)
                c.reviews += 1
        if self._on_holes is not None and news:
            views = {h.id: v for h in news if (v := self._views.get(h.id)) is not None}
            self._on_holes(served, news, views, tiers)

    def _worth_telling(self, h: Hole, tier: Tier) -> bool:
        """New to the ground in this tier, moved more than 0.5 m or its score rose by 0.05
        since the ground was last told (a hole for review that becomes announced is told
        again)."""
        last = (self._announced if tier == "announced" else self._reviewed).get(h.id)
        if last is None:
            return True
        east, north = local_en_m(h.lat_deg, h.lon_deg, last[0], last[1])
        return bool(math.hypot(east, north) > 0.5 or h.score > last[2] + 0.05)

    def _health(self) -> dict[str, Any]:
        assert self._writer is not None and self._worker is not None
        ws = self._worker.stats()
        ls = self._writer.stats()
        c = self.counters
        out: dict[str, Any] = {
            "frames_captured": c.frames_captured,
            "frames_logged": ls.written.get("frames", 0),
            "frames_log_dropped": ls.dropped.get("frames", 0),
            "log_queue_depth": ls.queue_depth,
            "detect_offered": ws.offered,
            "detect_skipped": ws.skipped,
            "detect_done": ws.done,
            "detect_ms_mean": c.detect_ms_total / max(c.frames_detected, 1),
            "detect_errors": c.detect_errors,
            "frames_no_depth": c.frames_no_depth,
            "frames_unposed": c.frames_unposed,
            "pose_refusals": c.pose_refusals,
            "pose_invalid": c.pose_invalid,
            "pose_invalid_why": self.invalid,
            "sensor_failures": c.sensor_failures,
            "holes": len(self.tracker.holes()),
        }
        tel = self._telemetry
        if tel is not None:
            ts = tel.stats()
            out.update(
                mavlink_bad_bytes=ts.bad_bytes,
                mavlink_bad_packets=ts.bad_packets,
                mavlink_age_s=tel.last_message_age_s(),
                clock_source=tel.clock.source,
                # autopilot_mode, _armed, _mode_changes: recorded; no behaviour depends on them
                **{f"autopilot_{k}": v for k, v in ts.vehicle.items()},
            )
            with contextlib.suppress(ClockUnavailable):
                out.update(
                    clock_offset_ns=tel.clock.offset_ns,
                    clock_uncertainty_ns=tel.clock.uncertainty_ns,
                )
        return out

    def _results_loop(self, done: threading.Event) -> None:
        assert self._worker is not None and self._writer is not None
        next_health = time.monotonic()
        while True:
            finished = done.is_set()
            for r in self._worker.results(timeout=0.05):
                try:
                    self._handle_result(r)
                except Exception:  # a bad record must not stop the flight
                    log.exception("handling detections of frame %d failed", r.frame_index)
            if time.monotonic() >= next_health:
                self._writer.write_health(self._health())
                next_health += self.config.health_period_s
            if finished:
                return

    # -- capture ----------------------------------------------------------------------------

    def _on_frame(self, frame: Frame) -> None:
        assert self._writer is not None and self._worker is not None
        c = self.counters
        frame = replace(frame, index=c.frames_captured)
        c.frames_captured += 1
        pose = self.pose(frame.t_mono_ns)
        if pose is None:
            c.frames_unposed += 1
        t_boot = None
        if self._telemetry is not None:
            try:
                t_boot = self._telemetry.clock.mono_to_boot_ns(frame.t_mono_ns)
            except ClockUnavailable:
                t_boot = None
        if not self._writer.write_frame(
            frame, self.unix_ns(frame.t_mono_ns), pose=pose, t_boot_ns=t_boot
        ):
            c.frames_log_dropped += 1
        self._views.add_frame(frame.index, frame.rgb)
        self._worker.offer(frame)
        if self._on_frame_hook is not None:
            try:
                self._on_frame_hook(frame, pose)
            except Exception:  # a listener's bug must not stop capture
                log.exception("frame listener failed on frame %d", frame.index)

    def _capture(self, t_end: float | None) -> None:
        cfg = self.config
        attempt = 0
        while not self.stop.is_set():
            try:
                source = self._source_factory()
                source.__enter__()
            except SensorError as err:
                self._sensor_failed(err, attempt)
                attempt += 1
                continue
            try:
                for frame in frames_with_timeout(source, cfg.frame_timeout_s, self.stop):
                    attempt = 0
                    self._on_frame(frame)
                    if (
                        cfg.max_frames is not None
                        and self.counters.frames_captured >= cfg.max_frames
                    ):
                        self._finish()
                    if t_end is not None and time.monotonic() >= t_end:
                        self._finish()
                close_quietly(source)
                if not self.stop.is_set():
                    self._finished = True  # the recording ended by itself
                return  # end of the recording
            except SensorError as err:
                close_quietly(source)
                self._sensor_failed(err, attempt)
                attempt += 1
            except BaseException:
                close_quietly(source)
                raise

    def _finish(self) -> None:
        """A limit was reached: the flight ends normally (the detector gets time to catch
        up; a stop asked from outside only gets a short drain)."""
        self._finished = True
        self.stop.set()

    def _sensor_failed(self, err: SensorError, attempt: int) -> None:
        c = self.counters
        c.sensor_failures += 1
        wait = self.config.retry_backoff_s[min(attempt, len(self.config.retry_backoff_s) - 1)]
        log.warning("sensor failure (%s); reopening in %.1f s", err, wait)
        if self._writer is not None:
            self._writer.write_health(
                {"event": "sensor_failure", "error": str(err), "retry_in_s": wait}
            )
        if self._usb_reset is not None:
            try:
                self._usb_reset()
            except SensorError as reset_err:
                log.warning("USB reset failed: %s", reset_err)
        self.stop.wait(wait)
        c.sensor_reopens += 1

    def _start_telemetry(self, sync_s: float) -> None:
        """Connect to the autopilot; if it is silent, capture anyway and keep trying (a link
        that cannot be opened at all, e.g. a bad connection string, is an error)."""
        assert self._mavlink is not None
        try:
            tel = self._telemetry_factory(self._mavlink, on_message=self._on_mavlink)
            tel.__enter__()
        except TelemetryTimeoutError as err:
            log.warning("%s; capturing unposed frames and retrying the link", err)
            if self._writer is not None:
                self._writer.write_health({"event": "autopilot_silent", "error": str(err)})
            threading.Thread(
                target=self._retry_telemetry, name="telemetry-retry", daemon=True
            ).start()
            return
        self._telemetry = tel
        self._wait_for_sync(sync_s)

    def _retry_telemetry(self) -> None:
        assert self._mavlink is not None
        while not self.stop.is_set():
            try:
                tel = self._telemetry_factory(self._mavlink, on_message=self._on_mavlink)
                tel.__enter__()
            except TelemetryTimeoutError:
                continue  # each attempt already waited for a heartbeat
            if self.stop.is_set():
                tel.close()
                return
            self._telemetry = tel
            log.info("autopilot link up: frames are posed from now on")
            return

    def _wait_for_sync(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not self.stop.is_set():
            if self.pose(time.monotonic_ns()) is not None:
                return
            time.sleep(0.05)
        log.warning("no synchronised pose after %.1f s; capturing anyway", timeout_s)

    def run(self) -> FlightSummary:
        """Capture until the source ends, a limit is reached or :attr:`stop` is set."""
        cfg = self.config
        t0 = time.monotonic()
        t_end = t0 + cfg.max_duration_s if cfg.max_duration_s else None
        writer = FlightLogWriter(
            cfg.log_prefix,
            self.camera,
            config=cfg.config_record,
            mount=cfg.mount,
            errors=cfg.errors,
            options=cfg.log_options,
            disk=self._disk,
        )
        self._writer = writer
        deadline: threading.Timer | None = None
        if cfg.max_duration_s:  # also while the sensor is missing and being retried
            deadline = threading.Timer(cfg.max_duration_s, self._finish)
            deadline.daemon = True
            deadline.start()
        done = threading.Event()
        t_stop = time.monotonic()
        results_thread: threading.Thread | None = None
        telemetry_stats: dict[str, Any] = {}
        try:
            if self._mavlink:
                self._start_telemetry(cfg.startup_sync_s)
            with DetectionWorker(self.camera, cfg.params) as worker:
                self._worker = worker
                results_thread = threading.Thread(
                    target=self._results_loop, args=(done,), name="results", daemon=True
                )
                results_thread.start()
                try:
                    self._capture(t_end)
                finally:
                    t_stop = time.monotonic()
                    # A stop from outside (SIGTERM, Ctrl-C) must end within seconds.
                    for r in worker.drain(timeout=10.0 if self._finished else 2.0):
                        self._handle_result(r)
                    done.set()
                    results_thread.join(timeout=5.0)
                    stats = worker.stats()
                    log.debug("capture ended; results drained in %.2f s", time.monotonic() - t_stop)
            if self._telemetry is not None:
                ts = self._telemetry.stats()
                telemetry_stats = {
                    "messages": dict(ts.messages),
                    "bad_bytes": ts.bad_bytes,
                    "bad_packets": ts.bad_packets,
                    "rate_method": ts.rate_method,
                    "clock_source": self._telemetry.clock.source,
                }
            final = self.tracker.holes()
            writer.write_holes(final, time.time_ns(), self._tiers(final)[1], self._gate)
        finally:
            if deadline is not None:
                deadline.cancel()
            done.set()
            self.stop.set()  # also ends a telemetry retry still waiting for the autopilot
            if self._before_close is not None:
                try:
                    self._before_close()
                except Exception:  # the flight's end must not fail on it
                    log.exception("before-close hook failed")
            if self._telemetry is not None:
                self._telemetry.close()
            try:
                writer.close()
            except FlightLogError as err:  # disk full, I/O error: the summary says so
                log.error("%s; the files written so far are readable (log recover)", err)
            log.debug("flight closed %.2f s after capture ended", time.monotonic() - t_stop)
        return FlightSummary(
            counters=self.counters,
            log=writer.stats(),
            holes=tuple(self.tracker.holes()),
            detect_offered=stats.offered,
            detect_skipped=stats.skipped,
            duration_s=time.monotonic() - t0,
            telemetry=telemetry_stats,
        )
