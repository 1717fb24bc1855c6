"""The live page's HTTP server: every request through :mod:`ground.station.guard` first.

stdlib :mod:`http.server`, one thread per connection, HTTP/1.0 (one request per
connection). :func:`make_server` serves a :class:`Site` (what the page shows and changes;
:class:`~ground.station.web.StationWeb` is the one site): ``GET /``, ``/static/NAME.js``,
``/state.json``, ``/events``, ``/cards/hole-ID.jpg``, the live map's ``/map.json`` and
``/map/...`` (:meth:`Site.map_reply`, read-only like the state); ``POST /holes/ID/mark``.
The checks, in order, each answered with a 4xx that touches nothing: one ``Host`` (and at most one
``Origin``) header, the Host names the station (403), the request is not cross-site (403),
the client's rate (429), the method (405) and path (404); for a mark: a ``Content-Length``
(411) within the body bound (413), the station token (401), a JSON body (415, 400), a known
hole (404). The request head is bounded in bytes (414, 431) and in time (a connection still
sending its request after ``Limits.request_s`` is cut); open connections and event streams
are bounded too.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any, Protocol

from holescan.errors import InputError
from holescan.ground.station.audit import AuditError
from holescan.ground.station.guard import (
    BoundedReader,
    Deadlines,
    Limits,
    RateLimiter,
    StationToken,
    host_allowed,
    origin_allowed,
)
from holescan.ground.station.state import GroundHole

__all__ = ["GuardedServer", "Site", "make_server"]

_log = logging.getLogger(__name__)

_STATIC = re.compile(r"/static/([a-z0-9_-]{1,40}\.(?:js|css))")
_CTYPES = {"js": "text/javascript; charset=utf-8", "css": "text/css; charset=utf-8"}
_SECURITY_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Resource-Policy": "same-origin",
}
_PAGE_CSP = (
    "default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; "
    "script-src 'self' 'unsafe-inline'; connect-src 'self'; frame-ancestors 'none'; "
    "base-uri 'none'; form-action 'none'"
)
"""The page's scripts and styles are its own (inline or /static); nothing else loads."""


class Site(Protocol):
    """What the server serves and changes (:class:`~ground.station.web.StationWeb`)."""

    token: StationToken
    names: tuple[str, ...]
    limits: Limits
    rate: RateLimiter
    deadlines: Deadlines
    refused: int

    @property
    def port(self) -> int: ...

    @property
    def closing(self) -> bool: ...

    def state_json(self, can_mark: bool) -> bytes: ...

    def card(self, hole_id: int) -> bytes: ...

    def map_reply(self, path: str, query: str) -> tuple[int, bytes, str] | None: ...

    def mark(self, hole_id: int, mark: str, operator: object, client: str) -> GroundHole: ...

    def event_slot(self) -> bool: ...

    def event_done(self) -> None: ...

    def wait_change(self, seen: int, timeout_s: float) -> int: ...


def make_server(site: Site, host: str, port: int) -> GuardedServer:
    """The server of ``site`` bound to ``host:port`` (raises OSError when it cannot bind)."""
    return GuardedServer((host, port), _handler(site), site.limits)


class GuardedServer(ThreadingHTTPServer):
    """Counts open connections (per client and in all) and refuses those over the limits."""

    daemon_threads = True

    def __init__(
        self, addr: tuple[str, int], handler: type[BaseHTTPRequestHandler], limits: Limits
    ) -> None:
        self.limits = limits = limits or Limits()
        self.errors = 0
        """Requests whose handler raised (a bug: the fuzz test wants none)."""
        self._open: dict[object, str] = {}
        self._per: dict[str, int] = {}
        self._count_lock = threading.Lock()
        super().__init__(addr, handler)

    def verify_request(self, request: Any, client_address: Any) -> bool:
        ip = str(client_address[0])
        with self._count_lock:
            if (
                len(self._open) >= self.limits.max_connections
                or self._per.get(ip, 0) >= self.limits.max_per_client
            ):
                _log.warning("web: connection from %s refused (too many open)", ip)
                return False
            self._open[request] = ip
            self._per[ip] = self._per.get(ip, 0) + 1
        return True

    def shutdown_request(self, request: Any) -> None:
        with self._count_lock:
            ip = self._open.pop(request, None)
            if ip is not None:
                self._per[ip] -= 1
                if not self._per[ip]:
                    del self._per[ip]
        super().shutdown_request(request)

    def handle_error(self, request: Any, client_address: Any) -> None:
        self.errors += 1
        _log.exception("web: request from %s failed", client_address[0])


