"""Helpers shared by the tests (one copy each): free loopback ports for the peers the tests
start (pymavlink links, MAVProxy, the ground station, Dask schedulers)."""

from __future__ import annotations

import socket

__all__ = ["free_tcp_port", "free_udp_port"]


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
