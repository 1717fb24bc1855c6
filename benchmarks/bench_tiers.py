#!/usr/bin/env python3
"""Announced and for-review tiers over simulated flights: recall, precision, review load.

    nice -n 10 python benchmarks/bench_tiers.py CACHE --seeds 17-36 [--announce P] [--review P]

Flights (``benchmarks/tier_flights.py``: surveys, hovers, passes over holes; seeds not
used to fit the confidence, ``benchmarks/calibrate_confidence.py --fit-seeds``) are
replayed frame by frame through :class:`geotag.HoleTracker`; after every frame each
changed hole's tier is decided by :class:`geotag.AnnounceGate` (``p_hole`` of all its
sightings, sightings, span). A hole reaches the ground at the first frame it is in a
tier (announced or review); a review hole later announced counts as announced. Holes
fused into another afterwards (:meth:`geotag.HoleTracker.merged`) count too if they had
reached the ground: a crew would have seen them.

Printed per gate of a grid and for the chosen one, per flight kind and overall:

* recall of the true holes in view (whole in the image in >= 3 frames): announced, and
  announced + review;
* announced precision (a hole is true within 0.5 m of an access hole's centre or inside
  its opening);
* review items per hectare flown over (survey 10 x 10 m; hover footprint 3.5 x 2.6 m;
  pass 8 x 2.6 m);
* duplicates: openings with two or more holes on the ground;
* first sighting -> tier decided (the flight's frame clock), median and max, for the
  true holes in view;
* the same for the best-frame gate the vehicle used before (``p_hole_of_score(best
  score) >= 0.9``, two sightings over 0.3 s; no review tier).

``--no-surface-vote``: the chosen gate without the absorbing-surface vote
(:meth:`geotag.AnnounceGate.surface_held`), for comparison on the same flights.
``--no-edge-hold``: without holding unread holes seen only at the image's edge
(:meth:`geotag.AnnounceGate.edge_held`), likewise.

``--holes``: where the thresholds can go. Per hole of every flight (true when it lies at an
access hole, as above), the highest hole-level ``p_hole`` it reached at all (what the
review threshold sees) and while seen ``min_sightings`` times over ``min_span_s`` (what the
announce threshold sees; 0 when it never was), as quantiles, for the true holes at an
opening in view (whole in the image in >= 3 frames), for those at an opening never whole in
view so often (seen cut by the border: not counted in the recall, wanted all the same) and
for the false holes.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import tier_flights

from holescan.detect import p_hole_of_score
from holescan.geotag import AnnounceGate, Hole, HoleTracker


@dataclass
class Replay:
    """One flight replayed: every hole's states (time s, hole) and the truth."""

    flight: tier_flights.Flight
    states: dict[int, list[tuple[float, Hole]]] = field(default_factory=dict)
    merged: dict[int, int] = field(default_factory=dict)


def replay(flight: tier_flights.Flight) -> Replay:
    r = Replay(flight)
    tracker = HoleTracker()
    t0: int | None = None
    for fr in tier_flights.sightings_of(flight):
        if not fr:
            continue
        t0 = fr[0].t_boot_ns if t0 is None else t0
        for h in tracker.update(fr):
            r.states.setdefault(h.id, []).append(((fr[0].t_boot_ns - t0) * 1e-9, h))
    r.merged = tracker.merged()
    return r


def _best_frame(h: Hole) -> Hole:
    from dataclasses import replace

    return replace(h, p_hole=p_hole_of_score(h.score))


