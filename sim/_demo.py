"""``holescan demo``: the whole system on a simulated sortie, scored against the truth.

One call runs what a real sortie runs, with no hardware:

* a synthetic rubble field with access holes and distractors, and a survey planned over it
  by :func:`missions.plan_survey` in the low dawn sun (:class:`sim._sortie.SimSortie`);
* the simulated autopilot (:class:`capture.SimAutopilot`) flying that survey and speaking
  MAVLink over loopback UDP (telemetry, TIMESYNC, SYSTEM_TIME);
* the capture daemon (:class:`capture._daemon.Flight`) with the simulated Xtion: MCAP flight
  log, detection worker, geotags, holes;
* the hole mission server (:class:`missions.HoleMissionServer`) announcing each confirmed
  hole by STATUSTEXT to a ground station, which is played by a pymavlink peer here: it
  prints the announcements as they come and downloads the hole mission at the end.

It stops after one lap of the survey (or ``duration_s`` of capture), then scores the holes
the flight confirmed against the simulator's truth: every true access hole the camera saw
whole in at least ``min_frames_in_view`` frames is found (a confirmed hole within
``match_m`` of its centre or inside its opening) or missed; confirmed holes matching no
true hole are false (the nearest feature of the world is named). It writes the hole files
and the report beside the flight log.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import json
import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pymap3d

from capture import Flight, FlightConfig, FlightSummary, LoggedFrame, LoggedPose, read_flight_log
from geotag import Hole, VehiclePose
from ground import ReprocessOptions, write_hole_outputs
from holescan_errors import InputError
from missions import HoleMissionServer, connect, download_mission
from sim._sortie import SimSortie, SortieParams, TrueHole, loop_length_m
from sim._world import RubbleWorld

__all__ = [
    "DEMO_SORTIE",
    "DemoOptions",
    "DemoProgress",
    "DemoResult",
    "FalseHole",
    "TruthRow",
    "format_result",
    "run_demo",
]

_log = logging.getLogger(__name__)

DEMO_SORTIE = SortieParams(world_seed=3, size_m=(10.0, 10.0), n_access_holes=4)
"""The built-in sortie: 10 x 10 m surveyed in a 17 x 17 m field with four access holes
(three inside the surveyed area, one in the margin) and 38 distractors."""


@dataclasses.dataclass(frozen=True)
class DemoOptions:
    """What the demo flies.

    out : folder for everything (None: a new ``holescan-demo-YYYYmmdd-HHMMSS`` folder in
        the current directory). sortie : the simulated sortie.
    duration_s : seconds of capture (None: one lap of the survey).
    min_sightings : a hole is confirmed (announced, scored, written) when seen this often.
    match_m : a confirmed hole this close to a true access hole's centre (or inside its
        opening) found it, metres.
    min_frames_in_view : a true hole counts as seen by the camera when it was whole in at
        least this many frames.
    """

    out: Path | None = None
    sortie: SortieParams = DEMO_SORTIE
    duration_s: float | None = None
    min_sightings: int = 3
    match_m: float = 0.5
    min_frames_in_view: int = 3

    def __post_init__(self) -> None:
        if self.duration_s is not None and not self.duration_s > 0:
            raise InputError(f"duration must be > 0 s, got {self.duration_s}")
        if self.min_sightings < 1 or self.match_m <= 0 or self.min_frames_in_view < 1:
            raise InputError("min_sightings, min_frames_in_view >= 1 and match_m > 0 please")


@dataclasses.dataclass(frozen=True)
class DemoProgress:
    """Where the demo is. phase : ``world``, ``start``, ``flying``, ``scoring``.

    elapsed_s / duration_s : capture time so far / planned. announcements : STATUSTEXTs
    the ground station received since the last report.
    """

    phase: str
    elapsed_s: float = 0.0
    duration_s: float = 0.0
    frames: int = 0
    detected: int = 0
    holes: int = 0
    announcements: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class TruthRow:
    """One true access hole and what the flight made of it.

    status : ``found``, ``missed`` (seen whole in enough frames, not found) or
    ``not in view``. x_m, y_m : position in the field (east, north of its south-west corner).
    hole_id, error_m, sightings : the confirmed hole that found it, its horizontal distance
    to the truth, its sightings.
    """

    truth: TrueHole
    frames_in_view: int
    status: str
    hole_id: int | None
    error_m: float
    sightings: int


@dataclasses.dataclass(frozen=True)
class FalseHole:
    """A confirmed hole that is no true access hole; ``nearest`` names the closest feature
    of the world (a distractor kind, or an access hole farther than the match distance)."""

    hole: Hole
    nearest: str
    distance_m: float


@dataclasses.dataclass(frozen=True)
class DemoResult:
    out: Path
    log_files: tuple[Path, ...]
    files: tuple[tuple[str, Path], ...]
    truth: tuple[TruthRow, ...]
    false: tuple[FalseHole, ...]
    confirmed: tuple[Hole, ...]
    summary: FlightSummary
    capture_s: float
    announcements: tuple[str, ...]
    mission_items: int | None
    mission_error: str | None
    elapsed_s: float
    interrupted: bool
    world_features: dict[str, int]
    min_sightings: int
    match_m: float

    @property
    def found(self) -> int:
        return sum(r.status == "found" for r in self.truth)

    @property
    def missed(self) -> int:
        return sum(r.status == "missed" for r in self.truth)

    def numbers(self) -> dict[str, Any]:
        errors = [r.error_m for r in self.truth if r.status == "found"]
        c = self.summary.counters
        return {
            "found": self.found,
            "missed": self.missed,
            "not_in_view": sum(r.status == "not in view" for r in self.truth),
            "false": len(self.false),
            "position_error_m": {
                "mean": float(np.mean(errors)) if errors else None,
                "max": max(errors) if errors else None,
            },
            "truth": [
                {
                    "truth_id": r.truth.id,
                    "x_m": r.truth.x_m,
                    "y_m": r.truth.y_m,
                    "status": r.status,
                    "frames_in_view": r.frames_in_view,
                    "hole_id": r.hole_id,
                    "error_m": None if math.isnan(r.error_m) else r.error_m,
                }
                for r in self.truth
            ],
            "false_holes": [
                {"hole_id": f.hole.id, "nearest": f.nearest, "distance_m": f.distance_m}
                for f in self.false
            ],
            "frames_captured": c.frames_captured,
            "frames_detected": c.frames_detected,
            "frames_unposed": c.frames_unposed,
            "capture_s": self.capture_s,
            "elapsed_s": self.elapsed_s,
            "announcements": list(self.announcements),
            "mission_items": self.mission_items,
            "interrupted": self.interrupted,
            "log_files": [str(p) for p in self.log_files],
            "files": {k: str(p) for k, p in self.files},
        }


# --------------------------------------------------------------------- ground station


class _GroundStation:
    """A pymavlink peer playing the ground station: collects STATUSTEXTs, then downloads
    the hole mission from the companion computer (component 191)."""

    def __init__(self, port: int) -> None:
        self.link = f"udpin:127.0.0.1:{port}"
        self.conn = connect(self.link, source_system=255, source_component=190)
        self.texts: list[str] = []
        self._new: list[str] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="demo-gcs", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.conn.recv_match(type="STATUSTEXT", blocking=True, timeout=0.2)
            if msg is None:
                continue
            text = str(msg.text).rstrip("\x00")
            with self._lock:
                self.texts.append(text)
                self._new.append(text)

    def take_new(self) -> tuple[str, ...]:
        with self._lock:
            new, self._new = tuple(self._new), []
            return new

    def stop_listening(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def download(self, sysid: int, compid: int) -> int:
        """Download the served mission; returns the number of hole waypoints (home excluded)."""
        items = download_mission(
            self.conn,
            target_system=sysid,
            target_component=compid,
            heartbeat_timeout_s=5.0,
        )
        return max(len(items) - 1, 0)

    def close(self) -> None:
        self.stop_listening()
        self.conn.close()


# ------------------------------------------------------------------------------ scoring


def _frames_in_view(sortie: SimSortie) -> Counter[int]:
    """World hole id -> frames that showed the whole opening (not cut by the border)."""
    seen: Counter[int] = Counter()
    for src in sortie.sources:
        for _, boxes in src.truth.values():
            for b in boxes:
                if not b.iscrowd:
                    seen[b.hole_id] += 1
    return seen


def _en(world_anchor: Any, lat: float, lon: float) -> tuple[float, float]:
    x, y, _ = pymap3d.geodetic2enu(
        lat,
        lon,
        world_anchor.alt_m,
        world_anchor.lat_deg,
        world_anchor.lon_deg,
        world_anchor.alt_m,
    )
    return float(x), float(y)


def score(
    confirmed: Sequence[Hole],
    truth: Sequence[TrueHole],
    world: RubbleWorld,
    anchor: Any,
    in_view: Counter[int],
    opts: DemoOptions,
) -> tuple[tuple[TruthRow, ...], tuple[FalseHole, ...]]:
    """Match confirmed holes to the true access holes, nearest pairs first, each used once.

    A confirmed hole finds a true one when it lies within ``opts.match_m`` of its centre or
    inside its opening (a big hole seen cut by the image border is placed off its centre,
    yet a crew sent there stands at the hole). Unmatched confirmed holes are false; the
    nearest feature of the world is named.
    """
    from shapely.geometry import Point, Polygon

    xy = [_en(anchor, h.lat_deg, h.lon_deg) for h in confirmed]
    pairs = []
    for i, t in enumerate(truth):
        opening = Polygon(world.holes[t.id].opening)
        for j, (x, y) in enumerate(xy):
            d = math.hypot(x - t.x_m, y - t.y_m)
            if d <= opts.match_m or opening.contains(Point(x, y)):
                pairs.append((d, i, j))
    matched: dict[int, tuple[int, float]] = {}
    used: set[int] = set()
    for d, i, j in sorted(pairs):
        if i not in matched and j not in used:
            matched[i] = (j, d)
            used.add(j)
    rows = []
    for i, t in enumerate(truth):
        frames = in_view.get(t.id, 0)
        if i in matched:
            j, d = matched[i]
            h = confirmed[j]
            rows.append(TruthRow(t, frames, "found", h.id, d, h.sightings))
        else:
            status = "missed" if frames >= opts.min_frames_in_view else "not in view"
            rows.append(TruthRow(t, frames, status, None, math.nan, 0))
    false = []
    for j, h in enumerate(confirmed):
        if j in used:
            continue
        x, y = xy[j]
        best = ("nothing", math.inf)
        for feature in world.holes:
            d = math.hypot(feature.centre_xy[0] - x, feature.centre_xy[1] - y)
            if d < best[1]:
                kind = "access hole" if feature.is_access else feature.kind.replace("_", " ")
                best = (kind, d)
        false.append(FalseHole(h, best[0], best[1]))
    return tuple(rows), tuple(false)


# --------------------------------------------------------------------------- the flight


def _default_out() -> Path:
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    out = Path.cwd() / f"holescan-demo-{stamp}"
    k = 1
    while out.exists():
        k += 1
        out = Path.cwd() / f"holescan-demo-{stamp}-{k}"
    return out


def _free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _views_and_track(
    files: Sequence[Path], holes: Sequence[Hole]
) -> tuple[
    dict[int, tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], tuple[int, ...]]],
    list[VehiclePose],
    int | None,
]:
    """Read the flight log once: each hole's best view (cropped), the track, boot -> Unix."""
    wanted: dict[int, list[Hole]] = {}
    for h in holes:
        if h.best_frame_index is not None:
            wanted.setdefault(h.best_frame_index, []).append(h)
    views: dict[int, tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], tuple[int, ...]]] = {}
    track: list[VehiclePose] = []
    boot_to_unix: int | None = None
    for rec in read_flight_log(files, kinds={LoggedFrame, LoggedPose}):
        if isinstance(rec, LoggedPose):
            track.append(rec.pose)
            boot_to_unix = rec.t_unix_ns - rec.pose.t_boot_ns
            continue
        assert isinstance(rec, LoggedFrame)
        for h in wanted.get(rec.frame.index, ()):
            x, y, w, ht = (int(v) for v in h.best_box)
            m = max(w, ht) + 24
            H, W = rec.frame.depth.shape
            x0, y0, x1, y1 = max(x - m, 0), max(y - m, 0), min(x + w + m, W), min(y + ht + m, H)
            views[h.id] = (
                rec.frame.rgb[y0:y1, x0:x1].copy(),
                rec.frame.depth[y0:y1, x0:x1].copy(),
                (x - x0, y - y0, w, ht),
            )
    return views, track, boot_to_unix


