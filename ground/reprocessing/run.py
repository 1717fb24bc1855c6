"""Reprocessing flights and campaigns: plan, run on Dask, merge in log order, write.

:func:`reprocess` (each flight on its own) and :func:`run_campaign` (the flights of an
operation, holes merged across them) share one engine (modules of this subpackage):

1. **plan** on the client (:mod:`.plan`): every log's chunk index, checked before any
   work is submitted; the logs are split along their chunks into partitions;
2. **detect** on Dask (:mod:`.engine`, :mod:`.task`): each task opens its log and reads
   its own byte ranges; only detections come back. Finished partitions are cached on disk
   (:mod:`.cache`), so a rerun does only what is missing;
3. **merge** on the client in log order (:mod:`.merge`): poses from the logged telemetry,
   holes through :class:`geotag.HolePipeline` as in flight; a campaign also merges every
   flight's sightings into one hole list (:mod:`.campaign`);
4. **write** per flight ``NAME_reprocess.mcap`` (sidecar, :mod:`.sidecar`),
   ``NAME_holes.*``, ``NAME_report.html``, ``NAME_reprocess.json`` (:mod:`.outputs`);
   ``summary.json`` for the run (a campaign adds ``campaign_holes.*`` and
   ``campaign_report.html``).

The output depends only on the logs and the parameters, not on the number of workers,
their timing, or which partitions came from the cache. Ctrl-C (``stop``) stops the
engine; what was merged is written, marked interrupted.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.flightlog import FlightLogError, read_log_layout, to_json
from holescan.geotag import FOUND_TIERS, AnnounceGate, Hole, VehiclePose
from holescan.ground.reprocessing.cache import PartitionCache
from holescan.ground.reprocessing.campaign import (
    CampaignHole,
    CampaignMerge,
    campaign_marks,
    campaign_summary,
)
from holescan.ground.reprocessing.engine import EngineStats, run_tasks
from holescan.ground.reprocessing.mapfiles import flight_map_outputs
from holescan.ground.reprocessing.merge import FlightMerger
from holescan.ground.reprocessing.options import (
    HoleMatch,
    Progress,
    ReprocessOptions,
    out_folder,
)
from holescan.ground.reprocessing.outputs import FlightResult, write_hole_outputs
from holescan.ground.reprocessing.plan import (
    FlightPlan,
    PartitionTask,
    group_flights,
    partition_flight,
    plan_flight,
    ref_name,
)
from holescan.ground.reprocessing.sidecar import Sidecar
from holescan.ground.station.marks import tier_with_mark
from holescan.outputs import atomic_output

__all__ = ["ReprocessResult", "reprocess", "run_campaign"]

_log = logging.getLogger(__name__)

CACHE_FOLDER = ".holescan-cache"


@dataclasses.dataclass(frozen=True)
class ReprocessResult:
    """A run: its flights, the campaign's holes (empty unless a campaign), the engine's
    numbers and where ``summary.json`` is."""

    flights: tuple[FlightResult, ...]
    campaign: tuple[CampaignHole, ...]
    summary_path: Path
    engine: EngineStats
    elapsed_s: float
    files: tuple[tuple[str, Path], ...] = ()

    @property
    def interrupted(self) -> bool:
        return any(f.interrupted for f in self.flights)

    @property
    def frames_per_s(self) -> float:
        n = sum(f.frames_detected for f in self.flights)
        return n / self.elapsed_s if self.elapsed_s > 0 else 0.0

    def lines(self) -> list[str]:
        out = [line for f in self.flights for line in f.lines()]
        if self.campaign:
            several = sum(len(h.flights) > 1 for h in self.campaign)
            out.append(
                f"campaign: {len(self.campaign)} holes, {several} seen by more than one flight"
            )
            out += [f"  wrote {path} ({kind})" for kind, path in self.files]
        out.append(
            f"{self.frames_per_s:.1f} frames/s over {self.elapsed_s:.1f} s; partitions: "
            f"{self.engine.computed} computed, {self.engine.cached} from the cache"
        )
        out.append(f"summary: {self.summary_path}")
        return out


class _Run:
    """The state of one run: plans, mergers, sidecars, results."""

    def __init__(self, plans: list[FlightPlan], out: Path, opts: ReprocessOptions, campaign: bool):
        self.plans, self.out, self.opts = plans, out, opts
        self.campaign = CampaignMerge() if campaign else None
        self.mergers: dict[int, FlightMerger] = {}
        self.sidecars: dict[int, Sidecar] = {}
        self.results: dict[int, FlightResult] = {}
        self.tasks: list[PartitionTask] = []
        self.left: dict[int, int] = {}
        self.cached: dict[int, int] = {}
        self.t0 = time.monotonic()
        # One map frame for the run (a campaign's flights share its cells): the first pose.
        firsts = [p.first_pose for p in plans if p.first_pose is not None]
        self.map_anchor = firsts[0] if firsts and opts.map_cell_m is not None else None
        for k, plan in enumerate(plans):
            self.tasks += partition_flight(plan, k, opts, self.map_anchor)
        for task in self.tasks:
            self.left[task.flight] = self.left.get(task.flight, 0) + 1

    def folder(self, plan: FlightPlan, create: bool = True) -> Path:
        single = len(self.plans) == 1 and self.campaign is None
        path = self.out if single else self.out / plan.name
        if create:
            path.mkdir(parents=True, exist_ok=True)
        return path

    def check_outputs(self) -> None:
        """Never write over an input or a log: before any work, refuse an output folder
        holding an input, or a sidecar path taken by a file reprocessing did not write."""
        inputs = [p for plan in self.plans for p in plan.files if isinstance(p, Path)]
        for plan in self.plans:
            folder = self.folder(plan, create=False)
            for p in inputs:
                if p.resolve().parent == folder.resolve():
                    raise InputError(f"{p} is a source log in {folder}: choose another --out")
            sidecar = folder / f"{plan.name}_reprocess.mcap"
            if sidecar.exists():
                try:
                    ours = "ground.reprocess" in read_log_layout(sidecar).metadata
                except FlightLogError:
                    ours = False
                if not ours:
                    raise InputError(
                        f"{sidecar} exists and is not a reprocessing sidecar: choose another --out"
                    )

    def open(self, k: int) -> FlightMerger:
        if k in self.mergers:
            return self.mergers[k]
        plan = self.plans[k]
        meta = {
            "version": _dist_version("holescan"),
            "params": to_json(self.opts.params).decode(),
            "frames": self.opts.frames,
            "sources": json.dumps([str(p) for p in plan.files]),
            "pose": "re-interpolated from /mavlink/raw at each frame's t_boot_ns",
        }
        path = self.folder(plan) / f"{plan.name}_reprocess.mcap"
        sidecar = Sidecar(path, self.opts.topic_prefix, meta).__enter__()
        on_frame = None
        if self.campaign is not None:
            merge, name = self.campaign, plan.name
            on_frame = lambda fr, step, task: merge.on_frame(name, fr, step, task)  # noqa: E731
        self.sidecars[k] = sidecar
        self.mergers[k] = FlightMerger(plan, self.opts, sidecar.write, on_frame)
        return self.mergers[k]

    def on_result(self, task: PartitionTask, result: Any, cached: bool) -> None:
        self.open(task.flight).add(task, result)
        self.cached[task.flight] = self.cached.get(task.flight, 0) + int(cached)
        self.left[task.flight] -= 1
        if self.left[task.flight] == 0:
            self.finish(task.flight, interrupted=False)

    def finish(self, k: int, interrupted: bool) -> None:
        plan = self.plans[k]
        merger = self.open(k) if plan.camera is not None else None
        sidecar = self.sidecars.get(k)
        if merger is not None:
            merger.finish()
        if sidecar is not None:
            sidecar.close(ok=True)
        self.results[k] = _flight_outputs(
            self.folder(plan),
            plan,
            merger,
            self.opts,
            interrupted=interrupted,
            outputs=(sidecar.path,) if sidecar is not None else (),
            partitions=sum(t.flight == k for t in self.tasks),
            cached=self.cached.get(k, 0),
            elapsed=time.monotonic() - self.t0,
            anchor=self.map_anchor,
        )

    def abort(self) -> None:
        """A failure: remove the sidecars not finished (no half-written outputs)."""
        for sc in self.sidecars.values():
            sc.close(ok=False)


def _flight_outputs(
    out: Path,
    plan: FlightPlan,
    fl: FlightMerger | None,
    opts: ReprocessOptions,
    *,
    interrupted: bool,
    outputs: tuple[Path, ...],
    partitions: int,
    cached: int,
    elapsed: float,
    anchor: tuple[float, float, float] | None = None,
) -> FlightResult:
    holes = tuple(fl.holes()) if fl is not None else ()
    gate, source = opts.gate_for(fl.flight_gate if fl is not None else None)
    marks = _flight_marks(fl, opts) if fl is not None else {}
    tiers = flight_tiers(holes, gate, opts, fl.flight_tiers if fl is not None else {}, marks)
    flight_holes = fl.flight_holes if fl is not None else ()
    told = fl.flight_tiers if fl is not None else {}
    flight_found = [
        h
        for h in flight_holes
        if told.get(h.id, "announced" if h.sightings >= opts.min_sightings else "candidate")
        in FOUND_TIERS
    ]
    by_id = {h.id: k for k, h in enumerate(holes)}
    dist = fl.id_map.distance_m if fl is not None and fl.id_map is not None else {}
    matches = [
        HoleMatch(k, by_id.get(h.id), dist.get(h.id, math.nan) if h.id in by_id else math.nan)
        for k, h in enumerate(flight_found)
    ]
    problems = (*plan.problems, *(fl.damaged if fl is not None else ()))
    result = FlightResult(
        name=plan.name,
        sources=plan.files,
        outputs=outputs,
        files=(),
        frames_read=fl.frames_read if fl else 0,
        frames_detected=fl.frames_detected if fl else 0,
        frames_unposed=fl.frames_unposed if fl else 0,
        detections=fl.detections if fl else 0,
        detect_errors=fl.detect_errors if fl else 0,
        frames_no_depth=fl.frames_no_depth if fl else 0,
        holes=holes,
        tiers=tiers,
        new_ids=tuple(fl.id_map.new_ids) if fl is not None and fl.id_map is not None else (),
        flight_holes=flight_holes,
        flight_matches=tuple(matches),
        flight_tiers=dict(told) if fl is not None and fl.flight_gate is not None else {},
        flight_same_ids=sum(
            m.found is not None and tiers[holes[m.found].id] in FOUND_TIERS for m in matches
        ),
        truncated=problems,
        interrupted=interrupted,
        partitions=partitions,
        partitions_cached=cached,
        detect_ms_mean=(fl.detect_ms / max(fl.frames_detected, 1)) if fl else 0.0,
        elapsed_s=elapsed,
    )
    facts = {
        "logs": ", ".join(ref_name(p) for p in plan.files),
        "reprocessed": f"{result.frames_detected} of {result.frames_read} frames"
        + (" (INTERRUPTED)" if interrupted else ""),
        "detector": f"{opts.params.mode.value}, searcher {opts.params.searcher.name}",
        "poses": "re-interpolated from the logged MAVLink telemetry",
        "in-flight holes reproduced": (
            f"{sum(m.found is not None for m in matches)} of {len(matches)}"
        ),
    }
    if fl is not None and fl.flight_gate is None:
        _log.info("%s: the log predates recorded tiers: default gate %s", plan.name, gate.summary())
    facts["tiers"] = f"{gate.summary()} ({source})"
    facts["ids"] = (
        "the flight's own (the same opening keeps its id); found only by reprocessing: "
        + (", ".join(str(i) for i in result.new_ids) or "none")
    )
    if marks:
        facts["operator marks"] = ", ".join(f"hole {i} {m}" for i, m in sorted(marks.items()))
    if problems:
        facts["cut off or damaged"] = "; ".join(problems)
    views = {}
    if fl is not None:
        got = fl.views({h.id for h in result.for_crew})
        views = {hid: (v.rgb, v.depth, v.box_in_crop) for hid, v in got.items()}
    mapped = None
    if fl is not None and anchor is not None:
        mapped = flight_map_outputs(
            out,
            plan.name,
            fl.map_parts,
            anchor,
            result.for_crew,
            opts,
            tiers=tiers,
            track=fl.track,
            home=fl.home(),
            boot_to_unix_ns=fl.boot_to_unix_ns,
            pose_gap_m=fl.pose_gap_m,
            map_s=fl.map_s,
            map_frames=fl.map_frames,
        )
    files = write_hole_outputs(
        out,
        plan.name,
        result.for_crew,
        views,
        fl.track if fl is not None else [],
        opts=opts,
        home=fl.home() if fl is not None else None,
        boot_to_unix_ns=fl.boot_to_unix_ns if fl is not None else None,
        facts=facts,
        title=f"holescan reprocessed flight: {plan.name}",
        tiers=tiers,
        search_map=mapped.section if mapped else None,
        overlay=mapped.overlay if mapped else None,
    )
    summary_path = out / f"{plan.name}_reprocess.json"
    if mapped is not None:
        files += mapped.files
    files.append(("summary", summary_path))
    result = dataclasses.replace(
        result,
        files=tuple(files),
        map_summary=mapped.summary if mapped else {},
        map_lines=mapped.lines if mapped else (),
    )
    _write_json(summary_path, result.summary())
    return result


def flight_tiers(
    holes: Sequence[Hole],
    gate: AnnounceGate,
    opts: ReprocessOptions,
    told: Mapping[int, str],
    marks: Mapping[int, str],
) -> dict[int, str]:
    """Every reprocessed hole's tier: the one gate (:meth:`geotag.AnnounceGate.tiers`, holes
    the flight announced staying announced while they pass), holes seen fewer than
    ``opts.min_sightings`` times candidates, then the operators' ``marks`` by these holes'
    ids (:func:`ground.station.marks.tier_with_mark`)."""
    announced = [i for i, t in told.items() if t == "announced"]
    tiers: dict[int, str] = dict(gate.tiers(holes, announced=announced))
    for h in holes:
        if h.sightings < opts.min_sightings:
            tiers[h.id] = "candidate"
        tiers[h.id] = tier_with_mark(tiers[h.id], marks.get(h.id))
    return tiers


def _flight_marks(fl: FlightMerger, opts: ReprocessOptions) -> dict[int, str]:
    """The operators' marks of one flight by its ids (:meth:`ReprocessOptions.marks_for`
    of its own holes; a log without them: the reprocessed holes, which then number alike)."""
    return opts.marks_for(fl.flight_holes or fl.holes())


def _write_json(path: Path, doc: Any) -> None:
    """A run's JSON summary, replaced atomically (the output-path rule)."""
    with atomic_output(path, force=True) as f:
        f.write((json.dumps(doc, indent=1, allow_nan=False) + "\n").encode())


