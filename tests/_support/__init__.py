"""Helpers shared by the tests (one copy each): free loopback ports for the peers the tests
start (pymavlink links, MAVProxy, the ground station, Dask schedulers), and a hang guard for
waits on them (:func:`wait_for`), and the live processes of a process group (a flight and its
worker, :func:`group_members`)."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["SIM_TOML", "free_tcp_port", "free_udp_port", "group_members", "wait_for"]


SIM_TOML = """
sensor = "sim"
[capture]
startup_sync_s = 5.0
[sim]
size_m = [4.0, 4.0]
world_seed = 15
n_access_holes = 4
fps = 10.0
"""
"""A short simulated sortie's fly.toml (4 x 4 m, world 15, 4 access holes, 10 fps) for the
tests and benchmarks that start ``holescan fly`` as a process."""


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing listens on now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for(cond: Callable[[], object], timeout_s: float, what: str, poll_s: float = 0.02) -> None:
    """Poll ``cond`` until it is true; raise :class:`TimeoutError` naming ``what`` if it is
    still false after ``timeout_s``.

    The timeout is a hang guard, never a speed check: make it many times what the wait takes
    on a loaded machine, so reaching it means the thing never came. How fast it comes is
    measured by a benchmark.
    """
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() >= deadline:
            raise TimeoutError(f"{what}: not after {timeout_s:g} s")
        time.sleep(poll_s)


def group_members(pgid: int) -> list[int]:
    """Pids of the live (not zombie) processes of process group ``pgid`` (reads ``/proc``)."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            out.append(int(entry.name))
    return out
