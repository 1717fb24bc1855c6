"""``holescan demo``: the whole system on a simulated sortie, scored against the truth.

One call runs what a real sortie runs, with no hardware:

* a synthetic rubble field with access holes and distractors, and a survey planned over it
  by :func:`missions.plan_survey` in the low dawn sun (:class:`sim._sortie.SimSortie`);
* the simulated autopilot (:class:`capture.SimAutopilot`) flying that survey and speaking
  MAVLink over loopback UDP (telemetry, TIMESYNC, SYSTEM_TIME);
* the capture daemon (:class:`capture._daemon.Flight`) with the simulated Xtion: MCAP flight
  log, detection worker, geotags, holes;
* the hole mission server (:class:`missions.HoleMissionServer`) announcing each hole that
  passes the announce gate by STATUSTEXT and sending its picture, to the ground station
  app (:class:`ground.GroundStation`, as ``holescan ground`` runs it) on a loopback link:
  it collects the holes, pictures and the hole mission into ``OUT/ground``.

It stops after one lap of the survey (or ``duration_s`` of capture; with ``min_frames``, not
before the camera delivered that many frames), then scores the holes
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
import functools
import json
import logging
import math
import os
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from holescan.capture import Flight, FlightConfig, FlightSummary, LiveMap
from holescan.demo._map import DemoMap, DemoMapper, views_and_track
from holescan.demo._scoring import FalseHole, TruthRow, frames_in_view, score_holes
from holescan.errors import InputError
from holescan.geotag import AnnounceGate, Hole, HoleView, Tier
from holescan.ground import GroundOptions, GroundStation, ReprocessOptions, write_hole_outputs
from holescan.missions import HoleMissionServer
from holescan.outputs import atomic_output
from holescan.sim import SimSortie, SortieParams, loop_length_m

__all__ = [
    "DEMO_SORTIE",
    "DemoOptions",
    "DemoProgress",
    "DemoResult",
    "FalseHole",
    "TruthRow",
    "default_demo_out",
    "run_demo",
]

_log = logging.getLogger(__name__)

DEMO_SORTIE = SortieParams(world_seed=3, size_m=(10.0, 10.0), n_access_holes=4)
"""The built-in sortie: 10 x 10 m surveyed in a 17 x 17 m field with four access holes
(three inside the surveyed area, one in the margin) and 38 distractors."""


@dataclasses.dataclass(frozen=True)
class DemoOptions:
    """What the demo flies.

    out : folder for everything (None: :func:`default_demo_out`, a new folder in the
        user's data folder). sortie : the simulated sortie.
    duration_s : seconds of capture (None: one lap of the survey).
    min_frames : capture goes on past ``duration_s`` until the simulated camera delivered
        this many frames (it renders as fast as the CPU lets it: on a slow or busy machine
        the duration alone gives few frames, and the vehicle flies on meanwhile).
    gate : when a hole is announced (served, sent, scored, written); weaker holes stay
        candidates. card_bytes_per_s : byte budget of the holes' pictures.
    match_m : a confirmed hole this close to a true access hole's centre (or inside its
        opening) found it, metres.
    min_frames_in_view : a true hole counts as seen by the camera when it was whole in at
        least this many frames.
    """

    out: Path | None = None
    sortie: SortieParams = DEMO_SORTIE
    duration_s: float | None = None
    min_frames: int = 0
    gate: AnnounceGate = dataclasses.field(default_factory=AnnounceGate)
    card_bytes_per_s: float = 1000.0
    match_m: float = 0.5
    min_frames_in_view: int = 3

    def __post_init__(self) -> None:
        if self.duration_s is not None and not self.duration_s > 0:
            raise InputError(f"duration must be > 0 s, got {self.duration_s}")
        if self.min_frames < 0:
            raise InputError(f"min_frames must be >= 0, got {self.min_frames}")
        if self.match_m <= 0 or self.min_frames_in_view < 1:
            raise InputError("min_frames_in_view >= 1 and match_m > 0 please")


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
    gate: AnnounceGate
    candidates: int = 0
    latency_s: tuple[float, ...] = ()
    card_bytes: int = 0
    match_m: float = 0.5
    cards_sent: int = 0
    pictures_at_ground: int = 0
    review: tuple[Hole, ...] = ()
    review_true: int = 0
    review_latency_s: tuple[float, ...] = ()
    area_m2: float = 0.0
    map_tiles_at_ground: int = 0
    search: DemoMap | None = None

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
            "holes_found": len(self.confirmed) + len(self.review),
            "holes_found_means": "announced + for review (FOUND_TIERS): what reached a person",
            "tiers": {
                "announced": [h.id for h in self.confirmed],
                "review": [h.id for h in self.review],
                "candidate": self.candidates,
            },
            "found": self.found,
            "missed": self.missed,
            "not_in_view": sum(r.status == "not in view" for r in self.truth),
            "false": len(self.false),
            "candidates": self.candidates,
            "review": [h.id for h in self.review],
            "review_true": self.review_true,
            "review_latency_s": list(self.review_latency_s),
            "area_m2": self.area_m2,
            "gate": dataclasses.asdict(self.gate),
            "latency_s": list(self.latency_s),
            "card_bytes": self.card_bytes,
            "cards_sent": self.cards_sent,
            "pictures_at_ground": self.pictures_at_ground,
            "map_tiles_at_ground": self.map_tiles_at_ground,
            "card_bytes_per_s": self.card_bytes / self.capture_s if self.capture_s else None,
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
            **(
                self.search.numbers([r.truth.id for r in self.truth if r.status != "found"])
                if self.search
                else {"searched_fraction": None, "missed_why": {}}
            ),
        }


# --------------------------------------------------------------------- ground station


class _Ground:
    """The ground station app (:class:`ground.GroundStation`, what ``holescan ground``
    runs) in-process on the demo's loopback link: holes, pictures, the hole mission."""

    def __init__(self, port: int, folder: Path) -> None:
        opts = GroundOptions(
            mavlink=f"udpin:127.0.0.1:{port}", out=folder, http_port=None, cot_url=None
        )
        self.station = GroundStation(opts).__enter__()
        self._told: set[int] = set()

    def take_new(self) -> tuple[str, ...]:
        """One line per hole the ground heard of since the last call."""
        _, holes, _ = self.station.state.snapshot()
        new = [h for h in holes if h.id not in self._told]
        self._told.update(h.id for h in new)
        return tuple(
            f"hole {h.id} ({h.vehicle_tier})"
            + (f" p_hole {h.p_hole:.2f}" if h.p_hole is not None else "")
            + f" at {h.lat_deg:.7f}, {h.lon_deg:.7f}"
            for h in new
        )

    def wait_complete(self, ids: set[int], revs: Mapping[int, int], timeout_s: float) -> bool:
        """Wait until every hole of ``ids`` is at the ground with its picture, in the
        downloaded mission, and every hole of ``revs`` (id -> the vehicle's newest card
        revision) has that card (the last facts the vehicle sent)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            _, holes, _ = self.station.state.snapshot()
            done = {h.id for h in holes if h.has_picture and h.seq is not None}
            rev = {h.id: h.card_rev for h in holes}
            if ids <= done and all(rev.get(i, 0) >= r for i, r in revs.items()):
                return True
            time.sleep(0.2)
        return False

    def close(self) -> None:
        self.station.__exit__(None, None, None)


# --------------------------------------------------------------------------- the flight


_RESULT = "demo.json"
"""The demo's numbers, in its output folder."""


