"""The live page's server under a small load, and idle: requests/s, latency, CPU, memory.

Serves a station with 20 holes and a 600-point track (:class:`ground.StationWeb`, the
rate limit lifted) on loopback and measures:

* ``GET /state.json`` (the page's main read, ~60 KB, mostly the state document's own
  work) and ``GET /static/review.js`` (a 7 KB file: mostly the server's own work), from
  ``--clients`` threads, each
  opening a new connection per request (as the old HTTP/1.0 server needed), and, when the
  server keeps connections alive, once more over one kept-alive connection per client;
  requests/s and latency (median, 95th percentile) over ``--requests`` per client;
The server runs in a child process (the clients' threads would otherwise take turns with
it on the interpreter lock).

* idle: a station in a child process with one open event stream (a page left open), CPU
  seconds and resident memory over ``--idle-s``.

Every figure is the median of ``--runs`` runs. It needs only the classes every version of
the station has (``StationState``, ``StationWeb``, ``Limits``), so the same script measures
an older checkout: ``PYTHONPATH=OLD_CHECKOUT python benchmarks/bench_station_http.py``.

    python benchmarks/bench_station_http.py [--clients 4] [--requests 200] [--runs 3]
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from holescan.ground import StationState, TrackPoint
from holescan.ground.station.guard import Limits
from holescan.ground.station.web import StationWeb

LIMITS = Limits(rate_per_s=1e9, burst=1e9)


def station(folder: Path) -> StationState:
    state = StationState.open(folder)
    for hid in range(1, 21):
        state.on_statustext(
            f"HOLE {hid} 0.8 {43.6533 + hid * 2e-5:.7f} {-79.3831 + hid * 1e-5:.7f}"
        )
    for i in range(600):
        p = TrackPoint(i * 10**8, 43.6532 + i * 1e-6, -79.3832 + (i % 50) * 2e-6, 3.0, 0.1)
        state.on_position(p, 0.0)
    return state


def load(
    port: int, path: str, clients: int, requests: int, keep_alive: bool
) -> tuple[float, list[float]]:
    """(requests/s, latencies in s) of ``clients`` threads x ``requests`` GETs each."""
    lat: list[list[float]] = [[] for _ in range(clients)]
    failed: list[str] = []

    def client(k: int) -> None:
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        for _ in range(requests):
            t0 = time.perf_counter()
            if not keep_alive:
                conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
            conn.request("GET", path, headers={"Host": f"127.0.0.1:{port}"})
            r = conn.getresponse()
            body = r.read()
            if r.status != 200 or not body:
                failed.append(f"{r.status}")
            if not keep_alive:
                conn.close()
            lat[k].append(time.perf_counter() - t0)
        conn.close()

    threads = [threading.Thread(target=client, args=(k,)) for k in range(clients)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.perf_counter() - t0
    if failed:
        raise SystemExit(f"{len(failed)} requests failed: {sorted(set(failed))}")
    flat = [x for xs in lat for x in xs]
    return len(flat) / wall, flat


def keeps_alive(port: int) -> bool:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    conn.request("GET", "/state.json", headers={"Host": f"127.0.0.1:{port}"})
    r = conn.getresponse()
    r.read()
    alive = not r.will_close
    conn.close()
    return alive


def idle_child(seconds: float) -> None:
    """Run a station with one open event stream; print its CPU s and RSS as JSON."""
    with tempfile.TemporaryDirectory() as tmp:
        state = station(Path(tmp) / "st")
        with StationWeb(state, "127.0.0.1", 0, limits=LIMITS, names=()) as web:
            conn = http.client.HTTPConnection("127.0.0.1", web.port, timeout=60)
            conn.request("GET", "/events", headers={"Host": f"127.0.0.1:{web.port}"})
            resp = conn.getresponse()
            assert resp.status == 200
            time.sleep(1.0)  # started
            t0 = os.times()
            time.sleep(seconds)
            t1 = os.times()
            rss_kb = next(
                int(line.split()[1])
                for line in Path("/proc/self/status").read_text().splitlines()
                if line.startswith("VmRSS:")
            )
            conn.close()
    cpu = (t1.user + t1.system) - (t0.user + t0.system)
    print(json.dumps({"cpu_s": cpu, "rss_mb": rss_kb / 1024}))


def serve_child() -> None:
    """Serve the station; print the port; stop when stdin closes."""
    with tempfile.TemporaryDirectory() as tmp:
        state = station(Path(tmp) / "st")
        with StationWeb(state, "127.0.0.1", 0, limits=LIMITS, names=()) as web:
            print(web.port, flush=True)
            sys.stdin.read()


def idle(seconds: float) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, __file__, "--idle-child", str(seconds)],
        capture_output=True,
        text=True,
        check=True,
    )
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--clients", type=int, default=4)
    ap.add_argument("--requests", type=int, default=200, help="per client")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--idle-s", type=float, default=20.0)
    ap.add_argument("--idle-child", type=float, help=argparse.SUPPRESS)
    ap.add_argument("--serve-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.serve_child:
        serve_child()
        return 0
    if args.idle_child is not None:
        idle_child(args.idle_child)
        return 0
    rows: dict[str, list[tuple[float, float, float]]] = {}
    # the server in a process of its own, as in the field (in one process the clients'
    # threads and the server would take turns on the interpreter lock)
    with subprocess.Popen(
        [sys.executable, __file__, "--serve-child"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    ) as server:
        assert server.stdout is not None and server.stdin is not None
        port = int(server.stdout.readline())
        modes = [("new connection per request", False)]
        if keeps_alive(port):
            modes.append(("kept-alive connections", True))
        for _ in range(args.runs):
            for path in ("/state.json", "/static/review.js"):
                for name, alive in modes:
                    rps, lat = load(port, path, args.clients, args.requests, alive)
                    q = statistics.quantiles(lat, n=20)
                    key = f"{path}, {name}"
                    rows.setdefault(key, []).append((rps, statistics.median(lat), q[18]))
        server.stdin.close()
        server.wait(timeout=30)
    print(
        f"{args.clients} clients x {args.requests} requests each (20 holes, 600 track points), "
        f"median of {args.runs} runs:"
    )
    for name, runs in rows.items():
        rps = statistics.median(r[0] for r in runs)
        med = statistics.median(r[1] for r in runs) * 1e3
        p95 = statistics.median(r[2] for r in runs) * 1e3
        print(f"  GET {name}: {rps:.0f} requests/s, latency median {med:.1f} ms, p95 {p95:.1f} ms")
    idles = [idle(args.idle_s) for _ in range(args.runs)]
    cpu = statistics.median(i["cpu_s"] for i in idles)
    rss = statistics.median(i["rss_mb"] for i in idles)
    print(
        f"idle with one open event stream, {args.idle_s:g} s: CPU {cpu:.3f} s "
        f"({100 * cpu / args.idle_s:.2f} %), resident memory {rss:.0f} MB"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
