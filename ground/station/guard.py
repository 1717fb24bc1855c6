"""Who may talk to the live page, and how much: every request is treated as hostile.

The live page (:mod:`ground.station.web`) passes every request through these checks
before it looks at the state:

* **Host** (:func:`host_allowed`): the ``Host`` header must name the address the request
  arrived on (the connection's own local address, port included), ``localhost`` when that
  address is loopback, or one of the names the station was told it serves (its hostname
  and ``HOSTNAME.local`` by default). A page of ``evil.example`` re-bound by DNS to the
  station's address (DNS rebinding) sends ``Host: evil.example`` and gets 403: it can
  neither read the holes nor hold an event stream.
* **Origin** (:func:`origin_allowed`): a request that carries ``Origin`` must come from
  the page itself (``http://`` + the checked Host); ``Sec-Fetch-Site`` must be
  ``same-origin`` or ``none`` when a browser sends it. A simple cross-site request (a
  ``text/plain`` POST that needs no CORS preflight) gets 403 before its body is read.
* **Secret** (:class:`StationToken`): every change needs ``Authorization: Bearer TOKEN``,
  the station's secret, wherever the page listens, loopback included (a browser is paired
  once by opening the ``?token=`` link printed at start; the page keeps the token in the
  browser's ``localStorage``). Without it the page is read-only. The token is kept in
  ``DIR/.station-token`` (mode 0600), so a restart keeps every browser paired; delete the
  file to revoke every browser.
* **Bounds** (:class:`Limits`): request head (line + headers) and body sizes, requests per
  second per client (:class:`RateLimiter`, a token bucket), open connections per client
  and in all, event-stream clients, and a deadline for reading a whole request
  (:class:`Deadlines`: a slow-loris client that drips one byte at a time is cut off).

Why on loopback too: the ground-station laptop runs a browser that visits other sites and
other programs (a second user, a plug-in, a local tool) can reach ``127.0.0.1``; the token
is one click per browser (the printed link), the same as Jupyter's.
"""

from __future__ import annotations

import contextlib
import hmac
import ipaddress
import logging
import os
import secrets
import socket
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from holescan.errors import InputError

__all__ = [
    "TOKEN_FILE",
    "BoundedReader",
    "Deadlines",
    "Limits",
    "RateLimiter",
    "StationToken",
    "default_names",
    "host_allowed",
    "origin_allowed",
]

_log = logging.getLogger(__name__)

TOKEN_FILE = ".station-token"
"""The station's secret in its folder (mode 0600); delete it to un-pair every browser."""


@dataclass(frozen=True)
class Limits:
    """Bounds of the live page's HTTP server.

    max_head_bytes : request line + headers. max_body_bytes : a POST body. rate_per_s,
    burst : a client's token bucket (requests). max_connections, max_per_client : open
    connections in all / from one address. max_event_clients : open ``/events`` streams.
    request_s : seconds to send a whole request (head and body) after connecting.
    io_timeout_s : a socket read or write that waits longer ends the connection.
    """

    max_head_bytes: int = 8192
    max_body_bytes: int = 1024
    rate_per_s: float = 20.0
    burst: float = 60.0
    max_connections: int = 64
    max_per_client: int = 16
    max_event_clients: int = 16
    request_s: float = 10.0
    io_timeout_s: float = 15.0


class StationToken:
    """The station's secret: ``DIR/.station-token``, made on first start (mode 0600).

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     t = StationToken.load_or_create(Path(d))
    ...     t.check("Bearer " + t.value), t.check("Bearer nope"), t.check(None)
    (True, False, False)
    """

    def __init__(self, value: str) -> None:
        if len(value) < 16:
            raise InputError("the station token must have at least 16 characters")
        self.value = value

    def __repr__(self) -> str:  # never in a log line
        return "StationToken(***)"

    @classmethod
    def load_or_create(cls, folder: Path) -> StationToken:
        """The token kept in ``folder`` (a new random one, 32 bytes, when none is)."""
        path = folder / TOKEN_FILE
        try:
            text = path.read_text().strip()
        except FileNotFoundError:
            text = ""
        except OSError as err:
            raise InputError(f"cannot read {path}: {err.strerror}") from err
        if text:
            return cls(text)
        value = secrets.token_urlsafe(32)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "w") as f:
                f.write(value + "\n")
        except OSError as err:
            raise InputError(f"cannot write the station token {path}: {err.strerror}") from err
        return cls(value)

    def check(self, authorization: str | None) -> bool:
        """True when an ``Authorization`` header carries this token (``Bearer TOKEN``)."""
        if not authorization:
            return False
        scheme, _, given = authorization.strip().partition(" ")
        if scheme.lower() != "bearer":
            return False
        return hmac.compare_digest(given.strip().encode(), self.value.encode())


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


class Deadlines:
    """Connections that must finish sending their request by a deadline.

    One thread checks every ``tick_s``; a connection past its deadline is shut down (its
    handler's read then ends). Use as a context manager.
    """

    def __init__(self, tick_s: float = 0.25) -> None:
        self._due: dict[socket.socket, float] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._tick_s = tick_s
        self._thread = threading.Thread(target=self._run, name="web-deadlines", daemon=True)
        self.cut = 0
        """Connections cut off so far."""

    def __enter__(self) -> Deadlines:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def watch(self, conn: socket.socket, within_s: float) -> None:
        with self._lock:
            self._due[conn] = time.monotonic() + within_s

    def release(self, conn: socket.socket) -> None:
        with self._lock:
            self._due.pop(conn, None)

    def _run(self) -> None:
        while not self._stop.wait(self._tick_s):
            now = time.monotonic()
            with self._lock:
                late = [c for c, t in self._due.items() if t <= now]
                for c in late:
                    del self._due[c]
            for c in late:
                self.cut += 1
                with contextlib.suppress(OSError):
                    c.shutdown(socket.SHUT_RDWR)


class BoundedReader:
    """A connection's input that gives out at most ``budget`` bytes (then end of file).

    The request head is read with ``budget = max_head_bytes``; :attr:`exhausted` tells that
    it was cut there. :meth:`allow` adds the bytes of an accepted body.
    """

    def __init__(self, raw: object, budget: int) -> None:
        self._raw = raw
        self.budget = budget
        self.exhausted = False

    def allow(self, n: int) -> None:
        self.budget += n

    def _take(self, want: int) -> int:
        n = self.budget if want < 0 else min(want, self.budget)
        if n <= 0 and want != 0:
            self.exhausted = True
        return max(n, 0)

    def readline(self, limit: int = -1) -> bytes:
        n = self._take(limit)
        if n == 0:
            return b""
        line: bytes = self._raw.readline(n)  # type: ignore[attr-defined]
        self.budget -= len(line)
        if self.budget <= 0 and not line.endswith(b"\n"):
            self.exhausted = True
        return line

    def read(self, size: int = -1) -> bytes:
        n = self._take(size)
        if n == 0:
            return b""
        data: bytes = self._raw.read(n)  # type: ignore[attr-defined]
        self.budget -= len(data)
        return data

    def close(self) -> None:
        self._raw.close()  # type: ignore[attr-defined]