def score(replays: list[Replay], gate: AnnounceGate, *, best_frame: bool = False) -> dict[str, Any]:
    in_view = found_a = found_ar = announced = announced_true = review = dups = 0
    area = 0.0
    lat_ar: list[float] = []
    lat_a: list[float] = []
    for r in replays:
        fl = r.flight
        area += fl.area_m2
        delivered: dict[int, tuple[str, float, float | None, Hole]] = {}
        for hid, states in r.states.items():
            t_first = states[0][0]
            t_review = t_announce = None
            for t, h in states:
                got = gate.tier(_best_frame(h) if best_frame else h)
                if got == "announced" and t_announce is None:
                    t_announce = t - t_first
                if got != "candidate" and t_review is None and not (best_frame and got == "review"):
                    t_review = t - t_first
            if t_review is not None:
                tier = "announced" if t_announce is not None else "review"
                delivered[hid] = (tier, t_review, t_announce, states[-1][1])
        truths: dict[int, list[tuple[str, float, float | None]]] = {}
        for tier, first, t_announce, h in delivered.values():
            tid = tier_flights.truth_of(fl, h.lat_deg, h.lon_deg)
            if tier == "announced":
                announced += 1
                announced_true += tid is not None
            else:
                review += 1
            if tid is not None:
                truths.setdefault(tid, []).append((tier, first, t_announce))
        dups += sum(len(v) > 1 for v in truths.values())
        for tid, frames in fl.in_view.items():
            if frames < 3:
                continue
            in_view += 1
            got = truths.get(tid, [])
            if got:
                found_ar += 1
                lat_ar.append(min(g[1] for g in got))
            announced_at = [g[2] for g in got if g[2] is not None]
            if announced_at:
                found_a += 1
                lat_a.append(min(announced_at))
    ha = area / 1e4
    return {
        "in_view": in_view,
        "recall_announced": found_a / in_view if in_view else float("nan"),
        "recall_both": found_ar / in_view if in_view else float("nan"),
        "announced": announced,
        "precision": announced_true / announced if announced else float("nan"),
        "review": review,
        "review_per_ha": review / ha if ha else float("nan"),
        "duplicates": dups,
        "latency_median_s": statistics.median(lat_ar) if lat_ar else float("nan"),
        "latency_max_s": max(lat_ar) if lat_ar else float("nan"),
        "announce_median_s": statistics.median(lat_a) if lat_a else float("nan"),
        "announce_max_s": max(lat_a) if lat_a else float("nan"),
        "hectares": ha,
    }


def _quantiles(v: list[float]) -> str:
    if not v:
        return "-"
    qs = [min(v), *(statistics.quantiles(v, n=10, method="inclusive")[i] for i in (0, 4, 8))]
    return " / ".join(f"{q:.2f}" for q in [*qs, max(v)])


def hole_levels(replays: list[Replay], gate: AnnounceGate) -> None:
    """Print the ``--holes`` table (module docstring)."""
    keys = ("true any", "true A", "true cut", "false any", "false A")
    rows: dict[str, list[float]] = {k: [] for k in keys}
    for r in replays:
        fl = r.flight
        for states in r.states.values():
            h_end = states[-1][1]
            tid = tier_flights.truth_of(fl, h_end.lat_deg, h_end.lon_deg)
            if tid is not None and fl.in_view.get(tid, 0) < 3:
                rows["true cut"].append(max(h.p_hole for _, h in states))
                continue
            span_ok = [
                h.p_hole
                for _, h in states
                if h.sightings >= gate.min_sightings
                and (h.t_last_boot_ns - h.t_first_boot_ns) * 1e-9 >= gate.min_span_s
            ]
            kind = "true" if tid is not None else "false"
            rows[f"{kind} any"].append(max(h.p_hole for _, h in states))
            rows[f"{kind} A"].append(max(span_ok, default=0.0))
    print("| holes | n | highest p_hole min / p10 / p50 / p90 / max |")
    print("|---|---|---|")
    names = {
        "true any": "true, any time",
        "true A": f"true, seen {gate.min_sightings}x over {gate.min_span_s:g} s",
        "true cut": "true, at an opening never whole in view 3 times, any time",
        "false any": "false, any time",
        "false A": f"false, seen {gate.min_sightings}x over {gate.min_span_s:g} s",
    }
    for k, v in rows.items():
        print(f"| {names[k]} | {len(v)} | {_quantiles(v)} |")


