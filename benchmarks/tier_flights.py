#!/usr/bin/env python3
"""Simulated flights recorded as every frame's sightings, with the world's truth.

Shared by ``benchmarks/calibrate_confidence.py`` (fits the hole-level confidence) and
``benchmarks/bench_tiers.py`` (measures the tiers): a flight is rendered and detected once
(the expensive part) and its per-frame :class:`geotag.HoleSighting` lists are cached as a
pickle, so merging, confidence and tiers can be replayed over hundreds of flights in
seconds.

Frames are rendered as the sortie's camera renders them: the structured-light sensor
(:mod:`sim.structured_light`, on by default in :class:`sim.Conditions`) with the motion blur
and depth/colour time offset of the vehicle's image motion (:func:`sim.image_motion`).

Flights, over :func:`sim.make_sortie_world` worlds (world seed ``S``, all distractors):

* ``survey`` : one lap of the demo's lawnmower at 3 m (``sim.survey_path``);
* ``hover`` : 20 s over each access hole and over distractors (stains, cracks, small
  holes, depressions, shadows) at 3 m, the vehicle wandering 0.15 m (the issue's
  "240 of 240 frames" case: views from one place);
* ``line`` : straight passes over each access hole at 0.8 m/s, the heading drawn per
  hole, so the opening enters and leaves the image cut by its border (the issue's
  "moving line over one opening" case).

Truth: a hole is true when its position lies within 0.5 m of an access hole's centre or
inside its opening (:func:`demo.score_holes`' rule); the opening it lies in is its
``truth_id`` (two holes with one ``truth_id`` are a duplicate).
"""

from __future__ import annotations

import math
import pickle
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from holescan.detect import CameraIntrinsics, detect_holes
from holescan.geotag import CameraMount, HoleSighting, LocalFrame, VehiclePose
from holescan.sim import (
    Conditions,
    SimAutopilot,
    SimPath,
    SortieParams,
    camera_pose_in_world,
    image_motion,
    make_sortie_world,
    random_conditions,
    render,
    survey_path,
)

KINDS = ("survey", "hover", "line")
#: Frames are rendered as the sortie's camera renders them (:class:`sim.SimSource`): the
#: structured-light sensor (``Conditions()``' default) under the vehicle's image motion,
#: measured over this step.
MOTION_DT_NS = 10_000_000
#: What the flights' frames are, for the provenance of what is fitted on them.
SENSOR = "structured-light sensor model under the vehicle's image motion"


@dataclass(frozen=True)
class Flight:
    """One recorded flight: per frame its sightings; the truth to score against."""

    kind: str
    seed: int
    fps: float
    frames: list[list[HoleSighting]]
    in_view: dict[int, int]  # access hole id -> frames that showed it whole
    openings: dict[int, list[tuple[float, float]]]  # access hole id -> outline (x, y) m
    centres: dict[int, tuple[float, float]]
    distractors: list[tuple[str, float, float]]  # kind, x, y (world metres)
    anchor: tuple[float, float, float]
    area_m2: float


def _path_line(p: SortieParams, x: float, y: float, heading: float, h: float) -> SimPath:
    d = (math.sin(heading), math.cos(heading))
    o = (-d[1] * 0.3, d[0] * 0.3)
    pts = [(x - 4 * d[0], y - 4 * d[1]), (x + 4 * d[0], y + 4 * d[1])]
    pts += [(pts[1][0] + o[0], pts[1][1] + o[1]), (pts[0][0] + o[0], pts[0][1] + o[1])]
    return _path(p, pts, 0.8, h)


def _path_hover(p: SortieParams, x: float, y: float, h: float) -> SimPath:
    r = 0.15
    pts = [(x + r * math.cos(k * 2.1), y + r * math.sin(k * 2.1)) for k in range(3)]
    return _path(p, pts, 0.05, h)


def _path(p: SortieParams, xy: list[tuple[float, float]], speed: float, h: float) -> SimPath:
    a = p.anchor  # home is the world's anchor: world metres are the path's ENU
    wps = tuple((float(x), float(y), h) for x, y in xy)
    return SimPath(
        a.lat_deg, a.lon_deg, a.alt_m, wps, speed_m_s=speed, wobble_rad=math.radians(1.5)
    )


def _fly(
    world: Any, p: SortieParams, path: SimPath, seconds: float, fps: float, tag: int
) -> tuple[list[list[HoleSighting]], dict[int, int]]:
    from holescan.geotag import HolePipeline

    ap = SimAutopilot("udpout:127.0.0.1:9", path, uptime_at_start_s=p.clock_offset_s)
    camera = CameraIntrinsics.xtion()
    mount = CameraMount()
    pipe = HolePipeline(camera, mount)
    frames: list[list[HoleSighting]] = []
    seen: dict[int, int] = {}
    for k in range(int(seconds * fps)):
        t_boot = round(p.clock_offset_s * 1e9) + round(k * 1e9 / fps)
        truth_pose = ap.truth_pose(t_boot)
        pose = VehiclePose(**{**truth_pose.__dict__, "eph_m": p.eph_m})
        rng = np.random.default_rng((p.world_seed, tag, k))
        cond = random_conditions(rng, Conditions())
        cam_pose = camera_pose_in_world(pose, mount, p.anchor)
        later = camera_pose_in_world(ap.truth_pose(t_boot + MOTION_DT_NS), mount, p.anchor)
        motion = image_motion(cam_pose, later, camera, MOTION_DT_NS * 1e-9)
        rgb, depth, boxes = render(world, cam_pose, camera, rng, cond, motion)
        for b in boxes:
            if not b.iscrowd:
                seen[b.hole_id] = seen.get(b.hole_id, 0) + 1
        dets = detect_holes(rgb, depth, camera)
        step = pipe.add(k, dets, lambda pose=pose: pose)
        frames.append(list(step.sightings))
    return frames, seen


