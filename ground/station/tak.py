"""The link to TAK: mesh multicast, or a TAK server over TCP or TLS, sent with pytak.

How teams run TAK:

* **mesh** ``udp+wo://239.2.3.1:6969`` (the default): every ATAK/WinTAK/iTAK on the same
  network segment sees the holes, no server;
* **TAK server, TCP** ``tcp://HOST:8087``: the server forwards each event to every
  connected client (across networks, VPNs, the internet);
* **TAK server, TLS** ``tls://HOST:8089`` with a client certificate the server's CA
  signed: a ``.p12`` (PKCS#12, as TAK servers hand them out in connection data packages)
  and its password, or a PEM certificate and key; ``ca`` is the CA (PEM) that signed the
  server's certificate (without it the system's trust store is used).

:func:`tak_settings` turns the URL and :class:`TakTls` into pytak's settings and checks
them once, at start: unknown schemes, a certificate for a non-TLS URL, missing or
unreadable files, a wrong ``.p12`` password, a certificate that does not match its key
all give one :class:`~ground.errors.CotError` line (the station does not start with a
TAK link that can never work). A server that is down is not an error: the publisher
retries.

:class:`CotPublisher` runs pytak's client on its own asyncio thread;
:meth:`CotPublisher.publish` may be called from any thread.
"""

from __future__ import annotations

import asyncio
import configparser
import contextlib
import logging
import math
import re
import ssl
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

from holescan.ground.errors import CotError

__all__ = ["DEFAULT_COT_URL", "CotError", "CotPublisher", "TakTls", "tak_settings"]

_log = logging.getLogger(__name__)

DEFAULT_COT_URL = "udp+wo://239.2.3.1:6969"
_UID = re.compile(rb'<event\b[^>]*?\buid="([^"]*)"')
_SCHEMES = {"udp", "udp+wo", "udp+broadcast", "udp+broadcast+wo", "tcp", "tcp+wo", "tls"}
_TLS_SCHEMES = {"tls"}


@dataclass(frozen=True)
class TakTls:
    """A client certificate for a TAK server's TLS port.

    cert : ``.p12`` (PKCS#12: certificate and key, needs ``password``) or PEM certificate
    (needs ``key``). key : PEM private key (PEM certificates only). ca : PEM CA that
    signed the server's certificate (None: the system's trust store). password : the
    ``.p12`` password. server_name : the name in the server's certificate, when the URL
    has its IP address and the certificate only its host name.
    """

    cert: Path
    key: Path | None = None
    ca: Path | None = None
    password: str | None = field(default=None, repr=False)
    server_name: str | None = None

    @property
    def is_p12(self) -> bool:
        return self.cert.suffix.lower() == ".p12"


def _readable(path: Path, what: str) -> None:
    try:
        with path.open("rb") as f:
            f.read(1)
    except OSError as err:
        raise CotError(f"{what} {path}: {err.strerror or err}") from err


def tak_settings(url: str, tls: TakTls | None = None) -> dict[str, str]:
    """pytak's settings (``COT_URL``, ``PYTAK_TLS_*``) for ``url``, checked.

    Raises
    ------
    CotError : a URL pytak cannot use, TLS settings missing or not usable (see the
        module docstring); the message is one line naming the file or option.
    """
    parsed = urlparse(url)
    scheme = parsed.scheme.lower()
    if scheme not in _SCHEMES:
        raise CotError(
            f"TAK URL {url!r}: use udp+wo://239.2.3.1:6969 (mesh), tcp://HOST:8087 or "
            "tls://HOST:8089 (a TAK server)"
        )
    try:
        port = parsed.port
    except ValueError as err:
        raise CotError(f"TAK URL {url!r}: {err}") from err
    if not parsed.hostname or port is None:
        raise CotError(f"TAK URL {url!r} needs a host and a port (tcp://HOST:8087)")
    settings = {"COT_URL": url}
    if scheme not in _TLS_SCHEMES:
        if tls is not None:
            raise CotError(f"a TAK client certificate is for tls:// URLs, not {url!r}")
        return settings
    if tls is None:
        raise CotError(f"TAK URL {url!r} needs a client certificate (--tak-cert)")
    _readable(tls.cert, "TAK client certificate")
    settings["PYTAK_TLS_CLIENT_CERT"] = str(tls.cert)
    if tls.is_p12:
        if tls.key is not None:
            raise CotError(f"{tls.cert} is a .p12 (it holds its key): drop --tak-key")
        if tls.password is None:
            raise CotError(f"{tls.cert} is a .p12: give its password (--tak-password-file)")
        settings["PYTAK_TLS_CLIENT_PASSWORD"] = tls.password
    else:
        if tls.key is None:
            raise CotError(f"{tls.cert} is a PEM certificate: give its key (--tak-key)")
        _readable(tls.key, "TAK client key")
        settings["PYTAK_TLS_CLIENT_KEY"] = str(tls.key)
        if tls.password is not None:
            settings["PYTAK_TLS_CLIENT_PASSWORD"] = tls.password
    if tls.ca is not None:
        _readable(tls.ca, "TAK server CA")
        settings["PYTAK_TLS_CLIENT_CAFILE"] = str(tls.ca)
    if tls.server_name is not None:
        settings["PYTAK_TLS_SERVER_EXPECTED_HOSTNAME"] = tls.server_name
    _check_tls(settings, tls)
    return settings