def _page() -> bytes:
    return resources.files("holescan.ground.station").joinpath("station.html").read_bytes()


def _static(name: str) -> bytes | None:
    try:
        return resources.files("holescan.ground.station").joinpath(name).read_bytes()
    except (FileNotFoundError, IsADirectoryError):
        return None


def _handler(web: Site) -> type[BaseHTTPRequestHandler]:
    limits = web.limits

    class Handler(BaseHTTPRequestHandler):
        server_version = "holescan-ground"
        sys_version = ""
        default_request_version = "HTTP/1.0"  # every answer has a status line (no HTTP/0.9)
        timeout = limits.io_timeout_s
        rfile: Any

        def setup(self) -> None:
            super().setup()
            self.rfile = BoundedReader(self.rfile, limits.max_head_bytes)
            web.deadlines.watch(self.connection, limits.request_s)

        def finish(self) -> None:
            web.deadlines.release(self.connection)
            with contextlib.suppress(OSError):
                super().finish()

        def log_message(self, format: str, *args: Any) -> None:
            _log.debug("web: " + format, *args)

        def log_request(self, code: int | str = "-", size: int | str = "-") -> None:
            line = getattr(self, "requestline", "").split("?", 1)[0]  # the query may hold the token
            _log.debug('web: %s "%s" %s', self.client_address[0], line[:200], code)

        def handle_one_request(self) -> None:
            """One request (HTTP/1.0: one per connection), through the guard first."""
            self.close_connection = True
            try:
                self.raw_requestline = self.rfile.readline(65537)
                if not self.raw_requestline:
                    return
                if self.rfile.exhausted:
                    self.requestline, self.request_version, self.command = "", "HTTP/1.0", ""
                    self._refuse(414, "request line too long")
                    return
                if not self.parse_request():
                    web.refused += 1
                    return
                if self.rfile.exhausted:
                    self._refuse(431, "request head too large")
                    return
                self._route()
                self.wfile.flush()
            except (TimeoutError, ConnectionError, OSError):
                return  # a slow, vanished or cut-off client: nothing to answer

        def _reply(
            self,
            code: int,
            body: bytes,
            ctype: str,
            headers: dict[str, str] | None = None,
        ) -> None:
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            for k, v in {
                "Cache-Control": "no-store",
                **_SECURITY_HEADERS,
                **(headers or {}),
            }.items():
                self.send_header(k, v)
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def _refuse(self, code: int, why: str, headers: dict[str, str] | None = None) -> None:
            web.refused += 1
            self._reply(code, why.encode() + b"\n", "text/plain; charset=utf-8", headers)

        def _route(self) -> None:
            hosts = self.headers.get_all("Host") or []
            origins = self.headers.get_all("Origin") or []
            if len(hosts) != 1 or len(origins) > 1:
                self._refuse(400, "one Host header (and at most one Origin) wanted")
                return
            local = str(self.connection.getsockname()[0])
            if not host_allowed(hosts[0], local, web.port, web.names):
                _log.warning("web: %s refused: Host %r", self.client_address[0], hosts[0][:80])
                self._refuse(403, "unknown Host: open the page by the station's address")
                return
            navigation = (
                self.command == "GET"
                and (self.headers.get("Sec-Fetch-Mode") or "").strip().lower() == "navigate"
            )
            if not origin_allowed(
                origins[0] if origins else None,
                self.headers.get("Sec-Fetch-Site"),
                hosts[0],
                navigation=navigation,
            ):
                _log.warning(
                    "web: %s refused: cross-site request (Origin %r)",
                    self.client_address[0],
                    (origins or ["-"])[0][:80],
                )
                self._refuse(403, "cross-site requests are refused")
                return
            if not web.rate.allow(str(self.client_address[0])):
                self._refuse(429, "too many requests", {"Retry-After": "1"})
                return
            if self.command == "GET":
                self._get()
            elif self.command == "POST":
                self._post()
            else:
                self._refuse(405, "GET or POST only", {"Allow": "GET, POST"})

        def _get(self) -> None:
            path, _, query = self.path.partition("?")
            web.deadlines.release(self.connection)
            static = _STATIC.fullmatch(path)
            if path in ("/", "/index.html"):
                self._reply(
                    200, _page(), "text/html; charset=utf-8", {"Content-Security-Policy": _PAGE_CSP}
                )
            elif static is not None and (data := _static(static[1])) is not None:
                self._reply(200, data, _CTYPES[static[1].rsplit(".", 1)[1]])
            elif path == "/state.json":
                can_mark = web.token.check(self.headers.get("Authorization"))
                self._reply(200, web.state_json(can_mark), "application/json")
            elif path == "/events":
                self._events()
            elif (m := re.fullmatch(r"/cards/hole-(\d{1,9})\.jpg", path)) is not None:
                try:
                    data = web.card(int(m[1]))
                except OSError:
                    self._refuse(404, "no such picture")
                    return
                self._reply(200, data, "image/jpeg", {"Cache-Control": "private, max-age=3600"})
            elif (mapped := web.map_reply(path, query)) is not None:
                code, body, ctype = mapped  # the live map's layers (maplayers.py)
                if code >= 400:
                    self._refuse(code, body.decode("utf-8", "replace"))
                else:
                    self._reply(code, body, ctype)
            else:
                self._refuse(404, "not found")

        def _events(self) -> None:
            if not web.event_slot():
                self._refuse(503, "too many event streams open", {"Retry-After": "5"})
                return
            try:
                self.send_response(200)
                self.send_header("Content-Type", "text/event-stream")
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                seen = -1
                while not web.closing:
                    version = web.wait_change(seen, 10.0)
                    if version == seen:
                        self.wfile.write(b": keep-alive\n\n")
                    else:
                        self.wfile.write(f"data: {version}\n\n".encode())
                        seen = version
                    self.wfile.flush()
            except OSError:  # the browser went away (or stopped reading: write timeout)
                return
            finally:
                web.event_done()

        def _post(self) -> None:
            m = re.fullmatch(r"/holes/(\d{1,9})/mark", self.path)
            if m is None:
                self._refuse(404, "not found")
                return
            if self.headers.get("Transfer-Encoding") is not None:
                self._refuse(411, "send a Content-Length (no chunked bodies)")
                return
            length_text = self.headers.get("Content-Length")
            if length_text is None or not length_text.strip().isdigit():
                self._refuse(411, "a Content-Length is required")
                return
            length = int(length_text)
            if length > limits.max_body_bytes:
                self._refuse(413, f"body over {limits.max_body_bytes} bytes")
                return
            if not web.token.check(self.headers.get("Authorization")):
                _log.warning("web: %s: a mark without the station token", self.client_address[0])
                self._refuse(
                    401,
                    "marking needs the station token: open the link printed at start",
                    {"WWW-Authenticate": 'Bearer realm="holescan ground station"'},
                )
                return
            ctype = (self.headers.get("Content-Type") or "").split(";", 1)[0].strip().lower()
            if ctype != "application/json":
                self._refuse(415, "Content-Type must be application/json")
                return
            self.rfile.allow(length)
            body = self.rfile.read(length)
            web.deadlines.release(self.connection)
            if len(body) != length:
                self._refuse(400, "body shorter than its Content-Length")
                return
            try:
                req = json.loads(body.decode("utf-8"))
                if not isinstance(req, dict):
                    raise ValueError("not an object")
                h = web.mark(
                    int(m[1]), str(req.get("mark")), req.get("operator"), self.client_address[0]
                )
            except LookupError as err:
                self._refuse(404, str(err))
                return
            except AuditError as err:  # the station's fault, not the request's
                _log.error("mark not made: %s", err)
                self._reply(503, f"mark not made: {err}\n".encode(), "text/plain; charset=utf-8")
                return
            except (ValueError, InputError, UnicodeDecodeError) as err:
                self._refuse(400, str(err))
                return
            out = {"id": h.id, "mark": h.mark, "tier": h.tier}
            self._reply(200, json.dumps(out).encode(), "application/json")

    return Handler
