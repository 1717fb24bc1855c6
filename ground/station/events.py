"""The live page's event stream (``GET /events``, Server-Sent Events), bounded.

After every change of the station's state each open stream says ``data: <version>`` (the
page then re-reads ``/state.json``); a ``: keep-alive`` comment goes out every
``keepalive_s`` otherwise. The streams are bounded: ``max_event_clients`` in all and
``max_events_per_client`` from one address (503 with ``Retry-After`` past them), and each
is closed after ``events_s``, so an address that opens streams and keeps them cannot hold
the slots for good. Every stream starts with ``retry: <ms>``: a browser's ``EventSource``
reconnects by itself after a stream ends, and the page (``station.js``) opens a new one
with a back-off after a 503.

:class:`Changes` carries the state's version from any thread (the MAVLink link's) to the
server's event loop.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time

import anyio

from holescan.ground.station.guard import Limits, Receive, Scope, Send, refuse

__all__ = ["Changes", "EventStream"]

_log = logging.getLogger(__name__)


class Changes:
    """The newest state version, awaited on the server's loop, set from any thread."""

    def __init__(self, version: int) -> None:
        self.version = version
        self.closing = False
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._waiters: set[asyncio.Future[None]] = set()

    def set(self, version: int) -> None:
        """A new version (any thread)."""
        with self._lock:
            self.version = version
            loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._wake)

    def close(self) -> None:
        """Every waiting stream returns (the station is closing)."""
        self.closing = True
        self.set(self.version)

    def _wake(self) -> None:
        for f in self._waiters:
            if not f.done():
                f.set_result(None)
        self._waiters.clear()

    async def wait(self, seen: int, timeout_s: float) -> int:
        """The version once it is not ``seen`` (or after ``timeout_s``, or closing)."""
        loop = asyncio.get_running_loop()
        with self._lock:
            self._loop = loop
            version = self.version
        if version != seen or self.closing:
            return version
        fut: asyncio.Future[None] = loop.create_future()
        self._waiters.add(fut)
        try:
            await asyncio.wait_for(fut, timeout_s)
        except TimeoutError:
            pass
        finally:
            self._waiters.discard(fut)
        return self.version


class EventStream:
    """``GET /events`` as an ASGI app (see the module docstring)."""

    def __init__(
        self, changes: Changes, limits: Limits, *, keepalive_s: float = 10.0, retry_ms: int = 2000
    ) -> None:
        self.changes = changes
        self.limits = limits
        self.keepalive_s = keepalive_s
        self.retry_ms = retry_ms
        self._open: dict[str, int] = {}
        self.refused = 0
        """Streams refused (503) so far."""
        self.served = 0
        """Streams opened so far."""

    @property
    def open(self) -> int:
        """Streams open now."""
        return sum(self._open.values())

    def _take(self, client: str) -> bool:
        lim = self.limits
        if self.open >= lim.max_event_clients or self._open.get(client, 0) >= (
            lim.max_events_per_client
        ):
            return False
        self._open[client] = self._open.get(client, 0) + 1
        self.served += 1
        return True

    def _give(self, client: str) -> None:
        self._open[client] -= 1
        if not self._open[client]:
            del self._open[client]

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["method"] not in ("GET", "HEAD"):
            await refuse(send, 405, "GET only", {"Allow": "GET"})
            return
        client = str((scope.get("client") or ("-", 0))[0])
        if not self._take(client):  # on the loop's one thread: no lock needed
            self.refused += 1
            _log.warning("web: %s: event stream refused (all slots taken)", client)
            await refuse(send, 503, "too many event streams open", {"Retry-After": "5"})
            return
        try:
            headers = [(b"content-type", b"text/event-stream"), (b"cache-control", b"no-store")]
            await send({"type": "http.response.start", "status": 200, "headers": headers})
            if scope["method"] == "HEAD":
                await send({"type": "http.response.body", "body": b""})
                return
            async with anyio.create_task_group() as tg:

                async def until_gone() -> None:
                    while (await receive())["type"] != "http.disconnect":
                        pass
                    tg.cancel_scope.cancel()

                tg.start_soon(until_gone)
                await self._stream(send)
                tg.cancel_scope.cancel()
        except OSError:  # the browser went away mid-write
            return
        finally:
            self._give(client)

    async def _stream(self, send: Send) -> None:
        async def put(text: str) -> None:
            with anyio.fail_after(self.limits.io_timeout_s):  # a client that stopped reading
                await send({"type": "http.response.body", "body": text.encode(), "more_body": True})

        end = time.monotonic() + self.limits.events_s
        try:
            await put(f"retry: {self.retry_ms}\n\n")
            seen = -1
            while not self.changes.closing and (left := end - time.monotonic()) > 0:
                version = await self.changes.wait(seen, min(self.keepalive_s, left))
                if version == seen:
                    await put(": keep-alive\n\n")
                else:
                    await put(f"data: {version}\n\n")
                    seen = version
        except TimeoutError:
            return
        await send({"type": "http.response.body", "body": b""})