def _line(name: str, s: dict[str, Any]) -> str:
    return (
        f"  {name:34} in view {s['in_view']:3}  recall A {s['recall_announced']:.3f} "
        f"A+R {s['recall_both']:.3f}  precision A {s['precision']:.3f} ({s['announced']})  "
        f"review {s['review']:3} = {s['review_per_ha']:6.1f}/ha  dup {s['duplicates']}  "
        f"first sighting -> tier median {s['latency_median_s']:.2f} max "
        f"{s['latency_max_s']:.2f} s (announced {s['announce_median_s']:.2f} / "
        f"{s['announce_max_s']:.2f} s)"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("cache", type=Path)
    ap.add_argument("--seeds", default="17-36")
    ap.add_argument("--announce", type=float, default=AnnounceGate.min_p_hole)
    ap.add_argument("--review", type=float, default=AnnounceGate.review_min_p_hole)
    ap.add_argument("--grid", action="store_true", help="print the threshold curves")
    ap.add_argument("--holes", action="store_true", help="print true/false holes' p_hole")
    ap.add_argument(
        "--no-surface-vote", action="store_true", help="the gate without the absorbing-surface vote"
    )
    ap.add_argument(
        "--surface-tie",
        type=int,
        default=AnnounceGate.surface_tie_views,
        help="AnnounceGate.surface_tie_views (0: off)",
    )
    ap.add_argument(
        "--no-edge-hold",
        action="store_true",
        help="the gate without holding unread holes seen only at the image's edge",
    )
    args = ap.parse_args(argv)
    a, _, b = args.seeds.partition("-")
    seeds = range(int(a), int(b or a) + 1)
    by_kind: dict[str, list[Replay]] = {}
    for kind in tier_flights.KINDS:
        for seed in seeds:
            f = args.cache / f"{kind}_{seed}_{tier_flights.FPS[kind]:g}.pkl"
            if f.is_file():
                by_kind.setdefault(kind, []).extend(replay(fl) for fl in tier_flights.load(f))
    everything = [r for rs in by_kind.values() for r in rs]
    n_frames = sum(len(r.flight.frames) for r in everything)
    print(
        f"{len(everything)} flights ({', '.join(f'{k} {len(v)}' for k, v in by_kind.items())}),"
        f" {n_frames} frames, seeds {args.seeds}"
    )
    if args.grid:
        print("announce p / review p over all flights:")
        for pa in (0.5, 0.7, 0.8, 0.9, 0.95, 0.98):
            for pr in (0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5):
                if pr <= pa:
                    g = AnnounceGate(min_p_hole=pa, review_min_p_hole=pr)
                    print(_line(f"A>={pa:.2f} R>={pr:.2f}", score(everything, g)))
    vote: dict[str, int] = {"surface_min_views": 10**9} if args.no_surface_vote else {}
    if args.no_edge_hold:
        vote["edge_behind_views"] = 0
    vote["surface_tie_views"] = 0 if args.no_surface_vote else args.surface_tie
    gate = AnnounceGate(min_p_hole=args.announce, review_min_p_hole=args.review, **vote)
    if args.holes:
        hole_levels(everything, gate)
    print(
        f"gate: announce p_hole >= {gate.min_p_hole}, review p_hole >= {gate.review_min_p_hole}"
        f", surface vote {'off' if args.no_surface_vote else 'on'}"
        f" (tie views {vote['surface_tie_views']})"
        f", edge hold {'off' if args.no_edge_hold else 'on'}"
    )
    for kind, rs in by_kind.items():
        print(_line(kind, score(rs, gate)))
    print(_line("all", score(everything, gate)))
    print("before: best-frame p_hole >= 0.9, no review tier")
    print(_line("all", score(everything, AnnounceGate(min_p_hole=0.9), best_frame=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
