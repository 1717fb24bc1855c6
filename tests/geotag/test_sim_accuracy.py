"""Geotag accuracy of the whole flight pipeline over the simulated world (issue 4).

A short simulated sortie at 3 m over a rubble world with known access holes: the simulated
autopilot flies a survey with realistic attitude motion (thrust tilt in the turns, a
1.5 deg wobble) and a boot clock 1234.5 s off the companion's, drifting 15 ppm; the
simulated Xtion renders each frame from the true pose at its capture time. GPS error is
switched off (the simulated position is exact and reports 1 mm accuracy), so what remains
is the error the pipeline adds: clock synchronisation, telemetry interpolation, geometry.

Figures (printed; run with ``-s`` to see them):

* *added*: each sighting the daemon geotagged vs the same detection geotagged with the
  true pose of its frame: the pipeline's own error (issue 4: median <= 0.10 m);
* *sighting*: each sighting vs the true hole's centre (adds where the detector put the
  opening's centre);
* *hole*: each merged hole vs the true hole: every access hole wholly in view in enough
  frames must be reported exactly once (no misses, no duplicates).
"""

from __future__ import annotations

import logging
import math
import statistics
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d
import pytest

from holescan.capture import Flight, FlightConfig
from holescan.flightlog import LoggedDetections, read_flight_log
from holescan.geotag import CIRCLE_95_PER_SIGMA, HoleSighting, geotag_frame
from holescan.sim import SimSortie, SortieParams, TrueHole

PARAMS = SortieParams(
    size_m=(4.0, 4.0),
    world_seed=15,
    n_access_holes=4,
    fps=10.0,
    eph_m=0.001,
    clock_offset_s=1234.5,
    drift_ppm=15.0,
    wobble_deg=1.5,
)
DURATION_S = 25.0
MIN_FRAMES = 150
"""The sortie lasts DURATION_S of flight *and* MIN_FRAMES frames: the vehicle flies in real
time (25 s cover the survey's holes) while the renderer delivers what the CPU lets it
(6-10 frames/s alone; on a loaded 2-core machine 1-3, when 25 s gave a hole 4 views), so
on a slow machine the flight goes on until the holes had as many views as on a fast one."""
HANG_GUARD_S = 300.0
MIN_SIGHTINGS = 3  # the daemon's announce_min_sightings: "reported"
IN_VIEW_FRAMES = 5  # a hole wholly in view in this many frames must be reported
MATCH_M = 0.5


def horizontal_m(lat: float, lon: float, t: TrueHole) -> float:
    e, n, _ = pymap3d.geodetic2enu(lat, lon, t.alt_m, t.lat_deg, t.lon_deg, t.alt_m)
    return math.hypot(float(e), float(n))


def nearest(lat: float, lon: float, truth: tuple[TrueHole, ...]) -> tuple[float, TrueHole]:
    return min(((horizontal_m(lat, lon, t), t) for t in truth), key=lambda p: p[0])


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


