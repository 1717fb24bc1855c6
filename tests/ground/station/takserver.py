"""A real TAK server on loopback for the tests: taky, certificates made here, a TAK client.

* :func:`taky_program`: the ``taky`` executable (a Python TAK server, PyPI ``taky`` 0.10).
  It pins Flask 2 and imports ``pkg_resources``, so it lives in its own venv, which
  ``.ci/run`` makes (``build/taky-venv``) and names in ``HOLESCAN_TAKY``; without it the
  tests that need it are skipped, saying how to make it.
* :func:`make_pki`: a CA, the server's certificate (SAN 127.0.0.1 and localhost), client
  certificates as ``.p12`` (password ``atakatak``, as TAK servers hand them out) and as
  PEM certificate + key, and a client certificate of another CA (a stranger's).
* :class:`Taky`: one server per test (taky replays the points it stores to every client
  that joins, even withdrawn ones), over TCP or TLS with client certificates required.
* :class:`TakClient`: a pytak client on its own asyncio loop that collects every event the
  server forwards; it pings (``t-x-c-t``) and waits for taky's ``takPong`` first, so it
  is registered before anything is published.
"""

from __future__ import annotations

import asyncio
import configparser
import contextlib
import datetime as dt
import ipaddress
import os
import signal
import socket
import subprocess
import threading
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.hazmat.primitives.serialization import pkcs12
from cryptography.x509.oid import NameOID

REPO = Path(__file__).resolve().parents[3]
TAKY_VENV = REPO / "build" / "taky-venv"
P12_PASSWORD = "atakatak"


def taky_program() -> Path:
    """The taky executable: ``HOLESCAN_TAKY``, else ``build/taky-venv/bin/taky``; skips the
    test (with how to make it) when there is none."""
    named = os.environ.get("HOLESCAN_TAKY")
    path = Path(named) if named else TAKY_VENV / "bin" / "taky"
    if not path.is_file():
        pytest.skip(
            f"no taky TAK server at {path}: .ci/run makes it (python3 -m venv {TAKY_VENV}; "
            f'{TAKY_VENV}/bin/pip install "taky==0.10" "setuptools<81")'
        )
    return path


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# -- certificates ---------------------------------------------------------------------------
def _name(cn: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])


def _cert(
    cn: str,
    key: ec.EllipticCurvePrivateKey,
    issuer: x509.Name,
    issuer_key: ec.EllipticCurvePrivateKey,
    *,
    ca: bool = False,
    san: list[x509.GeneralName] | None = None,
) -> x509.Certificate:
    now = dt.datetime.now(dt.UTC)
    b = (
        x509.CertificateBuilder()
        .subject_name(_name(cn))
        .issuer_name(issuer)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=2))
        .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True)
    )
    if san:
        b = b.add_extension(x509.SubjectAlternativeName(san), critical=False)
    return b.sign(issuer_key, hashes.SHA256())


def _pem(c: x509.Certificate) -> bytes:
    return c.public_bytes(serialization.Encoding.PEM)


def _key_pem(k: ec.EllipticCurvePrivateKey) -> bytes:
    return k.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


@dataclass(frozen=True)
class Pki:
    """Files of :func:`make_pki`. p12 : client name -> .p12; pem : name -> (cert, key)."""

    folder: Path
    ca: Path
    server_cert: Path
    server_key: Path
    p12: dict[str, Path]
    pem: dict[str, tuple[Path, Path]]
    stranger_p12: Path


def make_pki(
    folder: Path,
    clients: tuple[str, ...] = ("station", "reader"),
    server_names: tuple[str, ...] = ("localhost", "127.0.0.1"),
) -> Pki:
    """A CA, the server's certificate and key (its subject alternative names
    ``server_names``: host names or IP addresses), each client's ``.p12`` and PEM pair, and
    a stranger's ``.p12`` signed by another CA (EC P-256: milliseconds each)."""
    folder.mkdir(parents=True, exist_ok=True)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca = _cert("holescan test CA", ca_key, _name("holescan test CA"), ca_key, ca=True)
    (folder / "ca.pem").write_bytes(_pem(ca))
    server_key = ec.generate_private_key(ec.SECP256R1())
    san: list[x509.GeneralName] = []
    for n in server_names:
        try:
            san.append(x509.IPAddress(ipaddress.ip_address(n)))
        except ValueError:
            san.append(x509.DNSName(n))
    server = _cert(server_names[0], server_key, ca.subject, ca_key, san=san)
    (folder / "server.pem").write_bytes(_pem(server))
    (folder / "server.key").write_bytes(_key_pem(server_key))

    def client(cn: str, issuer: x509.Certificate, issuer_key: ec.EllipticCurvePrivateKey) -> Path:
        k = ec.generate_private_key(ec.SECP256R1())
        c = _cert(cn, k, issuer.subject, issuer_key)
        (folder / f"{cn}.pem").write_bytes(_pem(c))
        (folder / f"{cn}.key").write_bytes(_key_pem(k))
        p12 = folder / f"{cn}.p12"
        enc = serialization.BestAvailableEncryption(P12_PASSWORD.encode())
        p12.write_bytes(pkcs12.serialize_key_and_certificates(cn.encode(), k, c, [issuer], enc))
        return p12

    p12s = {cn: client(cn, ca, ca_key) for cn in clients}
    other_key = ec.generate_private_key(ec.SECP256R1())
    other = _cert("another CA", other_key, _name("another CA"), other_key, ca=True)
    return Pki(
        folder,
        folder / "ca.pem",
        folder / "server.pem",
        folder / "server.key",
        p12s,
        {cn: (folder / f"{cn}.pem", folder / f"{cn}.key") for cn in clients},
        client("stranger", other, other_key),
    )


