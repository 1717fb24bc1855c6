"""MAVLink telemetry kept under garbage: messages and posed samples received from a simulated
autopilot over UDP loopback in a few seconds, clean and with random datagrams interleaved.

    python benchmarks/bench_mavlink_garbage.py [--seconds 6] [--garbage-hz 50]
"""

from __future__ import annotations

import argparse
import socket
import threading
import time
from typing import Any

import numpy as np

from holescan.capture import Telemetry
from holescan.link import PoseUnavailable
from holescan.sim import SimAutopilot, SimPath


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run(seconds: float, garbage_hz: float, seed: int = 1) -> dict[str, Any]:
    """Messages received, share of 30 Hz sample times that could be posed, and each
    stream's rate measured at the receiver against the one asked (``measured/asked`` Hz)."""
    port = free_port()
    rng = np.random.default_rng(seed)
    path = SimPath(waypoints_enu=((0.0, 0.0, 2.5), (3.0, 0.0, 2.5), (3.0, 3.0, 2.5)), speed_m_s=0.5)
    stop = threading.Event()
    injected = 0
    with SimAutopilot(f"udpout:127.0.0.1:{port}", path) as ap:

        def inject() -> None:
            nonlocal injected
            while garbage_hz > 0 and not stop.wait(1.0 / garbage_hz):
                ap.inject_garbage(rng.bytes(int(rng.integers(1, 300))))
                injected += 1

        with Telemetry(f"udpin:127.0.0.1:{port}") as tel:
            time.sleep(1.0)  # rates requested, clock synchronised
            before = sum(tel.stats().messages.values())
            t = threading.Thread(target=inject, daemon=True)
            t.start()
            posed = tried = 0
            t_end = time.monotonic() + seconds
            while time.monotonic() < t_end:
                time.sleep(1 / 30)
                tried += 1
                try:
                    tel.pose_at_mono(time.monotonic_ns())
                    posed += 1
                except PoseUnavailable:
                    pass
            stop.set()
            t.join()
            st = tel.stats()
            measured = tel.message_rates_hz(window_s=seconds)
            asked = ap.rates_hz()
    return {
        "rates_hz": {
            k: f"{measured.get(k, 0.0):.1f}/{hz:g}" for k, hz in sorted(asked.items()) if hz > 0
        },
        "messages": sum(st.messages.values()) - before,
        "unposed": tried - posed,
        "samples": tried,
        "garbage_datagrams": injected,
        "bad_bytes": st.bad_bytes,
        "bad_packets": st.bad_packets,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--garbage-hz", type=float, default=50.0)
    args = ap.parse_args()
    clean = run(args.seconds, 0.0)
    dirty = run(args.seconds, args.garbage_hz)
    print(f"clean:   {clean}")
    print(f"garbage: {dirty}")
    print(f"kept {dirty['messages'] / max(clean['messages'], 1):.1%} of the messages")


if __name__ == "__main__":
    main()
