"""The capture daemon: frames -> flight log and detection worker -> geotags -> ground crew.

Threads and processes of one flight:

- **capture** (the caller's thread): reads frames from the source through a pump thread
  with a timeout, stamps each on the autopilot's clock, holds it until the telemetry after
  it has arrived (at most ``pose_wait_s`` after its time or after it reached this thread,
  whichever is later: a loaded computer reads its telemetry late, and a frame posed at once
  could only extrapolate, or not be posed at all), then queues it to the log writer with its
  pose and offers it to the detection worker and the live map. Nothing makes it wait (held
  frames go on as later frames come, all of them when the sensor fails or capture ends);
  when the log falls behind (short of CPU), the frame is logged and not offered: detection
  sheds first.
- **log writer** thread (:class:`flightlog.FlightLogWriter`); **detection worker**
  process (:class:`capture._worker.DetectionWorker`); **telemetry** receiver thread
  (:class:`capture._mavlink.Telemetry`): each message logged raw, each position also as a pose.
- **results** thread: logs detections, poses the frame they came from (interpolated, once
  the telemetry after it has arrived), geotags, merges sightings into holes, logs the holes,
  serves them to the ground station and announces them (:class:`geotag.AnnouncePolicy`:
  again on a noticeable change, once more at the end with their last facts); writes
  ``/health`` every second.

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
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

from holescan.capture._flightrecords import FlightConfig, FlightCounters, FlightSummary
from holescan.capture._health import AutopilotSilent, FlightHealth, SensorFailed
from holescan.capture._mavlink import Telemetry
from holescan.capture._sensorloop import SensorRetry
from holescan.capture._telemetrysupervisor import TelemetryFactory, TelemetrySupervisor
from holescan.capture._worker import DetectionWorker, WorkerResult
from holescan.detect import CameraIntrinsics, Frame, FrameSource
from holescan.flightlog import FlightLogError
from holescan.flightlog.diskspace import DiskSpace
from holescan.flightlog.writer import FlightLogWriter
from holescan.geotag import (
    AnnouncePolicy,
    BestViews,
    Hole,
    HoleNews,
    HolePipeline,
    HoleView,
    Tier,
    VehiclePose,
)
from holescan.link import PoseUnavailable

log = logging.getLogger(__name__)

# Frames held for their telemetry at most (a VGA frame is ~1.5 MB: ~48 MB). At 30 fps
# and pose_wait_s 0.5 s about 15 are held while the telemetry is late; a stall hands over
# up to the pump's 8 more at once.
_MAX_HELD = 32

SourceFactory = Callable[[], FrameSource]
FrameListener = Callable[[Frame, VehiclePose | None], None]
"""``on_frame(frame, pose)``: each captured frame and its pose (None: unposed), on the
capture thread, after the log and the detector have it; must never wait (the live map)."""
HoleListener = Callable[[list[Hole], list[Hole], Mapping[int, HoleView], Mapping[int, Tier]], None]
"""``on_holes(served, news, views, tiers)``: every announced hole (the waypoints), the
holes new or changed enough to tell the ground now (announced and for review; when the
flight ends, every hole whose facts changed since it was last told), the best
view of each hole in ``news`` whose best view is known (hole id -> :class:`HoleView`), and
the tier of each hole in ``news`` (``announced``/``review``, :meth:`geotag.AnnounceGate.tier`)."""


class Flight:
    """One capture run; see the module docstring. ``run()`` blocks until the end.

    Its parts: the sensor and its retries (:class:`~capture._sensorloop.SensorRetry`), the
    autopilot link, its clocks and poses
    (:class:`~capture._telemetrysupervisor.TelemetrySupervisor`), what the ground is told
    (:class:`geotag.AnnouncePolicy`), the ``/health`` records
    (:class:`~capture._health.FlightHealth`). The flight wires them together and runs them
    from start to end.
    """

    def __init__(
        self,
        config: FlightConfig,
        source_factory: SourceFactory,
        camera: CameraIntrinsics,
        *,
        mavlink: str | None = None,
        telemetry_factory: TelemetryFactory = Telemetry,
        usb_reset: Callable[[], None] | None = None,
        on_holes: HoleListener | None = None,
        before_close: Callable[[], None] | None = None,
        on_frame: FrameListener | None = None,
        disk: DiskSpace | None = None,
    ) -> None:
        self.config = config
        self._disk = disk
        self._on_frame_hook = on_frame
        # Frames queued for the log above which capture sheds the detector and the live map.
        self._shed_above = max(2, config.log_options.max_queued_frames // 4)
        self.camera = camera
        self._on_holes = on_holes
        self._before_close = before_close  # e.g. the last pictures out on the shared link
        self.counters = FlightCounters()
        self.hole_pipeline = HolePipeline(camera, config.mount, errors=config.errors)
        self.tracker = self.hole_pipeline.tracker
        self.stop = threading.Event()
        self._writer: FlightLogWriter | None = None
        self._worker: DetectionWorker | None = None
        self._link = TelemetrySupervisor(
            mavlink,
            telemetry_factory,
            on_message=self._on_mavlink,
            on_silent=self._on_autopilot_silent,
        )
        self._sensor = SensorRetry(
            source_factory,
            frame_timeout_s=config.frame_timeout_s,
            backoff_s=config.retry_backoff_s,
            usb_reset=usb_reset,
            on_failure=self._on_sensor_failed,
            on_reopen=self._on_sensor_reopen,
        )
        self._gate = config.gate
        self._policy = AnnouncePolicy(self._gate)
        self._views = BestViews()
        self._lock = threading.Lock()
        # Captured frames waiting (at most pose_wait_s after their time or their arrival
        # here, whichever is later) for the telemetry after them: (frame, its Unix and boot
        # times read at capture: a clock re-synchronised while a frame is held, after an
        # autopilot reboot, does not restamp it; its arrival at this thread, mono ns).
        self._held: deque[tuple[Frame, int, int | None, int]] = deque()
        self._finished = False  # ended by a limit or the source's end, not by a stop

    # -- clocks (the autopilot link's) --------------------------------------------------------

    @property
    def invalid(self) -> str:
        """Why the last frame refused as :class:`link.PoseInvalid` was."""
        return self._link.invalid

    def unix_ns(self, t_mono_ns: int) -> int:
        """Unix time of a companion monotonic time: the autopilot's UTC when known."""
        return self._link.unix_ns(t_mono_ns)

    def pose(
        self, t_mono_ns: int, wait_s: float = 0.0, invalid: list[str] | None = None
    ) -> VehiclePose | None:
        """The vehicle pose at a frame time, or None
        (:meth:`~capture._telemetrysupervisor.TelemetrySupervisor.pose`)."""
        return self._link.pose(t_mono_ns, wait_s=wait_s, invalid=invalid)

    # -- events of the parts, to the log ------------------------------------------------------

    def _on_mavlink(self, msg: Any, t_mono_ns: int) -> None:
        writer = self._writer
        if writer is None:
            return
        t_unix = self.unix_ns(t_mono_ns)
        try:
            writer.write_mavlink(msg.get_msgbuf(), t_unix, msg.get_type())
        except Exception as err:  # never let logging kill the receiver thread
            log.debug("raw MAVLink not logged: %s", err)
        tel = self._link.telemetry
        if msg.get_type() == "GLOBAL_POSITION_INT" and tel is not None:
            try:
                pose = tel.pose_at(int(msg.time_boot_ms) * 1_000_000)
            except PoseUnavailable:
                return
            writer.write_pose(pose, t_unix)

    def _on_autopilot_silent(self, event: AutopilotSilent) -> None:
        if self._writer is not None:
            self._writer.write_health(event.record())

    def _on_sensor_failed(self, event: SensorFailed) -> None:
        # On the capture thread (the sensor's retries run in its loop): the frames held
        # for their telemetry go on now, not after the reopen.
        self._release(flush=True)
        self.counters.sensor_failures += 1
        if self._writer is not None:
            self._writer.write_health(event.record())

    def _on_sensor_reopen(self) -> None:
        self.counters.sensor_reopens += 1

    # -- results ----------------------------------------------------------------------------

    def _handle_result(self, r: WorkerResult) -> None:
        # The results thread and the final drain in run() both hand results here: one at a
        # time, so the tracker sees (and the log records) the results in one order.
        with self._lock:
            self._handle_result_locked(r)

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
        served, now = self._policy.tiers(holes)
        self._writer.write_holes(holes, self.unix_ns(r.t_mono_ns), now, self._gate)
        self._views.update(r.frame_index, r.detections, changed)
        self._tell(served, self._policy.tell(changed, now))

    def _tell(self, served: list[Hole], news: list[HoleNews]) -> None:
        """Count ``news`` and hand it to the ground (``on_holes``)."""
        c = self.counters
        for n in news:
            if n.tier == "announced":
                c.announcements += 1
            else:
                c.reviews += 1
        if self._on_holes is not None and news:
            told = [n.hole for n in news]
            views = {h.id: v for h in told if (v := self._views.get(h.id)) is not None}
            tiers: dict[int, Tier] = {n.hole.id: n.tier for n in news}
            self._on_holes(served, told, views, tiers)

    def _tell_final(self) -> list[Hole]:
        """The flight's last holes, logged; every one the ground knows of whose facts
        changed since it was last told (a sigma a few cm smaller, more sightings) is told
        once more (:meth:`geotag.AnnouncePolicy.final`), so the ground ends with the
        vehicle's last numbers. Their cards are queued like any other (the hole server
        sends what the link and the budget allow before it closes)."""
        assert self._writer is not None
        with self._lock:
            final = self.tracker.holes()
            served, tiers = self._policy.tiers(final)
            self._writer.write_holes(final, time.time_ns(), tiers, self._gate)
            try:
                self._tell(served, self._policy.final(final, tiers))
            except Exception:  # the log must still close
                log.exception("telling the ground the holes' last facts failed")
        return final

    def _health(self) -> FlightHealth:
        assert self._writer is not None and self._worker is not None
        return FlightHealth.of(
            self.counters,
            self._writer.stats(),
            self._worker.stats(),
            holes=len(self.tracker.holes()),
            pose_invalid_why=self.invalid,
            telemetry=self._link.telemetry,
        )

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
                self._writer.write_health(self._health().record())
                next_health += self.config.health_period_s
            if finished:
                return

    # -- capture ----------------------------------------------------------------------------

    def _on_frame(self, frame: Frame) -> None:
        c = self.counters
        frame = replace(frame, index=c.frames_captured)
        c.frames_captured += 1
        t = frame.t_mono_ns
        self._held.append((frame, self.unix_ns(t), self._link.boot_ns(t), time.monotonic_ns()))
        self._release()

    def _release(self, flush: bool = False) -> None:
        """Log and offer the held frames, oldest first, each once the telemetry after it
        has arrived (its pose interpolated) or ``pose_wait_s`` after its time or its
        arrival here, whichever is later (extrapolated if the newest telemetry is recent
        enough, else unposed). A stalled process hands its frames over late, and reads the
        telemetry of their time late too: the wait starts when a frame is here to wait.
        Never waits: a frame still waiting stays held (and the ones after it) until a later
        frame comes; more than ``_MAX_HELD`` frames held, the oldest goes at once.
        ``flush``: all of them now, when no frame is coming (the end of capture, a sensor
        failure): their telemetry is waited for, until ``pose_wait_s`` after the last."""
        held = self._held
        wait_s = self.config.pose_wait_s
        while held:
            frame, _, t_boot, arrived = held[0]
            if (
                not flush
                and len(held) <= _MAX_HELD
                and self._link.pose_pending(
                    frame.t_mono_ns, wait_s, since_ns=arrived, t_boot_ns=t_boot
                )
            ):
                return
            self._log_and_offer(*held.popleft(), wait_s=wait_s if flush else 0.0)

    def _log_and_offer(
        self, frame: Frame, t_unix: int, t_boot: int | None, arrived: int, *, wait_s: float
    ) -> None:
        assert self._writer is not None and self._worker is not None
        c = self.counters
        # The pose at the boot time the frame is logged with (read at capture).
        pose = self._link.pose(frame.t_mono_ns, wait_s=wait_s, since_ns=arrived, t_boot_ns=t_boot)
        if pose is None:
            c.frames_unposed += 1
        if not self._writer.write_frame(frame, t_unix, pose=pose, t_boot_ns=t_boot):
            c.frames_log_dropped += 1
        self._views.add_frame(frame.index, frame.rgb)
        if self._writer.frames_queued > self._shed_above:  # short of CPU: log first
            c.frames_shed += 1
            return
        self._worker.offer(frame)
        if self._on_frame_hook is not None:
            try:
                self._on_frame_hook(frame, pose)
            except Exception:  # a listener's bug must not stop capture
                log.exception("frame listener failed on frame %d", frame.index)

    def _capture(self, t_end: float | None) -> None:
        cfg = self.config
        try:
            with contextlib.closing(self._sensor.frames(self.stop)) as frames:
                for frame in frames:
                    self._on_frame(frame)
                    if (
                        cfg.max_frames is not None
                        and self.counters.frames_captured >= cfg.max_frames
                    ):
                        self._finish()
                    if t_end is not None and time.monotonic() >= t_end:
                        self._finish()
        finally:
            self._release(flush=True)  # the last frames, posed as far as they can be
        if not self.stop.is_set():
            self._finished = True  # the recording ended by itself

    def _finish(self) -> None:
        """A limit was reached: the flight ends normally (the detector gets time to catch
        up; a stop asked from outside only gets a short drain)."""
        self._finished = True
        self.stop.set()

    # -- lifecycle --------------------------------------------------------------------------

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
            self._link.start(self.stop, cfg.startup_sync_s)
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
            telemetry_stats = self._link.summary()
            self._tell_final()
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
            self._link.close()
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
