"""On the client: one flight's partition results replayed in log order into holes.

:class:`FlightMerger` takes the partitions of a flight in order and replays their events
as the flight saw them: raw MAVLink packets through :class:`link.TelemetryReplay` (the
live link's decoder), each frame posed at its autopilot boot time as soon as telemetry
after it was read (at the end of the log the last frames are extrapolated or refused, as
in flight), and the frames' detections merged in frame order through
:class:`geotag.HolePipeline`, the capture daemon's own step. With ``frames="flight"``
only the frames the flight's ``/detections`` records name are merged, in their order.

Every merged frame is also handed to ``on_frame`` (the campaign's cross-flight merge)
and its records to ``write`` (the sidecar MCAP).

**One hole, one id.** The replay's tracker numbers holes in its own order of first
sighting; at :meth:`FlightMerger.finish` its holes take the ids the flight gave the same
openings (:func:`geotag.carry_ids` against the flight's last ``/holes`` record), and holes
only the replay found take ids above every id the flight used. :meth:`FlightMerger.holes`
and every output carry those ids, and so does **every** ``/holes`` record of the sidecar:
the replay's hole lists are kept (the holes themselves are shared, a record costs a list)
and written at :meth:`FlightMerger.finish`, once the pairing is known, at their own log
times. In a record from before two of the replay's holes were found to be one opening,
both carry the id of the hole they became (the tracker's ``merged``); each hole also
keeps the replay's own number as ``replay_id``. The last record repeats the final list
with the mapping (``"ids"``).
"""

from __future__ import annotations

import dataclasses
import logging
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from typing import Any, Final

from holescan.flightlog import (
    FlightLogError,
    LoggedDetections,
    LoggedHoles,
    LoggedMavlink,
    LoggedPose,
    annotations_message,
    detection_json,
    holes_geojson_message,
    jsonable,
)
from holescan.geotag import (
    AnnounceGate,
    FrameHoles,
    Hole,
    HolePipeline,
    IdMap,
    VehiclePose,
    carry_ids,
)
from holescan.ground.reprocessing.mapchunk import horizontal_gap_m
from holescan.ground.reprocessing.options import ReprocessOptions
from holescan.ground.reprocessing.plan import FlightPlan, PartitionTask
from holescan.ground.reprocessing.task import Box, FrameResult, PartitionResult, View, best_view
from holescan.link import TelemetryReplay
from holescan.mapping import MapLayers

__all__ = ["FlightMerger", "box_of", "read_views"]

_log = logging.getLogger(__name__)

_FLIGHT_HORIZON: Final = 60  # frames: a flight's detections are logged well within this

Writer = Callable[[str, Any, int], None]
"""``write(topic, obj, t_unix_ns)``: a new record for the sidecar (topic without prefix)."""
OnFrame = Callable[[FrameResult, FrameHoles, PartitionTask], None]