def default_demo_out(data_home: Path | None = None) -> Path:
    """A new folder for one demo: ``DATA/holescan/demo/YYYYmmdd-HHMMSS`` in the user's data
    folder (``data_home``; None: ``$XDG_DATA_HOME``, else ``~/.local/share``), never the
    current folder (a clone's root would otherwise collect gigabytes of demo logs)."""
    if data_home is None:
        xdg = os.environ.get("XDG_DATA_HOME", "")
        data_home = Path(xdg) if os.path.isabs(xdg) else Path.home() / ".local" / "share"
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    out = data_home / "holescan" / "demo" / stamp
    k = 1
    while out.exists():
        k += 1
        out = out.with_name(f"{stamp}-{k}")
    return out


def _free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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
    out = opts.out or default_demo_out()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"cannot create {out}: {err.strerror}") from err
    if any(out.glob("flight_*.mcap")) or (out / _RESULT).exists():
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
    first_announced: dict[int, float] = {}
    first_review: dict[int, float] = {}
    card_bytes = cards_sent = 0
    mission_items: int | None = None
    mission_error: str | None = None
    pictures = map_tiles = 0
    capture_s = 0.0
    report("start", duration_s=duration)
    with contextlib.ExitStack() as stack:
        gcs = _Ground(gcs_port, out / "ground")
        stack.callback(gcs.close)
        server = stack.enter_context(
            HoleMissionServer(f"udpout:127.0.0.1:{gcs_port}", 1, home=home)
        )

        def on_holes(
            served: list[Hole],
            news: list[Hole],
            views: Mapping[int, HoleView],
            tiers: Mapping[int, Tier],
        ) -> None:
            server.update_holes(served)
            for h in sorted(news, key=lambda h: tiers[h.id] != "announced"):
                tier = tiers[h.id]
                if (said := server.announce(h, tier)) is not None:  # None: said already
                    announced.append(said)
                told = first_announced if tier == "announced" else first_review
                if h.id not in told:  # boot-clock span first sighting -> now
                    told[h.id] = (h.t_last_boot_ns - h.t_first_boot_ns) * 1e-9
                if h.id in views:
                    server.send_card(h, views[h.id].jpeg, views[h.id].why, tier)

        stack.enter_context(sortie)
        live_map = stack.enter_context(LiveMap(sortie.camera, sortie.mount))
        server.set_tiles(live_map)  # the live map's tiles down the same link, after cards
        cfg = FlightConfig(
            log_prefix=out / "flight",
            announce_min_p_hole=opts.gate.min_p_hole,
            announce_min_sightings=opts.gate.min_sightings,
            announce_min_span_s=opts.gate.min_span_s,
            review_min_p_hole=opts.gate.review_min_p_hole,
            config_record={
                "demo": {"sortie": dataclasses.asdict(opts.sortie), "duration_s": duration}
            },
        )
        flight = Flight(
            cfg,
            sortie.source,
            sortie.camera,
            mavlink=sortie.mavlink,
            on_holes=on_holes,
            on_frame=live_map.offer,
        )
        flight.stop = stop
        t_first: list[float] = []

        def watch() -> None:
            while not stop.wait(0.5):
                c = flight.counters
                if c.frames_captured and not t_first:
                    t_first.append(time.monotonic())
                elapsed = time.monotonic() - t_first[0] if t_first else 0.0
                if elapsed >= duration and c.frames_captured >= opts.min_frames:
                    stop.set()
                report(
                    "flying",
                    elapsed_s=min(elapsed, duration),
                    duration_s=duration,
                    frames=c.frames_captured,
                    detected=c.frames_detected,
                    holes=len(opts.gate.select(flight.tracker.holes(), first_announced)),
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
            holes=len(opts.gate.select(summary.holes, first_announced)),
            announcements=gcs.take_new(),
        )
        served_ids = {h.id for h in opts.gate.select(summary.holes, first_announced)}
        live_map.close()  # the last changes cut into tiles, all due now
        live_map.finish()
        server.flush_cards(timeout_s=30.0)
        live_map.flush(timeout_s=10.0)
        server.flush_cards(timeout_s=5.0)
        if not gcs.wait_complete(served_ids, server.card_revisions(), timeout_s=30.0):
            mission_error = (
                "not every announced hole reached the ground with its picture and last facts"
            )
        _, ground_holes, _ = gcs.station.state.snapshot()
        mission_items = sum(h.seq is not None for h in ground_holes)
        pictures = sum(h.has_picture for h in ground_holes if h.id in served_ids)
        map_tiles = sum(int(gcs.station.map_store.summary()[k]) for k in ("cov", "ortho"))
        received = tuple(announced)
        card_bytes, cards_sent = server.cards.bytes_sent, server.cards.cards_sent
    interrupted = capture_s < duration - 1.0
    confirmed = tuple(opts.gate.select(summary.holes, first_announced))
    final = opts.gate.tiers(summary.holes, first_announced)  # the one gate, as the log has it
    review = tuple(h for h in summary.holes if final[h.id] == "review")
    truth = sortie.truth
    in_view = frames_in_view(sortie.sources)
    scored = functools.partial(
        score_holes, match_m=opts.match_m, min_frames_in_view=opts.min_frames_in_view
    )
    rows, false = scored(confirmed, truth, sortie.world, anchor, in_view)
    log_files = tuple(summary.log.files)
    mapper = DemoMapper(sortie.world, opts.sortie, sortie.camera, sortie.mount)
    views, track, boot_to_unix = views_and_track(log_files, (*confirmed, *review), mapper.add)
    tiers = {h.id: "announced" for h in confirmed} | {h.id: "review" for h in review}
    search = mapper.finish(out, (*confirmed, *review), boot_to_unix, tiers)
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
    review_rows, _ = scored(review, truth, sortie.world, anchor, in_view)
    files = write_hole_outputs(
        out,
        "flight",
        (*confirmed, *review),
        views,  # type: ignore[arg-type]
        track,
        opts=ReprocessOptions(workers=0, min_sightings=opts.gate.min_sightings),
        home=home,
        boot_to_unix_ns=boot_to_unix,
        truth=[(f"true hole {t.id}", t.lat_deg, t.lon_deg) for t in truth],
        facts=facts,
        title="holescan demo: simulated dawn survey",
        search_map=search.section,
        overlay=next((path for kind, path in search.files if kind == "map"), None),
        tiers=tiers,
    )
    result = DemoResult(
        out=out,
        log_files=log_files,
        files=(*search.files, *files),
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
        gate=opts.gate,
        candidates=len(summary.holes) - len(confirmed) - len(review),
        review=review,
        review_true=sum(r.status == "found" for r in review_rows),
        review_latency_s=tuple(first_review[h.id] for h in review if h.id in first_review),
        area_m2=opts.sortie.size_m[0] * opts.sortie.size_m[1],
        latency_s=tuple(first_announced[h.id] for h in confirmed if h.id in first_announced),
        card_bytes=card_bytes,
        cards_sent=cards_sent,
        pictures_at_ground=pictures,
        map_tiles_at_ground=map_tiles,
        match_m=opts.match_m,
        search=search,
    )
    path = out / _RESULT
    with atomic_output(path) as f:
        f.write((json.dumps(result.numbers(), indent=1) + "\n").encode())
    return dataclasses.replace(result, files=(*result.files, ("result", path)))
