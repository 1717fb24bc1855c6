"""Who may talk to the live page, and how much: every request is treated as hostile.

The live page (:mod:`ground.station.web`, served by :mod:`ground.station.webserver`) runs on
Starlette and uvicorn: request parsing and the bounds of a request's head (h11), keep-alive
and connection limits are the server's. What is policy is here, in :class:`GuardMiddleware`,
which every request passes before any route sees it:

* **Host** (:func:`host_allowed`): the ``Host`` header must name the address the request
  arrived on (the connection's own local address, port included), ``localhost`` when that
  address is loopback, or one of the names the station was told it serves (its hostname
  and ``HOSTNAME.local`` by default). A page of ``evil.example`` re-bound by DNS to the
  station's address (DNS rebinding) sends ``Host: evil.example`` and gets 403: it can
  neither read the holes nor hold an event stream. (Starlette's ``TrustedHostMiddleware``
  checks names only: it cannot say "the address this connection arrived on, this port",
  which is what a station bound to ``0.0.0.0`` on a changing incident network needs.)
* **Origin** (:func:`origin_allowed`): a request that carries ``Origin`` must come from
  the page itself (``http://`` + the checked Host); ``Sec-Fetch-Site`` must be
  ``same-origin`` or ``none`` when a browser sends it. A simple cross-site request (a
  ``text/plain`` POST that needs no CORS preflight) gets 403 before its body is read.
* **Rate** (:class:`RateLimiter`): a token bucket per client address (429).
* **Headers** on every answer: ``nosniff``, no framing, no referrer, the page's
  Content-Security-Policy (:data:`PAGE_CSP`: scripts and styles only from the station's
  own static files, nothing inline), ``Cache-Control: no-store`` unless the route says
  otherwise.

Who may *change* anything (mark a hole) is the operator's pairing
(:mod:`ground.station.pairing`), checked by the route.

Why on loopback too: the ground-station laptop runs a browser that visits other sites and
other programs (a second user, a plug-in, a local tool) can reach ``127.0.0.1``.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import threading
import time
from collections import OrderedDict
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from dataclasses import dataclass
from typing import Any

__all__ = [
    "PAGE_CSP",
    "GuardMiddleware",
    "Limits",
    "RateLimiter",
    "default_names",
    "host_allowed",
    "origin_allowed",
]

_log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
App = Callable[[Scope, Receive, Send], Awaitable[None]]

PAGE_CSP = (
    "default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; object-src 'none'; frame-ancestors 'none'; base-uri 'none'; "
    "form-action 'none'"
)
"""The page's scripts and styles are the station's own static files; nothing inline."""

SECURITY_HEADERS = {
    "x-content-type-options": "nosniff",
    "x-frame-options": "DENY",
    "referrer-policy": "no-referrer",
    "cross-origin-resource-policy": "same-origin",
    "content-security-policy": PAGE_CSP,
}


@dataclass(frozen=True)
class Limits:
    """Bounds of the live page's server.

    max_head_bytes : request line + headers (h11's incomplete-event bound). max_body_bytes :
    a POST body. rate_per_s, burst : a client's token bucket (requests). max_connections :
    open connections and requests in all (uvicorn's ``limit_concurrency``: 503 past it).
    max_per_client : open connections from one address (more are closed unanswered). A
    browser keeps up to 6 connections per page plus its event stream: 32 lets one laptop
    hold four tabs of the page (16 refused the third tab's loads) and still leaves half of
    ``max_connections`` to everyone else.
    max_event_clients, max_events_per_client : open ``/events`` streams in all / from one
    address (503 with ``Retry-After`` past them). events_s : an event stream is closed
    after this long (the page's ``EventSource`` reconnects on its own), so no client holds
    a slot for good. request_s : seconds to send a whole request (head and body) after
    connecting or after the previous answer (a slow-loris client is cut). keep_alive_s :
    an idle kept-alive connection is closed after this long. io_timeout_s : an event
    stream whose client stops reading for this long is ended.
    """

    max_head_bytes: int = 8192
    max_body_bytes: int = 1024
    rate_per_s: float = 20.0
    burst: float = 60.0
    max_connections: int = 64
    max_per_client: int = 32
    max_event_clients: int = 16
    max_events_per_client: int = 4
    events_s: float = 300.0
    request_s: float = 10.0
    keep_alive_s: int = 5
    io_timeout_s: float = 15.0


def default_names() -> tuple[str, ...]:
    """Names of this machine a browser may use: its hostname and ``HOSTNAME.local``."""
    name = socket.gethostname().lower()
    return (name, f"{name}.local") if name and name != "localhost" else ()


def _split_host(host: str) -> tuple[str, int | None] | None:
    """``Host`` header -> (name or address, port); None when malformed."""
    host = host.strip().lower()
    if host.startswith("["):
        addr, sep, rest = host[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            return None
        port_text = rest[1:]
    else:
        addr, _, port_text = host.partition(":")
        if ":" in port_text:
            return None
    if not addr:
        return None
    if not port_text:
        return addr, None
    if not port_text.isdigit() or len(port_text) > 5:
        return None
    return addr, int(port_text)


def host_allowed(host: str | None, local_addr: str, port: int, names: Iterable[str]) -> bool:
    """Does a ``Host`` header name this station?

    host : the header (None: absent, refused). local_addr, port : the address and port the
    connection arrived on. names : host names the station serves besides its addresses.

    >>> host_allowed("127.0.0.1:8080", "127.0.0.1", 8080, ())
    True
    >>> host_allowed("localhost:8080", "127.0.0.1", 8080, ())
    True
    >>> host_allowed("evil.example:8080", "127.0.0.1", 8080, ())
    False
    >>> host_allowed("192.168.1.7:8080", "127.0.0.1", 8080, ())
    False
    """
    if host is None:
        return False
    parts = _split_host(host)
    if parts is None:
        return False
    name, given_port = parts
    if (given_port if given_port is not None else 80) != port:
        return False
    try:
        local = ipaddress.ip_address(local_addr)
    except ValueError:
        return False
    try:
        return ipaddress.ip_address(name) == local
    except ValueError:
        pass
    if name == "localhost" or name.endswith(".localhost"):
        return local.is_loopback
    return name in {n.lower() for n in names}


def origin_allowed(
    origin: str | None, fetch_site: str | None, host: str, *, navigation: bool = False
) -> bool:
    """Is a request the page's own (or not a browser's cross-site one)?

    origin : the ``Origin`` header (None: absent, as from curl). fetch_site : the
    ``Sec-Fetch-Site`` header. host : the request's ``Host``, already checked.
    navigation : a GET that opens a page in the browser's window (``Sec-Fetch-Mode:
    navigate``), e.g. the pairing link clicked in a chat: allowed from another site (the
    other site cannot read what it opens, nor frame it: the page says ``frame-ancestors
    'none'``); a change never is.

    >>> origin_allowed("http://127.0.0.1:8080", "same-origin", "127.0.0.1:8080")
    True
    >>> origin_allowed("http://evil.example", None, "127.0.0.1:8080")
    False
    >>> origin_allowed(None, "cross-site", "127.0.0.1:8080")
    False
    >>> origin_allowed(None, "cross-site", "127.0.0.1:8080", navigation=True)
    True
    """
    site = None if fetch_site is None else fetch_site.strip().lower()
    if site is not None and site not in ("same-origin", "none") and not navigation:
        return False
    if origin is None:
        return True
    return origin.strip().lower() == f"http://{host.strip().lower()}"


class RateLimiter:
    """A token bucket per client: ``burst`` requests at once, ``rate_per_s`` after that.

    At most ``max_clients`` buckets are kept (the least recently seen go first).

    >>> now = [0.0]
    >>> r = RateLimiter(1.0, 2.0, clock=lambda: now[0])
    >>> [r.allow("a") for _ in range(3)], r.allow("b")
    ([True, True, False], True)
    >>> now[0] = 1.0
    >>> r.allow("a")
    True
    """

    def __init__(
        self,
        rate_per_s: float,
        burst: float,
        *,
        max_clients: int = 4096,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.rate_per_s, self.burst, self.max_clients = rate_per_s, burst, max_clients
        self._clock = clock
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()
        self._lock = threading.Lock()

    def allow(self, client: str) -> bool:
        """Take one request of ``client``'s bucket; False when it is empty."""
        now = self._clock()
        with self._lock:
            tokens, then = self._buckets.pop(client, (self.burst, now))
            tokens = min(self.burst, tokens + (now - then) * self.rate_per_s)
            ok = tokens >= 1.0
            self._buckets[client] = (tokens - 1.0 if ok else tokens, now)
            while len(self._buckets) > self.max_clients:
                self._buckets.popitem(last=False)
            return ok


def _header(scope: Scope, name: bytes) -> list[str]:
    return [v.decode("latin-1") for k, v in scope["headers"] if k == name]


async def refuse(send: Send, code: int, why: str, headers: dict[str, str] | None = None) -> None:
    """Answer ``code`` with one line of text (and the security headers)."""
    body = why.encode("utf-8") + b"\n"
    raw = [
        (b"content-type", b"text/plain; charset=utf-8"),
        (b"content-length", str(len(body)).encode()),
        (b"cache-control", b"no-store"),
        *((k.encode(), v.encode()) for k, v in SECURITY_HEADERS.items()),
        *((k.lower().encode(), v.encode()) for k, v in (headers or {}).items()),
    ]
    await send({"type": "http.response.start", "status": code, "headers": raw})
    await send({"type": "http.response.body", "body": body})


class GuardMiddleware:
    """The policy every request passes first (see the module docstring); ASGI middleware.

    app : the routes. names : host names served besides the addresses. rate : the
    clients' buckets. on_refuse : called once per refused request (the station's counter).
    max_head_bytes : the request line (414) and the whole head (431) over this are refused
    (h11 bounds a head that arrives in pieces; one that arrives whole is measured here).
    """

    def __init__(
        self,
        app: App,
        *,
        names: Iterable[str],
        rate: RateLimiter,
        on_refuse: Callable[[], None],
        max_head_bytes: int = Limits.max_head_bytes,
    ) -> None:
        self.app = app
        self.max_head_bytes = max_head_bytes
        self.names = tuple(names)
        self.rate = rate
        self.on_refuse = on_refuse

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        why = self._check(scope)
        if why is not None:
            self.on_refuse()
            code, text, extra = why
            await refuse(send, code, text, extra)
            return

        async def send_guarded(message: Message) -> None:
            if message["type"] == "http.response.start":
                have = {k.lower() for k, _ in message.get("headers", [])}
                add = [
                    (k.encode(), v.encode())
                    for k, v in SECURITY_HEADERS.items()
                    if k.encode() not in have
                ]
                if b"cache-control" not in have:
                    add.append((b"cache-control", b"no-store"))
                message["headers"] = [*message.get("headers", []), *add]
                if message["status"] >= 400:
                    self.on_refuse()
            await send(message)

        await self.app(scope, receive, send_guarded)

    def _check(self, scope: Scope) -> tuple[int, str, dict[str, str] | None] | None:
        """None when the request may go on, else (status, why, extra headers)."""
        client = str((scope.get("client") or ("-", 0))[0])
        line = len(scope["method"]) + len(scope["raw_path"]) + len(scope["query_string"]) + 12
        if line > self.max_head_bytes:
            return 414, "request line too long", None
        if line + sum(len(k) + len(v) + 4 for k, v in scope["headers"]) > self.max_head_bytes:
            return 431, "request head too large", None
        hosts, origins = _header(scope, b"host"), _header(scope, b"origin")
        if len(hosts) != 1 or len(origins) > 1:
            return 400, "one Host header (and at most one Origin) wanted", None
        local, port = scope.get("server") or ("", 0)
        if not host_allowed(hosts[0], str(local), int(port or 0), self.names):
            _log.warning("web: %s refused: Host %r", client, hosts[0][:80])
            return 403, "unknown Host: open the page by the station's address", None
        modes = _header(scope, b"sec-fetch-mode")
        navigation = (
            scope["method"] == "GET" and bool(modes) and modes[0].strip().lower() == "navigate"
        )
        sites = _header(scope, b"sec-fetch-site")
        if not origin_allowed(
            origins[0] if origins else None,
            sites[0] if sites else None,
            hosts[0],
            navigation=navigation,
        ):
            _log.warning(
                "web: %s refused: cross-site request (Origin %r)",
                client,
                (origins or ["-"])[0][:80],
            )
            return 403, "cross-site requests are refused", None
        if not self.rate.allow(client):
            return 429, "too many requests", {"Retry-After": "1"}
        return None
