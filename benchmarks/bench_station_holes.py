"""How fast the station takes hole reports when there are many: STATUSTEXTs straight into
:class:`ground.StationState` (no link: the state's own work, under its lock), as a flood of
forged ids or a long survey of several drones would bring them.

Each run reports ``--holes`` holes spread over one or ``--vehicles`` vehicles (each vehicle
its own ids, the openings a few metres apart so that vehicles' holes merge by the
campaign's rule), into a fresh state folder (its file written as the station writes it).
Prints, per case, the median over ``--runs`` of the seconds for all reports and the
per-report cost; the link takes a packet every 5 ms at 200/s.

    python benchmarks/bench_station_holes.py [--holes 2000] [--vehicles 2] [--runs 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from holescan.geotag import LocalFrame
from holescan.ground import StationState

HOME = (43.6532, -79.3832)


def run(n: int, vehicles: int) -> float:
    frame = LocalFrame(*HOME)
    with tempfile.TemporaryDirectory() as tmp:
        state = StationState.open(Path(tmp) / "st")
        t0 = time.perf_counter()
        for i in range(n):
            sysid = 1 + i % vehicles
            own = 1 + i // vehicles
            lat, lon = frame.to_geodetic(3.0 * (own % 40), 3.0 * (own // 40))
            state.on_statustext(f"HOLE {own} p0.90 {float(lat):.7f} {float(lon):.7f}", sysid)
        took = time.perf_counter() - t0
        state.flush()
    return took


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--holes", type=int, default=2000)
    ap.add_argument("--vehicles", type=int, default=2)
    ap.add_argument("--runs", type=int, default=3)
    a = ap.parse_args()
    for vehicles in sorted({1, a.vehicles}):
        took = statistics.median(run(a.holes, vehicles) for _ in range(a.runs))
        print(
            f"{a.holes} reports, {vehicles} vehicle(s): {took:.2f} s median of {a.runs}, "
            f"{1000 * took / a.holes:.2f} ms a report"
        )


if __name__ == "__main__":
    main()