def record(kind: str, seed: int, fps: float = 10.0) -> list[Flight]:
    """Fly world ``seed`` the ``kind`` way; one :class:`Flight` per path flown."""
    p = SortieParams(world_seed=seed, n_access_holes=4, fps=fps)
    world = make_sortie_world(p)
    a = p.anchor
    common = {
        "openings": {h.id: [tuple(map(float, q)) for q in h.opening] for h in world.access_holes},
        "centres": {h.id: tuple(map(float, h.centre_xy)) for h in world.access_holes},
        "distractors": [
            (str(h.kind), *map(float, h.centre_xy)) for h in world.holes if not h.is_access
        ],
        "anchor": (a.lat_deg, a.lon_deg, a.alt_m),
    }
    rng = np.random.default_rng((seed, 0x71E5))
    out = []
    if kind == "survey":
        _, path = survey_path(world, p)
        from holescan.sim import loop_length_m

        secs = loop_length_m(path) / path.speed_m_s
        frames, seen = _fly(world, p, path, secs, fps, 0)
        area = p.size_m[0] * p.size_m[1]
        out.append(Flight(kind, seed, fps, frames, seen, area_m2=area, **common))
    elif kind in ("hover", "line"):
        targets = [(h.id, *map(float, h.centre_xy)) for h in world.access_holes]
        if kind == "hover":
            others = list(common["distractors"])
            picks = rng.choice(len(others), size=min(4, len(others)), replace=False)
            targets += [(-1, others[i][1], others[i][2]) for i in picks]
        lo, hi = p.margin_m, p.margin_m + p.size_m[0]
        for j, (_, x, y) in enumerate(targets):
            if not (lo <= x <= hi and lo <= y <= hi):
                continue
            if kind == "hover":
                path = _path_hover(p, x, y, p.altitude_m)
                frames, seen = _fly(world, p, path, 20.0, fps, 100 + j)
                area = 3.5 * 2.6  # the footprint at 3 m
            else:
                path = _path_line(p, x, y, float(rng.uniform(0, 2 * math.pi)), p.altitude_m)
                frames, seen = _fly(world, p, path, 8.0 / 0.8, fps, 200 + j)
                area = 8.0 * 2.6
            out.append(Flight(kind, seed, fps, frames, seen, area_m2=area, **common))
    else:
        raise ValueError(f"kind must be one of {KINDS}")
    return out


def cached(cache: Path, kind: str, seed: int, fps: float) -> list[Flight]:
    """:func:`record`, from ``cache`` when it was recorded before."""
    f = cache / f"{kind}_{seed}_{fps:g}.pkl"
    if f.is_file():
        return load(f)
    flights = record(kind, seed, fps)
    cache.mkdir(parents=True, exist_ok=True)
    part = f.with_suffix(".part")
    part.write_bytes(pickle.dumps(flights))
    part.rename(f)
    return flights


class _Unpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if name == "Flight":
            return Flight
        return super().find_class(module, name)


def load(path: Path) -> list[Flight]:
    """The flights of one cache file."""
    with path.open("rb") as fh:
        flights: list[Flight] = _Unpickler(fh).load()
    return flights


def truth_of(flight: Flight, lat: float, lon: float) -> int | None:
    """The access hole whose opening holds (or whose centre is within 0.5 m of) a point."""
    from shapely.geometry import Point, Polygon

    frame = LocalFrame(flight.anchor[0], flight.anchor[1], flight.anchor[2])
    e, n, _ = frame.to_enu(lat, lon, flight.anchor[2])
    best: tuple[float, int] | None = None
    for hid, (x, y) in flight.centres.items():
        d = math.hypot(float(e) - x, float(n) - y)
        inside = d <= 0.5 or Polygon(flight.openings[hid]).contains(Point(float(e), float(n)))
        if inside and (best is None or d < best[0]):
            best = (d, hid)
    return None if best is None else best[1]


def shifted(s: HoleSighting, dt_ns: int) -> HoleSighting:
    return replace(s, t_boot_ns=s.t_boot_ns + dt_ns)


def _one(job: tuple[str, int, float, str]) -> str:
    kind, seed, fps, cache = job
    flights = cached(Path(cache), kind, seed, fps)
    return f"{kind} {seed}: {len(flights)} flights, {sum(len(f.frames) for f in flights)} frames"


FPS = {"survey": 10.0, "hover": 6.0, "line": 10.0}


def main(argv: list[str] | None = None) -> int:
    """Record (or find cached) flights: ``tier_flights.py CACHE --seeds 1-30 --jobs 2``."""
    import argparse
    import concurrent.futures

    ap = argparse.ArgumentParser(description="record simulated flights' sightings")
    ap.add_argument("cache", type=Path)
    ap.add_argument("--seeds", default="1-30")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    a, _, b = args.seeds.partition("-")
    seeds = list(range(int(a), int(b or a) + 1))
    jobs = [(k, s, FPS[k], str(args.cache)) for s in seeds for k in args.kinds.split(",")]
    with concurrent.futures.ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for line in pool.map(_one, jobs):
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    import sys

    import tier_flights  # pickle the records under the module's name, not __main__

    sys.exit(tier_flights.main())


def sightings_of(flight: Flight) -> list[list[HoleSighting]]:
    """The flight's frames, ``cut_by_border`` set from the boxes (the Xtion's 640 x 480)."""
    from holescan.geotag import box_cut_by_border

    return [
        [replace(s, cut_by_border=box_cut_by_border(s.box, 640, 480)) for s in fr]
        for fr in flight.frames
    ]