def _check_tls(settings: dict[str, str], tls: TakTls) -> None:
    """Build pytak's TLS context once, so a bad certificate fails at start."""
    from pytak.client_functions import get_ssl_ctx, get_tls_config

    parser = configparser.ConfigParser(interpolation=None)
    parser["tak"] = settings
    try:
        get_ssl_ctx(get_tls_config(parser["tak"]))
    except (ValueError, SyntaxError, SystemError, OSError, ssl.SSLError) as err:
        cause = err.__cause__ or err
        if tls.is_p12:
            why = f"{tls.cert}: not a PKCS#12 file, or the password is wrong ({cause})"
        elif tls.ca is not None and isinstance(cause, ssl.SSLError) and "ca" in str(err).lower():
            why = f"{tls.ca}: not a PEM CA certificate ({cause})"
        else:
            why = f"{tls.cert} / {tls.key}: not a PEM certificate and its key ({cause})"
        raise CotError(f"TAK client certificate not usable: {why}") from err


class CotPublisher:
    """pytak's client on its own asyncio thread; :meth:`publish` queues events.

    url : pytak ``COT_URL`` (``udp+wo://239.2.3.1:6969``, ``udp://HOST:PORT``,
    ``tcp://HOST:8087``, ``tls://HOST:8089`` with ``tls`` settings). extra : more pytak
    settings (``PYTAK_TLS_CLIENT_CERT`` ..., from :func:`tak_settings`). A link that cannot
    be opened or breaks is logged in one line and retried; events wait in the queue
    meanwhile. On a TCP/TLS link whatever the server sends (other clients' events, pings)
    is read and dropped, so the server never blocks on us; its end of the stream means a
    reconnect. After a reconnect the newest event of every uid sent so far is sent again
    (a restarted server has forgotten them, and the write that met the closed stream may
    have been lost). A link that keeps failing soon after it opens (a server refusing our
    certificate) backs off up to 30 s between tries, and each distinct warning is logged
    at most once a minute.
    """

    def __init__(self, url: str = DEFAULT_COT_URL, extra: dict[str, str] | None = None) -> None:
        self.url = url
        self._config = {"COT_URL": url, **(extra or {})}
        self._loop = asyncio.new_event_loop()
        self._queue: asyncio.Queue[bytes] | None = None
        self._thread = threading.Thread(target=self._run, name="cot", daemon=True)
        self._ready = threading.Event()
        self._task: asyncio.Task[None] | None = None
        self.sent = 0
        self.errors = 0
        self.connects = 0
        self._last: dict[bytes, bytes] = {}  # uid -> the newest event sent under it
        self._replay: list[bytes] = []  # of _last, still to send again after a reconnect
        self._warned_at: dict[str, float] = {}

    def __enter__(self) -> CotPublisher:
        self._thread.start()
        self._ready.wait(5.0)
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Send what is queued (up to 2 s), then stop the thread."""
        if self._loop.is_running():
            asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop)
        self._thread.join(timeout=5.0)

    async def _shutdown(self) -> None:
        q = self._queue
        for _ in range(20):
            if q is None or q.empty():
                break
            await asyncio.sleep(0.1)
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        self._loop.stop()

    def publish(self, events: list[bytes]) -> None:
        """Queue events for sending (any thread)."""
        q = self._queue
        if q is None:
            return
        for e in events:
            self._loop.call_soon_threadsafe(q.put_nowait, e)

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._queue = asyncio.Queue()
        self._task = self._loop.create_task(self._send_loop())
        self._ready.set()
        try:
            self._loop.run_forever()
        finally:
            self._loop.close()

    async def _open(self, config: Any) -> tuple[Any, asyncio.Task[str] | None]:
        """A TXWorker on a fresh connection, and the task draining a stream's reader."""
        import pytak  # imported here: pytak is needed only when TAK is on

        reader, writer = await pytak.protocol_factory(config)
        if self.connects:  # a reconnect: send them all again (replacing an older replay)
            self._replay = list(self._last.values())
        drain = None
        if isinstance(reader, asyncio.StreamReader):
            drain = asyncio.get_running_loop().create_task(_drain(reader))
            drain.add_done_callback(self._ended)
        self.connects += 1
        return pytak.TXWorker(self._queue, config, writer), drain

    def _ended(self, drain: asyncio.Task[str]) -> None:
        """Say at once why the server ended the stream (a refused certificate ...)."""
        if not drain.cancelled():
            self._warn(f"TAK link {self.url}: {drain.result()}")

    def _warn(self, text: str) -> None:
        """Log a warning, each distinct one at most once a minute."""
        now = time.monotonic()
        if now - self._warned_at.get(text, -math.inf) >= 60.0:
            self._warned_at[text] = now
            _log.warning("%s", text)

    async def _send_loop(self) -> None:
        assert self._queue is not None
        parser = configparser.ConfigParser(interpolation=None)
        parser["holescan"] = self._config
        config = parser["holescan"]
        tx: Any = None
        drain: asyncio.Task[str] | None = None
        pending: bytes | None = None
        warned = False
        opened_at, fails = 0.0, 0
        try:
            while True:
                if tx is None:
                    try:
                        tx, drain = await self._open(config)
                        opened_at = time.monotonic()
                        if warned:
                            _log.warning("TAK link %s is up again", self.url)
                        warned = False
                    except Exception as err:
                        if not warned:
                            _log.warning(
                                "TAK link %s cannot be opened (%s); retrying", self.url, err
                            )
                        warned = True
                        await asyncio.sleep(2.0)
                        continue
                if pending is not None:
                    data = pending
                elif self._replay:
                    data = self._replay.pop(0)
                else:
                    data = await self._queue.get()
                try:
                    if drain is not None and drain.done():
                        raise ConnectionError(drain.result())
                    await tx.send_data(data)
                    self.sent += 1
                    uid = _UID.search(data)
                    if uid is not None:
                        self._last.pop(uid[1], None)
                        self._last[uid[1]] = data
                    pending = None
                except Exception as err:
                    self.errors += 1
                    self._warn(f"TAK send to {self.url} failed ({err}); reconnecting")
                    _close(drain)
                    _close_writer(tx)
                    pending, tx = data, None
                    fails = fails + 1 if time.monotonic() - opened_at < 10.0 else 1
                    await asyncio.sleep(min(30.0, 2.0 ** (fails - 1)))
        finally:
            _close(drain)


async def _drain(reader: asyncio.StreamReader) -> str:
    """Read and drop what a TAK server sends until it closes the stream; return why it
    ended (a refused certificate shows here: ``TLSV1_ALERT_UNKNOWN_CA`` ...)."""
    try:
        while await reader.read(65536):
            pass
    except (ConnectionError, ssl.SSLError, OSError) as err:
        return f"the server closed the connection: {err}"
    return "the server closed the connection"


def _close_writer(tx: Any) -> None:
    writer = getattr(tx, "writer", None)
    if writer is not None and hasattr(writer, "close"):
        with contextlib.suppress(Exception):
            writer.close()


def _close(task: asyncio.Task[str] | None) -> None:
    if task is not None and not task.done():
        task.cancel()