def _tracks(run: _Run) -> dict[str, list[VehiclePose]]:
    return {
        plan.name: run.mergers[k].track if k in run.mergers else []
        for k, plan in enumerate(run.plans)
    }


def _campaign_gate(run: _Run) -> tuple[AnnounceGate, str]:
    gates = {m.flight_gate for m in run.mergers.values()}  # one gate when all flights agree
    return run.opts.gate_for(gates.pop() if len(gates) == 1 else None)


def _campaign_tiers(run: _Run, holes: list[CampaignHole]) -> list[CampaignHole]:
    """The campaign's holes with their tiers (:func:`flight_tiers`, the first flight's
    announced holes staying announced while they pass)."""
    first = run.mergers[min(run.mergers)].flight_tiers if run.mergers else {}
    per_flight = {run.plans[k].name: _flight_marks(m, run.opts) for k, m in run.mergers.items()}
    holes = campaign_marks(holes, per_flight)
    marks = {h.id: h.mark for h in holes if h.mark is not None}
    tiers = flight_tiers([h.hole for h in holes], _campaign_gate(run)[0], run.opts, first, marks)
    return [dataclasses.replace(h, tier=tiers[h.id]) for h in holes]


def _campaign_outputs(run: _Run, holes: list[CampaignHole]) -> list[tuple[str, Path]]:
    assert run.campaign is not None
    confirmed = [h.hole for h in holes if h.tier != "candidate"]
    got = run.campaign.views({h.id for h in confirmed})
    views = {hid: (v.rgb, v.depth, v.box_in_crop) for hid, v in got.items()}
    track: list[VehiclePose] = []  # every flight's, on the Unix clock like the holes' times
    breaks: list[int] = []
    for k in sorted(run.mergers):
        m = run.mergers[k]
        shift = m.boot_to_unix_ns or 0
        breaks.append(len(track))
        track += [dataclasses.replace(p, t_boot_ns=p.t_boot_ns + shift) for p in m.track]
    homes = [m.home() for m in run.mergers.values() if m.home() is not None]
    gate, source = _campaign_gate(run)
    facts = {
        "flights": ", ".join(p.name for p in run.plans),
        "frames": str(sum(r.frames_detected for r in run.results.values())),
        "holes seen by several flights": str(sum(len(h.flights) > 1 for h in holes)),
        "tiers": f"{gate.summary()} ({source})",
    }
    per = campaign_summary(holes, _tracks(run))["per_flight"]
    for name, c in per.items():
        r = next(r for r in run.results.values() if r.name == name)
        facts[f"flight {name}"] = (
            f"{r.frames_detected} frames, track {c['track_length_m']:.0f} m over "
            f"{c['track_duration_s'] / 60:.1f} min; {c['holes_seen']} holes seen "
            f"({c['also_seen_by_another_flight']} also by another flight)"
        )
    mapped = None
    if run.map_anchor is not None:
        mapped = flight_map_outputs(
            run.out,
            "campaign",
            [p for k in sorted(run.mergers) for p in run.mergers[k].map_parts],
            run.map_anchor,
            confirmed,
            run.opts,
            tiers={h.id: h.tier for h in holes},
            track=track,
            home=homes[0] if homes else None,
            boot_to_unix_ns=0,
        )
    files = write_hole_outputs(
        run.out,
        "campaign",
        confirmed,
        views,
        track,
        opts=run.opts,
        home=homes[0] if homes else None,
        boot_to_unix_ns=0,  # campaign hole times are Unix times
        facts=facts,
        track_breaks=breaks,
        title="holescan campaign: " + ", ".join(p.name for p in run.plans),
        tiers={h.id: h.tier for h in holes},
        search_map=mapped.section if mapped else None,
        overlay=mapped.overlay if mapped else None,
    )
    return files + list(mapped.files if mapped else ())