@pytest.mark.timeout(HANG_GUARD_S + 100)
@pytest.mark.slow
def test_pipeline_geotag_error_and_every_hole_once(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.ERROR, logger="holescan.capture")  # restored after the test
    caplog.set_level(logging.ERROR, logger="holescan.link")
    with SimSortie(PARAMS) as sortie:
        cfg = FlightConfig(
            log_prefix=tmp_path / "flight",
            max_duration_s=HANG_GUARD_S,
            announce_min_sightings=MIN_SIGHTINGS,
            # A loaded CI machine can stall the renderer for seconds: no sensor reopen
            # here (frame indices must stay those of the one simulated source).
            frame_timeout_s=60.0,
            pose_wait_s=1.0,  # a loaded machine can delay telemetry; the flight waits
        )
        flight = Flight(cfg, sortie.source, sortie.camera, mavlink=sortie.mavlink)
        sightings: list[HoleSighting] = []
        tracker_update = flight.tracker.update

        def record(batch: Any) -> Any:
            sightings.extend(batch)
            return tracker_update(batch)

        flight.tracker.update = record  # type: ignore[method-assign,assignment]
        refused: set[int] = set()  # frames detected but never placed (no pose in time)
        placed: list[int] = []  # frames detected and placed
        pipeline_add = flight.hole_pipeline.add

        def add(frame_index: int, *args: Any) -> Any:
            step = pipeline_add(frame_index, *args)
            (refused.add if step.refused else placed.append)(frame_index)
            return step

        flight.hole_pipeline.add = add  # type: ignore[method-assign]
        access = {t.id for t in sortie.truth}

        def most_looked_at() -> int:
            """Frames detected and placed with an access hole wholly in view, for the hole
            with the most of them."""
            n: dict[int, int] = {}
            for i in list(placed):
                _, boxes = sortie.sources[0].truth.get(i, (None, ()))
                for b in boxes:
                    if not b.iscrowd and b.hole_id in access:
                        n[b.hole_id] = n.get(b.hole_id, 0) + 1
            return max(n.values(), default=0)

        def stop_when_flown() -> None:
            # 25 s of flight, MIN_FRAMES frames, and a hole looked at IN_VIEW_FRAMES times
            # (a loaded machine detects few frames and places fewer: it flies on).
            t0 = time.monotonic()
            while not flight.stop.wait(0.2):
                flown = time.monotonic() - t0 >= DURATION_S
                enough = flight.counters.frames_captured >= MIN_FRAMES
                if flown and enough and most_looked_at() >= IN_VIEW_FRAMES:
                    flight.stop.set()

        threading.Thread(target=stop_when_flown, daemon=True).start()
        summary = flight.run()
    truth = sortie.truth
    (source,) = sortie.sources
    c = summary.counters
    assert c.frames_captured > 0 and summary.frames_logged == c.frames_captured
    assert c.frames_log_dropped == 0
    assert summary.telemetry["clock_source"] == "timesync"

    # The pipeline's own error: the daemon's sighting vs the same detection at the true pose.
    dets = {
        r.frame_index: r.detections
        for r in read_flight_log(summary.log.files, kinds={LoggedDetections})
        if isinstance(r, LoggedDetections)
    }
    added, to_truth, cut_to_truth = [], [], []
    for s in sightings:
        assert s.frame_index is not None
        det = next(d for d in dets[s.frame_index] if d.box == s.box)
        true_pose = source.truth[s.frame_index][0]
        (ideal,) = geotag_frame([det], sortie.camera, sortie.mount, true_pose)
        e, n, _ = pymap3d.geodetic2enu(
            s.lat_deg, s.lon_deg, s.alt_m, ideal.lat_deg, ideal.lon_deg, ideal.alt_m
        )
        added.append(math.hypot(float(e), float(n)))
        d, _ = nearest(s.lat_deg, s.lon_deg, truth)
        if d <= MATCH_M:
            (cut_to_truth if det.border_cut else to_truth).append(d)

    # Holes in view: wholly inside the image in IN_VIEW_FRAMES frames or more; looked at:
    # so in frames the detector took and the flight placed. The detector takes the newest
    # frame whenever it is free and the telemetry may come too late to place one, so
    # which frames those are is the machine's (fewer under load): a hole must be
    # reported when the flight looked at it, not when it flew over it.
    whole: dict[int, int] = {}
    looked: dict[int, int] = {}
    for i, (_, boxes) in source.truth.items():
        for b in boxes:
            if not b.iscrowd:
                whole[b.hole_id] = whole.get(b.hole_id, 0) + 1
                if i in dets and i not in refused:
                    looked[b.hole_id] = looked.get(b.hole_id, 0) + 1
    in_view = {t.id for t in truth if whole.get(t.id, 0) >= IN_VIEW_FRAMES}
    looked_at = {t.id for t in truth if looked.get(t.id, 0) >= IN_VIEW_FRAMES}
    reported = [h for h in summary.holes if h.sightings >= MIN_SIGHTINGS]
    matches: dict[int, list[float]] = {}
    false_holes = 0
    whole_err: list[float] = []  # holes seen whole at least once
    only_cut: list[tuple[float, float]] = []  # holes never seen whole: (error, 95 % radius)
    for h in reported:
        d, t = nearest(h.lat_deg, h.lon_deg, truth)
        if d > MATCH_M:
            false_holes += 1
            continue
        matches.setdefault(t.id, []).append(d)
        if all(s.cut_by_border for s in flight.tracker.sightings_of(h.id)):
            only_cut.append((d, CIRCLE_95_PER_SIGMA * h.sigma_h_m))
        else:
            whole_err.append(d)
    hole_err = [d for ds in matches.values() for d in ds]

    print(
        f"\nsim accuracy: {c.frames_captured} frames in {summary.duration_s:.1f} s, "
        f"render {statistics.median(source.render_ms):.0f} ms median, "
        f"{c.frames_detected} detected, {len(sightings)} sightings, {c.pose_refusals} refused"
        f"\n  added by the pipeline: median {statistics.median(added):.3f} m, "
        f"p90 {pct(added, 90):.3f} m, max {max(added):.3f} m (n={len(added)})"
        f"\n  sighting vs true hole: median {statistics.median(to_truth):.3f} m, "
        f"p90 {pct(to_truth, 90):.3f} m (n={len(to_truth)} within {MATCH_M} m); cut by "
        f"the frame's border or band: median "
        f"{statistics.median(cut_to_truth) if cut_to_truth else float('nan'):.3f} m "
        f"(n={len(cut_to_truth)})"
        f"\n  merged hole vs true hole: {', '.join(f'{d:.3f}' for d in hole_err)} m; of them "
        f"seen only cut by the border (error, 95 % radius): "
        f"{', '.join(f'{d:.3f} ({r:.3f})' for d, r in only_cut) or 'none'}"
        f"\n  access holes in view {sorted(in_view)} (frames wholly in view: {whole}; "
        f"of them detected and placed: {looked}); "
        f"found {sorted(matches)}, missed {sorted(looked_at - set(matches))}, duplicated "
        f"{sorted(k for k, v in matches.items() if len(v) > 1)}; {false_holes} reported "
        f"holes match no access hole (distractors)"
    )
    assert len(in_view) >= 2, whole  # the sortie does fly over holes
    # The sortie renders and detects in real time: how many frames get a detection depends
    # on the machine (30-60 sightings idle, 15 under a full parallel test run); the
    # statistics below need a dozen.
    assert len(added) >= 12
    assert statistics.median(added) <= 0.10
    assert pct(added, 90) <= 0.20
    assert looked_at, looked  # (the flight went on until one was: HANG_GUARD_S else)
    for hole_id in looked_at:
        assert len(matches.get(hole_id, [])) == 1, (hole_id, matches)
    assert all(len(v) == 1 for v in matches.values()), matches  # none twice
    # Placed at the opening's centre: before, the box centre put sightings a median
    # 0.11 m and merged holes up to 0.20 m from the truth in this flight.
    # Keeping views cut by the image border (one opening, one hole): they place
    # less well, and this flight's sighting median went 0.042 -> 0.045-0.052 m (the merged
    # holes, what the crew gets, still within 0.10 m below). Since the detector finds the
    # openings an unread band or the border cuts (closed there, Detection.border_cut), those
    # views are many more: they are held to a bar of their own (0.10-0.18 m measured), the
    # others to the one before.
    assert statistics.median(to_truth) <= 0.06
    # (The median of ten or more: a loaded machine's flight once had six, median 0.207 m.)
    if len(cut_to_truth) >= 10:
        assert statistics.median(cut_to_truth) <= 0.20
    # The holes seen whole at least once: within 0.10 m (each hole's estimate comes from its
    # whole views, the views cut by the border weighing as one: averaged in with the whole
    # ones, a loaded machine's flight with few whole views once put a hole 0.15 m off).
    # A hole seen only cut by the border is placed less well: its 95 % circle must hold it.
    assert max(whole_err, default=0.0) <= 0.10
    assert all(d <= r for d, r in only_cut), only_cut