# -- the server -----------------------------------------------------------------------------
class Taky:
    """taky on 127.0.0.1 (TCP, or TLS requiring client certificates of ``pki``'s CA)."""

    def __init__(self, folder: Path, pki: Pki | None = None, port: int | None = None) -> None:
        self.program = taky_program()
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.port = port or free_tcp_port()
        self.tls = pki is not None
        ssl = (
            f"enabled = true\nclient_cert_required = true\nca = {pki.ca}\n"
            f"cert = {pki.server_cert}\nkey = {pki.server_key}\ncert_db = {folder / 'certs.txt'}\n"
            if pki is not None
            else "enabled = false\n"
        )
        self.config = folder / "taky.conf"
        self.config.write_text(
            f"[taky]\nbind_ip = 127.0.0.1\nroot_dir = {folder}\n"
            f"[cot_server]\nport = {self.port}\nlog_cot =\n[ssl]\n{ssl}"
        )
        self.log = folder / "taky.log"
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"{'tls' if self.tls else 'tcp'}://127.0.0.1:{self.port}"

    def __enter__(self) -> Taky:
        with self.log.open("wb") as log:
            self.proc = subprocess.Popen(
                [str(self.program), "-c", str(self.config)],
                stdout=log,
                stderr=subprocess.STDOUT,
                cwd=self.folder,
            )
        deadline = time.monotonic() + 30.0  # a liveness bound: it listens in ~0.3 s idle
        while True:
            if self.proc.poll() is not None:
                raise AssertionError(f"taky exited: {self.log.read_text()[-2000:]}")
            with (
                contextlib.suppress(OSError),
                socket.create_connection(("127.0.0.1", self.port), 0.5),
            ):
                return self
            if time.monotonic() > deadline:
                self.__exit__()
                raise AssertionError("taky did not listen within 30 s")
            time.sleep(0.05)

    def __exit__(self, *exc: object) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(10.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5.0)

    def log_text(self) -> str:
        return self.log.read_text(errors="replace")


# -- a TAK client ---------------------------------------------------------------------------
def _ping(uid: str) -> bytes:
    now = dt.datetime.now(dt.UTC)
    t = now.strftime("%Y-%m-%dT%H:%M:%S.000Z")
    s = (now + dt.timedelta(seconds=60)).strftime("%Y-%m-%dT%H:%M:%S.000Z")
    return (
        f'<event version="2.0" uid="{uid}" type="t-x-c-t" how="h-g-i-g-o" time="{t}" '
        f'start="{t}" stale="{s}"><point lat="0" lon="0" hae="0" ce="9999999" '
        f'le="9999999"/><detail/></event>'
    ).encode()


class TakClient:
    """A pytak client of the server collecting the events it forwards (``events``)."""

    def __init__(self, url: str, tls: dict[str, str] | None = None, name: str = "reader") -> None:
        self.settings = {"COT_URL": url, **(tls or {})}
        self.name = name
        self.events: list[ET.Element] = []
        self.raw: list[bytes] = []
        self.closed_by_server = threading.Event()
        self.error: BaseException | None = None
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._task: asyncio.Task[None] | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> TakClient:
        self._thread.start()
        if not self._ready.wait(30.0):  # liveness bound; the pong comes in milliseconds
            raise AssertionError(f"{self.name}: no takPong from the server ({self.error})")
        if self.error is not None:
            raise AssertionError(f"{self.name}: {self.error}")
        return self

    def __exit__(self, *exc: object) -> None:
        if self._task is not None:
            with contextlib.suppress(RuntimeError):  # the loop already ended (refused)
                self._loop.call_soon_threadsafe(self._task.cancel)
        self._thread.join(timeout=5.0)

    def send(self, data: bytes) -> None:
        async def write() -> None:
            assert self._writer is not None
            self._writer.write(data)
            await self._writer.drain()

        asyncio.run_coroutine_threadsafe(write(), self._loop).result(10.0)

    def _run(self) -> None:
        self._task = self._loop.create_task(self._main())
        with contextlib.suppress(asyncio.CancelledError):
            self._loop.run_until_complete(self._task)
        self._loop.close()

    async def _main(self) -> None:
        import pytak

        parser = configparser.ConfigParser(interpolation=None)
        parser["c"] = self.settings
        try:
            reader, writer = await pytak.protocol_factory(parser["c"])
            self._writer = writer
            writer.write(_ping(f"{self.name}-ping"))
            await writer.drain()
            buf = b""
            while True:
                chunk = await reader.read(65536)
                if not chunk:
                    self.closed_by_server.set()
                    return
                buf += chunk
                while b"</event>" in buf:
                    one, buf = buf.split(b"</event>", 1)
                    one = one[one.find(b"<event") :] + b"</event>"
                    ev = ET.fromstring(one)
                    if ev.get("uid") == "takPong":
                        self._ready.set()
                        continue
                    self.raw.append(one)
                    self.events.append(ev)
        except asyncio.CancelledError:
            raise
        except Exception as err:  # a refused handshake, a reset: what the test looks at
            self.error = err
            self.closed_by_server.set()
            self._ready.set()

    def of(self, uid: str) -> list[ET.Element]:
        return [e for e in self.events if e.get("uid") == uid]


def p12_settings(pki: Pki, who: str) -> dict[str, str]:
    """pytak's settings for client ``who``'s .p12 (and the CA that signed the server)."""
    return {
        "PYTAK_TLS_CLIENT_CERT": str(pki.p12[who]),
        "PYTAK_TLS_CLIENT_PASSWORD": P12_PASSWORD,
        "PYTAK_TLS_CLIENT_CAFILE": str(pki.ca),
    }