def _execute(
    logs: Iterable[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    opts: ReprocessOptions | None,
    campaign: bool,
    progress: Callable[[Progress], None] | None,
    stop: threading.Event | None,
) -> ReprocessResult:
    opts = opts or ReprocessOptions()
    groups = group_flights(logs)
    plans = sorted((plan_flight(g, opts) for g in groups), key=lambda p: (p.start_ns, p.name))
    out_dir = out_folder(out, [p for g in groups for p in g if isinstance(p, Path)])
    run = _Run(plans, out_dir, opts, campaign)
    run.check_outputs()
    cache = PartitionCache(out_dir / CACHE_FOLDER if opts.cache else None)
    t0 = time.monotonic()

    def tick(stats: EngineStats) -> None:
        if progress is not None:
            progress(
                Progress(
                    partitions_done=len(stats.results),
                    partitions_total=len(run.tasks),
                    partitions_cached=stats.cached,
                    frames_done=sum(r.frames for r in stats.results),
                    flights_done=len(run.results),
                    flights=len(plans),
                    elapsed_s=time.monotonic() - t0,
                    dashboard=stats.dashboard,
                )
            )

    try:
        for k in range(len(plans)):
            if run.left.get(k, 0) == 0:
                run.finish(k, interrupted=False)
        stats = run_tasks(run.tasks, opts, cache, run.on_result, stop=stop, tick=tick)
        for k in range(len(plans)):
            if k not in run.results:
                run.finish(k, interrupted=True)
    except BaseException:
        run.abort()
        raise
    elapsed = time.monotonic() - t0
    results = tuple(run.results[k] for k in range(len(plans)))
    holes: list[CampaignHole] = []
    files: list[tuple[str, Path]] = []
    doc: dict[str, Any] = {
        "holescan": _dist_version("holescan"),
        "engine": {
            "scheduler": opts.scheduler or f"local, {opts.workers} workers",
            "start_s": round(stats.start_s, 2),
            "partitions_computed": stats.computed,
            "partitions_cached": stats.cached,
            "elapsed_s": round(elapsed, 2),
        },
        "flights": [r.summary() for r in results],
    }
    if run.campaign is not None:
        run.campaign.carry_ids(
            [
                (run.plans[k].name, run.mergers[k].holes(), run.mergers[k].flight_max_id)
                for k in sorted(run.mergers)
            ]
        )
        holes = _campaign_tiers(run, run.campaign.holes(opts.min_sightings))
        files = _campaign_outputs(run, holes)
        doc["campaign"] = campaign_summary(holes, _tracks(run))
    summary = out_dir / "summary.json"
    _write_json(summary, doc)
    return ReprocessResult(results, tuple(holes), summary, stats, elapsed, tuple(files))


def reprocess(
    logs: Iterable[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    opts: ReprocessOptions | None = None,
    *,
    progress: Callable[[Progress], None] | None = None,
    stop: threading.Event | None = None,
) -> ReprocessResult:
    """Reprocess every flight among ``logs`` on its own (see the module docstring).

    One flight's files go to ``out`` directly, several flights' to ``out/NAME/``.

    Raises
    ------
    InputError : a missing file, one that is not a holescan flight log, ``out`` a file,
        read-only, or the folder of the logs.
    EngineError : the Dask scheduler cannot be reached, or a task failed.
    """
    return _execute(logs, out, opts, False, progress, stop)


def run_campaign(
    logs: Iterable[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    opts: ReprocessOptions | None = None,
    *,
    progress: Callable[[Progress], None] | None = None,
    stop: threading.Event | None = None,
) -> ReprocessResult:
    """Reprocess the flights of an operation (several vehicles and days) and merge their
    holes: every flight's outputs in ``out/NAME/``, and in ``out`` the campaign's hole
    files (``campaign_holes.*``), report and ``summary.json`` listing per hole the flights
    that saw it. Same errors as :func:`reprocess`."""
    return _execute(logs, out, opts, True, progress, stop)
