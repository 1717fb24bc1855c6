#!/usr/bin/env python3
"""What reaches the rescuers, measured through the whole system over several worlds.

Runs :func:`demo.run_demo` (simulated autopilot over loopback MAVLink, simulated Xtion,
capture daemon with the announce gate, hole server with pictures under the byte budget,
the ground station app in-process) for each world seed, and sums up against the
simulator's truth, which the code under test never sees:

* delivered precision: announced holes that are true access holes;
* recall of holes in view: true holes wholly in view in >= 3 frames that were announced;
* time from first sighting to announcement (autopilot clock), median and max;
* pictures: announced holes whose picture reached the ground; bytes/s of pictures;
* review items: holes sent for review (not announced), how many sit at a true opening,
  and per hectare surveyed (the sortie's ``size_m``).

The gate is the daemon's :meth:`geotag.AnnounceGate.tier` on each hole's hole-level
``p_hole`` (:attr:`geotag.Hole.p_hole`), the default thresholds unless ``--min-p-hole`` /
``--review-min-p-hole`` say otherwise.

Usage::

    nice python benchmarks/bench_delivery.py --seeds 1-8 --out /tmp/delivery
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
from pathlib import Path

from holescan.demo import DEMO_SORTIE, DemoOptions, run_demo
from holescan.geotag import AnnounceGate


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--seeds", default="1-8")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--min-p-hole", type=float, default=AnnounceGate.min_p_hole)
    ap.add_argument("--review-min-p-hole", type=float, default=AnnounceGate.review_min_p_hole)
    args = ap.parse_args(argv)
    gate = AnnounceGate(min_p_hole=args.min_p_hole, review_min_p_hole=args.review_min_p_hole)
    print(f"gate: {gate}", flush=True)
    a, _, b = args.seeds.partition("-")
    seeds = list(range(int(a), int(b or a) + 1))
    rows = []
    for seed in seeds:
        sortie = dataclasses.replace(DEMO_SORTIE, world_seed=seed)
        r = run_demo(DemoOptions(out=args.out / f"seed{seed}", sortie=sortie, gate=gate))
        n = r.numbers()
        rows.append(n | {"seed": seed, "announced": len(r.confirmed), "area_m2": r.area_m2})
        print(
            f"seed {seed}: announced {len(r.confirmed)}, true {n['found']}, false {n['false']}, "
            f"in view {n['found'] + n['missed']}, missed {n['missed']}, review "
            f"{len(n['review'])} ({n['review_true']} at a true opening), candidates "
            f"{n['candidates']}, pictures at ground {n['pictures_at_ground']}, "
            f"picture bytes/s {n['card_bytes_per_s']:.0f}, latency {n['latency_s']}",
            flush=True,
        )
    announced = sum(r["announced"] for r in rows)
    true = sum(r["found"] for r in rows)
    in_view = sum(r["found"] + r["missed"] for r in rows)
    lat = [x for r in rows for x in r["latency_s"]]
    print(
        f"{len(rows)} worlds: delivered precision {true}/{announced} = "
        f"{true / max(announced, 1):.3f}; recall of holes in view {true}/{in_view}; "
        f"first sighting -> announcement median {statistics.median(lat):.1f} s, max "
        f"{max(lat):.1f} s; pictures {sum(r['pictures_at_ground'] for r in rows)}/{announced};"
        f" picture bytes/s max {max(r['card_bytes_per_s'] for r in rows):.0f}"
    )
    reviews = sum(len(r["review"]) for r in rows)
    ha = sum(r["area_m2"] for r in rows) / 1e4
    print(
        f"review items {reviews} ({sum(r['review_true'] for r in rows)} at a true opening) "
        f"over {ha:.2f} ha surveyed: {reviews / ha:.0f} per hectare"
    )
    (args.out / "delivery.json").write_text(
        json.dumps({"gate": dataclasses.asdict(gate), "worlds": rows}, indent=1)
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
