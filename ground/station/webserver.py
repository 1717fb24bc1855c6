"""The live page's server: uvicorn (h11) on its own thread, serving an ASGI app.

What the server bounds, from uvicorn's own settings (:class:`~ground.station.guard.Limits`):
the request head (``h11_max_incomplete_event_size``: a longer head is answered 400), open
connections and requests in all (``limit_concurrency``: 503 past it), idle kept-alive
connections (``timeout_keep_alive``). Malformed requests (a bad request line, two
``Content-Length``, a ``Content-Length`` that is not ASCII digits such as ``²``, a missing
``Host`` in HTTP/1.1) are h11's to refuse (400). ``X-Forwarded-*`` headers are not trusted
(no proxy in front of the station: a local program could otherwise pose as any address).

Two bounds uvicorn does not have are added in :class:`_Protocol`, uvicorn's h11 protocol
with two more checks: connections from one address beyond ``max_per_client`` are closed
unanswered, and a request must be complete (head and body) within ``request_s`` of the
connection (or of the previous answer on it): a slow-loris client that drips its request
a byte at a time is cut off.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time
from typing import Any

import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from holescan.errors import InputError
from holescan.ground.station.guard import App, Limits

__all__ = ["ServerCounters", "WebServer"]

_log = logging.getLogger(__name__)


class ServerCounters:
    """What the server refused at the connection level (read by tests and the station)."""

    def __init__(self) -> None:
        self.cut = 0
        """Connections cut off for not sending a whole request within ``request_s``."""
        self.crowded = 0
        """Connections closed unanswered: too many open from one address."""


def _protocol(limits: Limits, counters: ServerCounters) -> type[H11Protocol]:
    class _Protocol(H11Protocol):  # type: ignore[misc,unused-ignore]
        """uvicorn's h11 protocol with a per-address cap and a whole-request deadline."""

        _deadline: asyncio.TimerHandle | None = None

        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override,unused-ignore]
            super().connection_made(transport)
            ip = self.client[0] if self.client else ""
            peers = [getattr(c, "client", None) or ("",) for c in self.connections]
            same = sum(1 for peer in peers if peer[0] == ip)
            if same > limits.max_per_client:
                counters.crowded += 1
                _log.warning("web: connection from %s refused (too many open)", ip)
                transport.close()
                return
            self._arm()

        def _arm(self) -> None:
            if self._deadline is not None:
                self._deadline.cancel()
            self._deadline = self.loop.call_later(limits.request_s, self._late)

        def _late(self) -> None:
            self._deadline = None
            cycle = self.cycle
            if cycle is not None and not cycle.more_body and not cycle.response_complete:
                return  # the whole request is in: the app is answering (an event stream too)
            if self.transport.is_closing():
                return
            counters.cut += 1
            _log.info("web: %s cut off: no whole request in %g s", self.client, limits.request_s)
            self.transport.close()

        def eof_received(self) -> bool:  # type: ignore[override,unused-ignore]
            """The client is done sending (a half-close, as ``curl``-like clients and
            ``nc -N`` do): a whole request already in is still answered, then the
            connection closes; anything else closes it now."""
            cycle = self.cycle
            if cycle is not None and not cycle.response_complete and not cycle.more_body:
                self._half_closed = True
                return True
            return False

        _half_closed = False

        def on_response_complete(self) -> None:
            super().on_response_complete()
            if self._half_closed:
                self.transport.close()
            elif not self.transport.is_closing():
                self._arm()  # the next request on this connection has the same deadline

        def connection_lost(self, exc: Exception | None) -> None:
            if self._deadline is not None:
                self._deadline.cancel()
                self._deadline = None
            super().connection_lost(exc)

    return _Protocol


class WebServer:
    """``app`` served on ``host:port`` by uvicorn on a thread; a context manager.

    The socket is bound here (port 0: a free one, see :attr:`address`); InputError when it
    cannot be.
    """

    def __init__(self, app: App, host: str, port: int, limits: Limits) -> None:
        self.counters = ServerCounters()
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        # IPPROTO_TCP named: asyncio sets TCP_NODELAY only on sockets that say it (else each
        # answer on a kept-alive connection waits ~40 ms for a delayed ACK)
        self._sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._sock.bind((host, port))
        except OSError as err:
            self._sock.close()
            raise InputError(f"cannot serve the page on {host}:{port}: {err.strerror}") from err
        self.address: tuple[str, int] = self._sock.getsockname()[:2]
        config = uvicorn.Config(
            app,
            http=_protocol(limits, self.counters),
            ws="none",
            lifespan="off",
            interface="asgi3",
            log_config=None,
            access_log=False,  # a request line may carry a pairing token
            proxy_headers=False,
            server_header=False,
            limit_concurrency=limits.max_connections,
            timeout_keep_alive=limits.keep_alive_s,
            h11_max_incomplete_event_size=limits.max_head_bytes,
            timeout_graceful_shutdown=2,
        )
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._run, name="web", daemon=True)
        self._failed: BaseException | None = None

    def _run(self) -> None:
        try:
            self._server.run(sockets=[self._sock])
        except BaseException as err:  # told to the starting thread, then logged
            self._failed = err
            _log.exception("web: the page's server stopped")

    def __enter__(self) -> WebServer:
        self._thread.start()
        deadline = time.monotonic() + 20.0
        while not self._server.started:
            if self._failed is not None or not self._thread.is_alive():
                raise InputError(f"the page's server did not start: {self._failed}")
            if time.monotonic() > deadline:
                raise InputError("the page's server did not start within 20 s")
            time.sleep(0.01)
        return self

    def __exit__(self, *exc: Any) -> None:
        self._server.should_exit = True
        self._thread.join(timeout=10.0)
        self._sock.close()