class FlightMerger:
    """Replays one flight (see the module docstring). Feed :meth:`add` the partitions in
    order, then call :meth:`finish`."""

    def __init__(
        self,
        plan: FlightPlan,
        opts: ReprocessOptions,
        write: Writer,
        on_frame: OnFrame | None = None,
    ) -> None:
        if plan.camera is None:
            raise FlightLogError(f"{plan.name}: no camera calibration: nothing to merge")
        self.plan = plan
        self.opts = opts
        self.write = write
        self.on_frame = on_frame
        self.pipeline = HolePipeline(plan.camera, plan.mount, errors=plan.errors)
        self.telemetry = TelemetryReplay()
        self.track: list[VehiclePose] = []
        self.flight_holes: tuple[Hole, ...] = ()
        self.flight_gate: AnnounceGate | None = None  # as the last /holes record gives it
        self.flight_tiers: dict[int, str] = {}  # the flight's own tiers (last record)
        self.flight_max_id = 0  # the highest hole id any of the flight's /holes records used
        self.id_map: IdMap | None = None  # set by finish(): this run's ids -> the flight's
        self.first_pose: VehiclePose | None = None
        self.best: dict[int, tuple[PartitionTask, int, Box]] = {}
        self._task: PartitionTask | None = None
        self._task_of: dict[int, PartitionTask] = {}  # frame index -> its partition
        self.damaged: list[str] = []
        self.frames_read = self.frames_detected = self.frames_unposed = 0
        self.detections = self.detect_errors = self.incomplete_frames = 0
        self.frames_no_depth = 0
        self.detect_ms = 0.0
        self.boot_to_unix_ns: int | None = None
        self._boot_minus_mono: int | None = None
        self._undecided: OrderedDict[int, FrameResult] = OrderedDict()
        self._boots: dict[int, int | None] = {}
        self._pose_queue: deque[tuple[int, int | None]] = deque()
        self._poses: dict[int, VehiclePose | None] = {}
        self._frames: dict[int, FrameResult] = {}
        self._order: deque[int] = deque()
        self.map_parts: list[MapLayers] = []
        self.map_frames = 0
        self.map_s = 0.0
        self.pose_gap_m: list[float] = []
        self._map_every = 0
        self._last_t_unix_ns = 0
        self._hole_records: list[tuple[int, tuple[Hole, ...]]] = []  # (t, holes) to write

    # -- feeding -----------------------------------------------------------------------------

    def add(self, task: PartitionTask, part: PartitionResult) -> None:
        """One partition's events (partitions of the flight in order)."""
        self._task = task
        self._map_every = task.map_every if task.map_anchor is not None else 0
        if part.map is not None:
            self.map_parts.append(part.map)
        self.map_frames += part.map_frames
        self.map_s += part.map_s
        self.damaged += part.damaged
        self.incomplete_frames += part.incomplete_frames
        for _, ev in part.events:
            if isinstance(ev, FrameResult):
                self._on_frame(ev)
            elif isinstance(ev, LoggedMavlink):
                if self.telemetry.feed(ev.packet):
                    self._pose_ready()
            elif isinstance(ev, LoggedPose):
                self.track.append(ev.pose)
                self.first_pose = self.first_pose or ev.pose
            elif isinstance(ev, LoggedDetections):
                if self.opts.frames == "flight":
                    self._decide(ev.frame_index)
            elif isinstance(ev, LoggedHoles):
                ids = [h["id"] for h in ev.holes if isinstance(h.get("id"), int)]
                self.flight_max_id = max([self.flight_max_id, *ids])
                try:
                    self.flight_tiers = ev.tiers() or {}
                    self.flight_gate = ev.announce_gate()
                    self.flight_holes = ev.as_holes()
                except FlightLogError as err:
                    _log.debug("in-flight hole list not comparable: %s", err)
        self._merge()

    def _on_frame(self, fr: FrameResult) -> None:
        t_boot = fr.t_boot_ns
        if t_boot is not None:
            self._boot_minus_mono = t_boot - fr.t_mono_ns
            self.boot_to_unix_ns = fr.t_unix_ns - t_boot
        elif self._boot_minus_mono is not None:
            t_boot = fr.t_mono_ns + self._boot_minus_mono
        if fr.pose is not None and self.first_pose is None:
            self.first_pose = fr.pose
        self.frames_read += 1
        assert self._task is not None
        self._task_of[fr.index] = self._task
        if self.opts.frames == "flight":
            self._undecided[fr.index] = fr
            self._boots[fr.index] = t_boot
        else:
            self._dispatch(fr, t_boot)

    def _decide(self, detected_index: int) -> None:
        """The flight detected frame ``detected_index``: merge it now. Frames no record named
        within :data:`_FLIGHT_HORIZON` frames were skipped in flight."""
        fr = self._undecided.pop(detected_index, None)
        if fr is not None:
            self._dispatch(fr, self._boots.pop(detected_index, None))
        while self._undecided and next(iter(self._undecided)) < detected_index - _FLIGHT_HORIZON:
            old, _ = self._undecided.popitem(last=False)
            self._boots.pop(old, None)
            self._task_of.pop(old, None)

    def _dispatch(self, fr: FrameResult, t_boot: int | None) -> None:
        self._order.append(fr.index)
        self._frames[fr.index] = fr
        self._pose_queue.append((fr.index, t_boot))
        self._pose_ready()

    def _pose_ready(self, final: bool = False) -> None:
        """Pose queued frames whose time the telemetry has passed (all of them when final)."""
        newest = self.telemetry.poses.newest_t_boot_ns
        q = self._pose_queue
        while q and (final or q[0][1] is None or (newest is not None and q[0][1] <= newest)):
            index, t_boot = q.popleft()
            self._poses[index] = self.telemetry.pose_at(t_boot)

    # -- merging -----------------------------------------------------------------------------

    def _merge(self) -> None:
        while self._order and self._order[0] in self._poses:
            index = self._order.popleft()
            fr = self._frames.pop(index)
            pose = self._poses.pop(index)
            task = self._task_of.pop(index)
            self.frames_detected += 1
            self.detect_ms += fr.detect_ms
            mapped = self._map_every and index % self._map_every == 0
            if mapped and fr.pose is not None and pose is not None:
                self.pose_gap_m.append(horizontal_gap_m(fr.pose, pose))
            if fr.no_depth:  # under the sensor's range (on the ground): not an error
                self.frames_no_depth += 1
                continue
            if fr.error is not None:
                self.detect_errors += 1
                _log.warning("%s: frame %d: detection failed: %s", self.plan.name, index, fr.error)
                continue
            self._merge_frame(fr, pose, task)

    def _merge_frame(self, fr: FrameResult, pose: VehiclePose | None, task: PartitionTask) -> None:
        t = fr.t_unix_ns
        self.detections += len(fr.detections)
        dets = [detection_json(d) for d in fr.detections]
        self.write("detections", {"frame_index": fr.index, "t_unix_ns": t, "detections": dets}, t)
        self.write("detections/annotations", annotations_message(fr.detections, t), t)
        step = self.pipeline.add(fr.index, fr.detections, lambda: pose)
        if step.refused:
            self.frames_unposed += 1
        if self.on_frame is not None:
            self.on_frame(fr, step, task)
        if not step.changed:
            return
        for h in step.changed:
            if h.best_frame_index == fr.index:
                self.best[h.id] = (task, fr.index, box_of(h.best_box))
        self._last_t_unix_ns = t
        self._hole_records.append((t, tuple(self.pipeline.holes())))

    def finish(self) -> None:
        """End of the flight: pose the frames still waiting for telemetry and merge them."""
        self._undecided.clear()
        self._pose_ready(final=True)
        self._merge()
        self.id_map = carry_ids(
            self.flight_holes,
            self.pipeline.holes(),
            self.pipeline.tracker.params,
            reference_max_id=self.flight_max_id,
        )
        for t, holes in self._hole_records:  # every record, with the flight's ids
            self._write_holes(t, holes)
        self._hole_records.clear()
        if self.pipeline.holes():  # the last record: the final holes and the mapping
            self._write_holes(self._last_t_unix_ns, self.pipeline.holes(), self._ids_record())

    def _write_holes(
        self, t: int, holes: Sequence[Hole], ids: dict[str, Any] | None = None
    ) -> None:
        """One ``/holes`` record of the replay's ``holes`` at ``t``, with the flight's ids
        (a hole fused later into another: the id of the one it became)."""
        assert self.id_map is not None
        merged = self.pipeline.tracker.merged()
        out = []
        for h in holes:
            own = h.id
            while own in merged and own not in self.id_map.ids:
                own = merged[own]
            carried = self.id_map.ids.get(own)
            if carried is None:  # the tracker keeps every hole: not expected
                _log.warning("%s: replay hole %d has no id to carry", self.plan.name, h.id)
                continue
            out.append({**jsonable(dataclasses.replace(h, id=carried)), "replay_id": h.id})
        doc: dict[str, Any] = {"holes": sorted(out, key=lambda d: (d["id"], d["replay_id"]))}
        if ids is not None:
            doc["ids"] = ids
        self.write("holes", doc, t)
        self.write("holes/geojson", holes_geojson_message(doc["holes"]), t)

    def _ids_record(self) -> dict[str, Any]:
        m = self.id_map
        assert m is not None
        return {
            "this_run_to_flight": {str(k): v for k, v in m.ids.items()},
            "new_in_reprocessing": m.new_ids,
            "first_new_id": m.first_new_id,
        }

    # -- what came out -----------------------------------------------------------------------

    def holes(self) -> list[Hole]:
        """The holes, with the flight's ids (:func:`geotag.carry_ids`; after :meth:`finish`)."""
        holes = self.pipeline.holes()
        return holes if self.id_map is None else self.id_map.apply(holes)

    def views(self, ids: set[int]) -> dict[int, View]:
        """The best views of holes ``ids`` (the flight's ids), read again from the logs."""
        back = {v: k for k, v in self.id_map.ids.items()} if self.id_map else {i: i for i in ids}
        own = {i: back[i] for i in ids if i in back and back[i] in self.best}
        got = read_views({back_id: self.best[back_id] for back_id in own.values()})
        return {i: got[b] for i, b in own.items() if b in got}

    def home(self) -> tuple[float, float, float] | None:
        if self.telemetry.home is not None:
            return self.telemetry.home
        p = self.first_pose
        return None if p is None else (p.lat_deg, p.lon_deg, p.alt_m - p.rel_alt_m)


def box_of(box: tuple[int, ...]) -> Box:
    return (int(box[0]), int(box[1]), int(box[2]), int(box[3]))


def read_views(where: dict[int, tuple[PartitionTask, int, Box]]) -> dict[int, View]:
    """hole id -> its best view, from (partition, frame index, box)."""
    out = {}
    for hid, (task, index, box) in where.items():
        view = best_view(task, index, box)
        if view is not None:
            out[hid] = view
        else:
            _log.warning("hole %d: its best view (frame %d) could not be read again", hid, index)
    return out