def run_demo(
    opts: DemoOptions | None = None,
    *,
    progress: Callable[[DemoProgress], None] | None = None,
    stop: threading.Event | None = None,
) -> DemoResult:
    """Fly the simulated sortie, score it against the truth, write the files.

    ``stop`` ends the flight early (cleanly: the log is closed, what was found is scored).
    """
    opts = opts or DemoOptions()
    t_start = time.monotonic()
    out = opts.out or _default_out()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"cannot create {out}: {err.strerror}") from err
    if any(out.glob("flight_*.mcap")):
        raise InputError(f"{out} already holds a demo flight: choose another --out folder")
    stop = stop or threading.Event()

    def report(phase: str, **kw: Any) -> None:
        if progress is not None:
            progress(DemoProgress(phase, **kw))

    report("world")
    sortie = SimSortie(opts.sortie)
    assert sortie.world is not None and sortie.path is not None
    duration = opts.duration_s or loop_length_m(sortie.path) / sortie.path.speed_m_s
    anchor = opts.sortie.anchor
    home = (anchor.lat_deg, anchor.lon_deg, anchor.alt_m)
    gcs_port = _free_udp_port()
    announced: list[str] = []
    mission_items: int | None = None
    mission_error: str | None = None
    capture_s = 0.0
    report("start", duration_s=duration)
    with contextlib.ExitStack() as stack:
        gcs = _GroundStation(gcs_port)
        stack.callback(gcs.close)
        server = stack.enter_context(
            HoleMissionServer(f"udpout:127.0.0.1:{gcs_port}", 1, home=home)
        )

        def on_holes(confirmed: list[Hole], news: list[Hole]) -> None:
            server.update_holes(confirmed)
            announced.extend(server.announce(h) for h in news)

        stack.enter_context(sortie)
        cfg = FlightConfig(
            log_prefix=out / "flight",
            announce_min_sightings=opts.min_sightings,
            config_record={
                "demo": {"sortie": dataclasses.asdict(opts.sortie), "duration_s": duration}
            },
        )
        flight = Flight(
            cfg, sortie.source, sortie.camera, mavlink=sortie.mavlink, on_holes=on_holes
        )
        flight.stop = stop
        t_first: list[float] = []

        def watch() -> None:
            while not stop.wait(0.5):
                c = flight.counters
                if c.frames_captured and not t_first:
                    t_first.append(time.monotonic())
                elapsed = time.monotonic() - t_first[0] if t_first else 0.0
                if elapsed >= duration:
                    stop.set()
                report(
                    "flying",
                    elapsed_s=min(elapsed, duration),
                    duration_s=duration,
                    frames=c.frames_captured,
                    detected=c.frames_detected,
                    holes=len(flight.tracker.confirmed(opts.min_sightings)),
                    announcements=gcs.take_new(),
                )

        watcher = threading.Thread(target=watch, name="demo-watch", daemon=True)
        watcher.start()
        try:
            summary = flight.run()
        finally:
            stop.set()
            watcher.join(timeout=2.0)
        capture_s = time.monotonic() - t_first[0] if t_first else 0.0
        report(
            "scoring",
            elapsed_s=min(capture_s, duration),
            duration_s=duration,
            frames=summary.counters.frames_captured,
            detected=summary.counters.frames_detected,
            holes=sum(h.sightings >= opts.min_sightings for h in summary.holes),
            announcements=gcs.take_new(),
        )
        gcs.stop_listening()
        time.sleep(0.3)  # the last STATUSTEXTs in flight on the loopback link
        try:
            mission_items = gcs.download(1, server.compid)
        except Exception as err:  # shown in the result: the demo still reports the rest
            mission_error = f"{type(err).__name__}: {err}"
            _log.warning("ground station could not download the hole mission: %s", err)
        received = tuple(gcs.texts)
    interrupted = capture_s < duration - 1.0
    confirmed = tuple(h for h in summary.holes if h.sightings >= opts.min_sightings)
    truth = sortie.truth
    rows, false = score(confirmed, truth, sortie.world, anchor, _frames_in_view(sortie), opts)
    log_files = tuple(summary.log.files)
    views, track, boot_to_unix = _views_and_track(log_files, confirmed)
    kinds = Counter(str(h.kind) for h in sortie.world.holes)
    facts = {
        "flight log": ", ".join(p.name for p in log_files),
        "sortie": f"{opts.sortie.size_m[0]:g} x {opts.sortie.size_m[1]:g} m survey at "
        f"{opts.sortie.altitude_m:g} m, world seed {opts.sortie.world_seed}",
        "world": ", ".join(f"{n} {k}" for k, n in sorted(kinds.items())),
        "against the truth": f"found {sum(r.status == 'found' for r in rows)}, missed "
        f"{sum(r.status == 'missed' for r in rows)}, false {len(false)} (a find: inside a "
        f"true opening or within {opts.match_m:g} m of its centre)",
    }
    files = write_hole_outputs(
        out,
        "flight",
        confirmed,
        views,  # type: ignore[arg-type]
        track,
        opts=ReprocessOptions(workers=0, min_sightings=opts.min_sightings),
        home=home,
        boot_to_unix_ns=boot_to_unix,
        truth=[(f"true hole {t.id}", t.lat_deg, t.lon_deg) for t in truth],
        facts=facts,
        title="holescan demo: simulated dawn survey",
    )
    result = DemoResult(
        out=out,
        log_files=log_files,
        files=tuple(files),
        truth=rows,
        false=false,
        confirmed=confirmed,
        summary=summary,
        capture_s=capture_s,
        announcements=received,
        mission_items=mission_items,
        mission_error=mission_error,
        elapsed_s=time.monotonic() - t_start,
        interrupted=interrupted,
        world_features=dict(kinds),
        min_sightings=opts.min_sightings,
        match_m=opts.match_m,
    )
    path = out / "demo.json"
    path.write_text(json.dumps(result.numbers(), indent=1) + "\n")
    return dataclasses.replace(result, files=(*result.files, ("result", path)))


