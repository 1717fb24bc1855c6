"""The MCAP flight log writer: everything a flight saw, written off the capture thread.

``write_*`` calls only stamp the record (log time, per-topic sequence number) and put it
on a bounded queue; a writer thread encodes (Foxglove protobuf / JSON), writes zstd
chunks of ``chunk_size`` bytes, flushes and fsyncs about every ``sync_interval_s`` and
rotates files by size and age (``PREFIX_0000.mcap``, ``PREFIX_0001.mcap``, ...). A full
queue never blocks the caller: the record is dropped, counted, and its sequence number is
left as a gap a reader can see. Topics and frames: see :mod:`flightlog.schemas`.
"""

from __future__ import annotations

import logging
import os
import platform
import queue
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import Any, Final

import numpy as np

import holescan.flightlog.schemas as sch
from holescan.detect import CameraIntrinsics, Detection, Frame
from holescan.errors import InputError
from holescan.flightlog.detections import annotations_message, detection_json
from holescan.flightlog.diskspace import DiskSpace, SystemDiskSpace
from holescan.flightlog.errors import FlightLogError
from holescan.flightlog.images import ImageEncoder
from holescan.flightlog.mcapfile import McapFile, mcap_version
from holescan.flightlog.metadata import mount_metadata
from holescan.flightlog.options import LogOptions, WriterStats, log_file_path
from holescan.geotag import CameraMount, ErrorModel, LocalFrame, VehiclePose

__all__ = ["FlightLogWriter"]

_log = logging.getLogger(__name__)

_FRAME_TOPICS: Final = (sch.TOPIC_FRAME_INFO, sch.TOPIC_COLOR, sch.TOPIC_DEPTH)