# ------------------------------------------------------------------------------ output


def format_result(r: DemoResult) -> list[str]:
    """What the demo prints at the end."""
    c = r.summary.counters
    n_access = r.world_features.get("access", 0)
    distractors = sum(r.world_features.values()) - n_access
    cut = " (stopped early)" if r.interrupted else ""
    lines = [
        f"holescan demo: {r.capture_s:.0f} s of a simulated dawn survey{cut}, "
        f"{n_access} access holes and {distractors} distractors in the field",
        f"frames: {c.frames_captured} captured ({c.frames_captured / max(r.capture_s, 1e-9):.1f}"
        f"/s), {c.frames_detected} detected, {c.frames_unposed} not posed at capture",
        f"holes against the simulator's truth (a confirmed hole, >= {r.min_sightings} "
        f"sightings, inside a true opening or within {r.match_m:g} m of its centre finds it):",
    ]
    for row in r.truth:
        t = row.truth
        where = f"true hole {t.id} at ({t.x_m:.1f}, {t.y_m:.1f}) m, {t.major_m:.2f} m wide"
        if row.status == "found":
            score = next(h.score for h in r.confirmed if h.id == row.hole_id)
            lines.append(
                f"  {where}: FOUND as hole {row.hole_id} (score {score:.2f}), "
                f"{100 * row.error_m:.0f} cm off, {row.sightings} sightings"
            )
        elif row.status == "missed":
            lines.append(f"  {where}: MISSED (whole in view in {row.frames_in_view} frames)")
        else:
            lines.append(f"  {where}: not in view (outside what the survey saw)")
    for f in r.false:
        lines.append(
            f"  hole {f.hole.id}: FALSE (score {f.hole.score:.2f}, {f.hole.sightings} sightings;"
            f" nearest feature: {f.nearest}, {f.distance_m:.2f} m)"
        )
    errors = [row.error_m for row in r.truth if row.status == "found"]
    in_view = sum(row.status != "not in view" for row in r.truth)
    err = (
        f"; position error mean {100 * float(np.mean(errors)):.0f} cm, max "
        f"{100 * max(errors):.0f} cm"
        if errors
        else ""
    )
    lines.append(
        f"  => found {r.found} of {in_view} in view, missed {r.missed}, false {len(r.false)}" + err
    )
    gcs = f"ground station: {len(r.announcements)} STATUSTEXT announcements"
    if r.mission_items is not None:
        gcs += f", downloaded a mission of {r.mission_items} hole waypoints (component 191)"
    else:
        gcs += f", mission download failed ({r.mission_error})"
    lines.append(gcs)
    lines.append(f"files in {r.out}:")
    lines += [f"  flight log  {p}" for p in r.log_files]
    lines += [f"  {kind:<11} {p}" for kind, p in r.files]
    lines.append(
        f"reprocess it: holescan reprocess {' '.join(str(p) for p in r.log_files)} "
        f"--out {r.out / 'reprocessed'}"
    )
    lines.append(f"({r.elapsed_s:.0f} s in all)")
    return lines