class FlightLogWriter:
    """Context manager writing a flight to ``PREFIX_NNNN.mcap`` files.

    Parameters
    ----------
    prefix : path and name of the log, e.g. ``/data/flight-0612`` (``.mcap`` optional);
        existing files are never overwritten (:class:`FlightLogError`).
    camera : intrinsics of the depth-registered RGB image (``/camera/color/camera_info``).
    config : the run's configuration, stored as MCAP metadata ``holescan.config``
        (values as JSON).
    mount : how the camera sits on the vehicle (default: nadir, image top towards the
        nose); logged as the ``/tf`` transform base_link -> camera and as metadata
        ``holescan.mount``. A gimbal attitude in it is not logged.
    errors : the sightings' error model; its attitude sigma goes into ``holescan.mount``.
    options : :class:`LogOptions` (compression, image codecs, the disk reserve).
    disk : where the free space of the log's folder is read (default: the real file
        system). When it falls under ``options.image_reserve_bytes`` the writer stops
        logging frames for the rest of the flight and keeps every other record; a
        ``/health`` record with ``event = "images_stopped"`` says when, and later health
        records carry ``images_stopped_t_unix_ns`` and ``frames_not_logged``.

    Every ``write_*`` returns at once: True when queued, False when dropped (queue full
    or writer failed); ``write_frame`` also returns True for a frame deliberately not
    logged after images were stopped (counted apart, never as a drop). ``t_unix_ns``
    arguments are when the thing happened (capture or receive time, Unix clock) and become
    the MCAP ``publish_time``; ``log_time`` is ``time.time_ns()`` at the call.
    """

    def __init__(
        self,
        prefix: str | os.PathLike[str],
        camera: CameraIntrinsics,
        *,
        config: Mapping[str, Any] | None = None,
        mount: CameraMount | None = None,
        errors: ErrorModel | None = None,
        options: LogOptions | None = None,
        disk: DiskSpace | None = None,
    ) -> None:
        self.options = options or LogOptions()
        o = self.options
        self._encoder = ImageEncoder(o.color, o.depth, o.jpeg_quality)
        self._disk: DiskSpace = disk or SystemDiskSpace()
        self._images_stopped_ns: int | None = None
        self._frames_not_logged = 0
        self._frame_cpu_ns_total = 0
        self.camera = camera
        self._prefix = Path(prefix)
        mount = mount or CameraMount()
        self._mount_rot = np.asarray(mount.rotation, dtype=np.float64)
        self._mount_offset = tuple(float(v) for v in mount.offset_m)
        self._metadata = {
            "holescan": {
                "version": _dist_version("holescan"),
                "python": platform.python_version(),
                "mcap": mcap_version(),
                "host": platform.node(),
                "log_prefix": str(self._prefix),
            },
            "holescan.config": {k: sch.to_json(v).decode() for k, v in (config or {}).items()},
            "holescan.camera": {k: repr(v) for k, v in camera.to_dict().items()},
            "holescan.mount": mount_metadata(mount, errors or ErrorModel()),
        }
        self._queue: queue.Queue[tuple[Any, ...]] = queue.Queue(self.options.max_queued_messages)
        self._lock = threading.Lock()
        self._seq: Counter[str] = Counter()
        self._enqueued: Counter[str] = Counter()
        self._written: Counter[str] = Counter()
        self._dropped: Counter[str] = Counter()
        self._frames_queued = 0
        self._frames_queued_max = 0
        self._queue_max = 0
        self._frames_synced = 0
        self._frame_write_ns_total = 0
        self._frame_write_ns_max = 0
        self._enqueue_ns_max = 0
        self._bytes_closed = 0
        self._files: list[Path] = []
        self._file: McapFile | None = None
        self._file_opened_ns = 0
        self._origin: LocalFrame | None = None
        self._error: BaseException | None = None
        self._closing = threading.Event()
        self._closed = False
        self._open_next_file()  # fail here, on the caller's thread, if the path is bad
        self._check_disk(time.time_ns())
        self._thread = threading.Thread(target=self._run, name="flight-log-writer", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ caller side

    def __enter__(self) -> FlightLogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def paths(self) -> tuple[Path, ...]:
        """Files written so far (the last one may still be open)."""
        with self._lock:
            return tuple(self._files)

    def write_frame(
        self,
        frame: Frame,
        t_unix_ns: int,
        *,
        pose: VehiclePose | None = None,
        t_boot_ns: int | None = None,
    ) -> bool:
        """Queue an RGB-D frame (its arrays must not be modified afterwards).

        t_unix_ns : capture time on the Unix clock (image timestamps, publish_time).
        pose, t_boot_ns : the vehicle pose at capture and the capture time on the
            autopilot's boot clock, when known; stored with the frame.
        """
        h, w = self.camera.height, self.camera.width
        if frame.rgb.shape != (h, w, 3) or frame.rgb.dtype != np.uint8:
            raise InputError(f"frame.rgb must be ({h}, {w}, 3) uint8, got {frame.rgb.shape}")
        if frame.depth.shape != (h, w) or frame.depth.dtype != np.uint16:
            raise InputError(f"frame.depth must be ({h}, {w}) uint16, got {frame.depth.shape}")
        if self._images_stopped_ns is not None:
            with self._lock:
                self._frames_not_logged += 1
            return True
        return self._put("frames", "frame", frame, int(t_unix_ns), pose, t_boot_ns)

    def write_pose(self, pose: VehiclePose, t_unix_ns: int) -> bool:
        """Queue a vehicle pose: ``/mavlink/location`` (GPS), ``/tf`` world -> base_link and
        the exact record on ``/mavlink/pose``. ``t_unix_ns``: the pose's time, Unix clock."""
        return self._put(sch.TOPIC_POSE, "pose", pose, int(t_unix_ns))

    def write_mavlink(self, packet: bytes, t_unix_ns: int, name: str = "") -> bool:
        """Queue one raw MAVLink packet (``msg.get_msgbuf()``) received at ``t_unix_ns``."""
        return self._put(sch.TOPIC_MAVLINK_RAW, "mavlink", bytes(packet), int(t_unix_ns), name)

    def write_detections(
        self, frame_index: int, detections: Sequence[Detection], t_unix_ns: int
    ) -> bool:
        """Queue the detections of frame ``frame_index`` captured at ``t_unix_ns``: boxes
        on ``/detections/annotations`` and the full records on ``/detections``."""
        dets = tuple(detections)
        return self._put(sch.TOPIC_DETECTIONS, "detections", int(frame_index), dets, int(t_unix_ns))

    def write_holes(
        self,
        holes: Sequence[Any],
        t_unix_ns: int,
        tiers: Mapping[int, str] | None = None,
        gate: Any = None,
    ) -> bool:
        """Queue the hole list on ``/holes``, ``/holes/geojson`` (:func:`~schemas.holes_record`)."""
        doc = sch.holes_record(holes, tiers, gate)
        return self._put(sch.TOPIC_HOLES, "holes", doc, int(t_unix_ns))

    def write_health(
        self, values: Mapping[str, Any], t_unix_ns: int | None = None, source: str = "daemon"
    ) -> bool:
        """Queue a health record (frame drops, queue depths, clock offset, ...) on ``/health``."""
        record = {"source": source, **sch.jsonable(values)}
        t = time.time_ns() if t_unix_ns is None else int(t_unix_ns)
        return self._put(sch.TOPIC_HEALTH, "health", record, t)

    @property
    def frames_queued(self) -> int:
        """Frames queued and not written yet (how far the writer is behind capture)."""
        return self._frames_queued

    def stats(self) -> WriterStats:
        with self._lock:
            frames = self._written["frames"]
            return WriterStats(
                enqueued=dict(self._enqueued),
                written=dict(self._written),
                dropped=dict(self._dropped),
                frames_synced=self._frames_synced,
                queue_depth=self._queue.qsize(),
                queue_depth_max=self._queue_max,
                frames_queued_max=self._frames_queued_max,
                frame_write_ms_mean=self._frame_write_ns_total / max(frames, 1) / 1e6,
                frame_write_ms_max=self._frame_write_ns_max / 1e6,
                frame_cpu_ms_mean=self._frame_cpu_ns_total / max(frames, 1) / 1e6,
                enqueue_ms_max=self._enqueue_ns_max / 1e6,
                bytes_written=self._bytes_closed + self._open_bytes(),
                files=tuple(self._files),
                error=None if self._error is None else repr(self._error),
                images_stopped_t_unix_ns=self._images_stopped_ns,
                frames_not_logged=self._frames_not_logged,
            )

    def close(self) -> None:
        """Write everything queued, finish the file (summary, indexes), fsync, close.

        Raises :class:`FlightLogError` if the writer thread failed (the files written up
        to the failure can be repaired with ``recover_log``).
        """
        if self._closed:
            return
        self._closed = True
        self._closing.set()
        self._thread.join()
        f, self._file = self._file, None
        if f is not None:
            try:
                f.close()
            except (OSError, ValueError) as err:
                self._error = self._error or err
            with self._lock:
                self._bytes_closed += os.path.getsize(f.path)
                self._frames_synced = self._written["frames"]
        if self._error is not None:
            raise FlightLogError(f"flight log writer failed: {self._error}") from self._error
        st = self.stats()
        _log.info(
            "flight log closed: %d files, %d frames written, %d dropped, %.1f MB",
            len(st.files),
            st.written.get("frames", 0),
            sum(st.dropped.values()),
            st.bytes_written / 1e6,
        )

    def _put(self, topic: str, kind: str, *payload: Any) -> bool:
        t0 = time.perf_counter_ns()
        log_time = time.time_ns()
        is_frame = kind == "frame"
        with self._lock:
            # /health is also written by the writer thread itself (_periodic): its sequence
            # numbers are given where the records are written, so they stay in order.
            seq = -1 if topic == sch.TOPIC_HEALTH else self._seq[topic]
            if topic != sch.TOPIC_HEALTH:
                self._seq[topic] = seq + 1
            self._enqueued[topic] += 1
            ok = self._error is None and not self._closed
            if ok and is_frame and self._frames_queued >= self.options.max_queued_frames:
                ok = False
            if ok:
                try:
                    self._queue.put_nowait((kind, seq, log_time, *payload))
                except queue.Full:
                    ok = False
            if ok:
                depth = self._queue.qsize()
                self._queue_max = max(self._queue_max, depth)
                if is_frame:
                    self._frames_queued += 1
                    self._frames_queued_max = max(self._frames_queued_max, self._frames_queued)
            else:
                self._dropped[topic] += 1
            self._enqueue_ns_max = max(self._enqueue_ns_max, time.perf_counter_ns() - t0)
        return ok

    # ------------------------------------------------------------------ writer thread

    def _run(self) -> None:
        interval_ns = int(self.options.sync_interval_s * 1e9)
        next_sync = time.monotonic_ns() + interval_ns
        handlers: dict[str, Callable[..., None]] = {
            "frame": self._on_frame,
            "pose": self._on_pose,
            "mavlink": self._on_mavlink,
            "detections": self._on_detections,
            "holes": self._on_holes,
            "health": self._on_health,
        }
        try:
            while True:
                timeout = max(next_sync - time.monotonic_ns(), 0) / 1e9
                try:
                    item = self._queue.get(timeout=min(timeout, 0.05))
                except queue.Empty:
                    item = None
                if item is not None:
                    self._maybe_rotate()
                    handlers[item[0]](*item[1:])
                if time.monotonic_ns() >= next_sync:
                    self._periodic()
                    next_sync = time.monotonic_ns() + interval_ns
                if item is None and self._closing.is_set() and self._queue.empty():
                    self._periodic()  # final health record: drops up to the end
                    return
        except Exception as err:  # disk full, I/O error: keep capture running, report
            _log.exception("flight log writer stopped")
            with self._lock:
                self._error = err

    def _write(
        self, topic: str, proto: Any | None, data: bytes, seq: int, log_time: int, pub: int
    ) -> None:
        assert self._file is not None
        schema = sch.JSON_SCHEMAS[topic] if proto is None else type(proto)
        cid = self._file.channel(topic, schema)
        self._file.add_message(cid, log_time, data, pub, seq)

    def _proto(self, topic: str, msg: Any, seq: int, log_time: int, pub: int) -> None:
        self._write(topic, msg, msg.SerializeToString(), seq, log_time, pub)

    def _json(self, topic: str, obj: Any, seq: int, log_time: int, pub: int) -> None:
        self._write(topic, None, sch.to_json(obj), seq, log_time, pub)

    def _own_seq(self, topic: str) -> int:
        with self._lock:
            seq = self._seq[topic]
            self._seq[topic] = seq + 1
            self._enqueued[topic] += 1
            return seq

    def _count(self, topic: str) -> None:
        with self._lock:
            self._written[topic] += 1

    def _on_frame(
        self,
        seq: int,
        log_time: int,
        frame: Frame,
        t_unix_ns: int,
        pose: VehiclePose | None,
        t_boot_ns: int | None,
    ) -> None:
        # The reserve is checked before every frame, not only every sync: a writer behind
        # capture (short of CPU) would otherwise write the frames queued before the check
        # past the reserve, and fill the disk.
        self._check_disk(time.time_ns())
        if self._images_stopped_ns is not None:  # queued before the disk reached the reserve
            with self._lock:
                self._frames_queued -= 1
                self._frames_not_logged += 1
            return
        t0 = time.perf_counter_ns()
        cpu0 = time.thread_time_ns()
        info = {
            "index": frame.index,
            "t_mono_ns": frame.t_mono_ns,
            "t_sensor_ns": frame.t_sensor_ns,
            "t_unix_ns": t_unix_ns,
            "t_boot_ns": t_boot_ns,
            "pose": None if pose is None else sch.pose_json(pose),
        }
        self._json(sch.TOPIC_FRAME_INFO, info, seq, log_time, t_unix_ns)
        color = self._encoder.color_message(frame.rgb, t_unix_ns)
        self._proto(sch.TOPIC_COLOR, color, seq, log_time, t_unix_ns)
        depth = self._encoder.depth_message(frame.depth, t_unix_ns)
        self._proto(sch.TOPIC_DEPTH, depth, seq, log_time, t_unix_ns)
        dt = time.perf_counter_ns() - t0
        cpu = time.thread_time_ns() - cpu0
        with self._lock:
            self._frame_cpu_ns_total += cpu
            self._written["frames"] += 1
            self._frames_queued -= 1
            self._frame_write_ns_total += dt
            self._frame_write_ns_max = max(self._frame_write_ns_max, dt)

    def _on_pose(self, seq: int, log_time: int, pose: VehiclePose, t_unix_ns: int) -> None:
        if self._origin is None:
            self._origin = LocalFrame(pose.lat_deg, pose.lon_deg, pose.alt_m)
            self._write_origin()
        enu = self._origin.to_enu(pose.lat_deg, pose.lon_deg, pose.alt_m)
        self._json(sch.TOPIC_POSE, sch.pose_json(pose), seq, log_time, t_unix_ns)
        loc_seq, tf_seq = self._own_seq(sch.TOPIC_LOCATION), self._own_seq(sch.TOPIC_TF)
        self._proto(
            sch.TOPIC_LOCATION, sch.location_message(pose, t_unix_ns), loc_seq, log_time, t_unix_ns
        )
        tf = sch.vehicle_transform(pose, [float(v) for v in enu], t_unix_ns)
        self._proto(sch.TOPIC_TF, tf, tf_seq, log_time, t_unix_ns)
        for topic in (sch.TOPIC_POSE, sch.TOPIC_LOCATION, sch.TOPIC_TF):
            self._count(topic)

    def _on_mavlink(
        self, seq: int, log_time: int, packet: bytes, t_unix_ns: int, name: str
    ) -> None:
        self._json(sch.TOPIC_MAVLINK_RAW, sch.mavlink_json(packet, name), seq, log_time, t_unix_ns)
        self._count(sch.TOPIC_MAVLINK_RAW)

    def _on_detections(
        self, seq: int, log_time: int, frame_index: int, dets: tuple[Detection, ...], t: int
    ) -> None:
        record = {
            "frame_index": frame_index,
            "t_unix_ns": t,
            "detections": [detection_json(d) for d in dets],
        }
        self._json(sch.TOPIC_DETECTIONS, record, seq, log_time, t)
        ann_seq = self._own_seq(sch.TOPIC_DETECTION_ANNOTATIONS)
        self._proto(
            sch.TOPIC_DETECTION_ANNOTATIONS, annotations_message(dets, t), ann_seq, log_time, t
        )
        self._count(sch.TOPIC_DETECTIONS)
        self._count(sch.TOPIC_DETECTION_ANNOTATIONS)

    def _on_holes(self, seq: int, log_time: int, doc: dict[str, Any], t: int) -> None:
        self._json(sch.TOPIC_HOLES, doc, seq, log_time, t)
        geo_seq = self._own_seq(sch.TOPIC_HOLES_GEOJSON)
        geo = sch.holes_geojson_message(doc["holes"])
        self._proto(sch.TOPIC_HOLES_GEOJSON, geo, geo_seq, log_time, t)
        self._count(sch.TOPIC_HOLES)
        self._count(sch.TOPIC_HOLES_GEOJSON)

    def _on_health(self, _seq: int, log_time: int, record: dict[str, Any], t: int) -> None:
        with self._lock:
            seq = self._seq[sch.TOPIC_HEALTH]
            self._seq[sch.TOPIC_HEALTH] = seq + 1
        self._json(sch.TOPIC_HEALTH, record, seq, log_time, t)
        self._count(sch.TOPIC_HEALTH)

    # ------------------------------------------------------------ files, sync, health

    def _open_bytes(self) -> int:
        f = self._file
        try:
            return 0 if f is None else f.bytes_written
        except ValueError:  # closed by a rotation meanwhile
            return 0

    def _open_next_file(self) -> None:
        path = log_file_path(self._prefix, len(self._files))
        self._file = McapFile(
            path,
            library=f"holescan/{_dist_version('holescan')} mcap-python/{mcap_version()}",
            compression=self.options.compression,
            chunk_size=self.options.chunk_size,
            via_part=False,  # the open file is the record: a crash leaves it readable
        )
        self._file_opened_ns = time.monotonic_ns()
        with self._lock:
            self._files.append(path)
        now = time.time_ns()
        meta = {**self._metadata["holescan"], "file_index": str(len(self._files) - 1)}
        self._file.add_metadata("holescan", meta)
        for name, values in self._metadata.items():
            if name != "holescan":
                self._file.add_metadata(name, values)
        if self._origin is not None:
            self._write_origin()
        mount = sch.camera_mount_transform(self._mount_rot, self._mount_offset, now)
        self._proto(sch.TOPIC_TF, mount, self._own_seq(sch.TOPIC_TF), now, now)
        self._count(sch.TOPIC_TF)
        self._write_calibration(now)

    def _write_origin(self) -> None:
        assert self._file is not None
        assert self._origin is not None
        o = self._origin
        values = {
            "lat_deg": repr(o.lat0_deg),
            "lon_deg": repr(o.lon0_deg),
            "alt_m": repr(o.alt0_m),
            "frame": "ENU",
        }
        self._file.add_metadata("holescan.world_origin", values)

    def _write_calibration(self, now: int) -> None:
        msg = sch.calibration_message(self.camera, now)
        self._proto(sch.TOPIC_CAMERA_INFO, msg, self._own_seq(sch.TOPIC_CAMERA_INFO), now, now)
        self._count(sch.TOPIC_CAMERA_INFO)

    def _maybe_rotate(self) -> None:
        f = self._file
        assert f is not None
        too_big = f.bytes_written >= self.options.max_file_bytes
        too_old = time.monotonic_ns() - self._file_opened_ns >= self.options.max_file_s * 1e9
        if too_big or too_old:
            f.close()
            with self._lock:
                self._bytes_closed += os.path.getsize(f.path)
                self._frames_synced = self._written["frames"]
            self._file = None
            self._open_next_file()

    def _check_disk(self, now: int) -> None:
        """Stop logging frames when the disk's free space is under the reserve (once)."""
        reserve = self.options.image_reserve_bytes
        if self._images_stopped_ns is not None or reserve <= 0:
            return
        try:
            free = self._disk.free_bytes(self._prefix.parent)
        except OSError as err:
            _log.warning("cannot read the free space of %s: %s", self._prefix.parent, err)
            return
        if free >= reserve:
            return
        with self._lock:
            self._images_stopped_ns = now
        _log.warning(
            "disk nearly full (%.0f MB free, reserve %.0f MB): frames are no longer logged; "
            "telemetry, detections and holes still are",
            free / 1e6,
            reserve / 1e6,
        )
        record = {
            "source": "logger",
            "event": "images_stopped",
            "free_bytes": free,
            "reserve_bytes": reserve,
            "images_stopped_t_unix_ns": now,
        }
        self._json(sch.TOPIC_HEALTH, record, self._own_seq(sch.TOPIC_HEALTH), now, now)
        self._count(sch.TOPIC_HEALTH)

    def _periodic(self) -> None:
        assert self._file is not None
        now = time.time_ns()
        self._check_disk(now)
        st = self.stats()
        health = {
            "source": "logger",
            "queue_depth": st.queue_depth,
            "queue_depth_max": st.queue_depth_max,
            "frames_queued_max": st.frames_queued_max,
            "frames_written": st.written.get("frames", 0),
            "dropped": dict(st.dropped),
            "frame_write_ms_mean": round(st.frame_write_ms_mean, 3),
            "frame_write_ms_max": round(st.frame_write_ms_max, 3),
            "frame_cpu_ms_mean": round(st.frame_cpu_ms_mean, 3),
            "bytes_written": st.bytes_written,
            "file_index": len(st.files) - 1,
        }
        if st.images_stopped_t_unix_ns is not None:
            health["images_stopped_t_unix_ns"] = st.images_stopped_t_unix_ns
            health["frames_not_logged"] = st.frames_not_logged
        self._json(sch.TOPIC_HEALTH, health, self._own_seq(sch.TOPIC_HEALTH), now, now)
        self._count(sch.TOPIC_HEALTH)
        self._write_calibration(now)
        written = st.written.get("frames", 0)
        self._file.sync()
        with self._lock:
            self._frames_synced = written
