"""The live page treats every request as hostile (attacks, bounds, a fuzz).

Each test runs a real :class:`StationWeb` (Starlette on uvicorn) on a free port and talks
to it over real sockets, byte for byte, as an attacker's browser or script would. "Nothing
changes" is checked on the state file's bytes, the state's version and the audit trail.
"""

from __future__ import annotations

import json
import random
import socket
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from holescan.ground import StationState
from holescan.ground.station.audit import AuditTrail
from holescan.ground.station.guard import Limits
from holescan.ground.station.web import StationWeb


@dataclass
class Reply:
    status: int
    headers: dict[str, str]
    body: bytes


def send(port: int, data: bytes, host: str = "127.0.0.1", timeout_s: float = 10.0) -> Reply:
    """One raw request (bytes as given) -> the parsed reply (status 0: closed unanswered)."""
    with socket.create_connection((host, port), timeout=timeout_s) as s:
        try:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        chunks = []
        try:
            while chunk := s.recv(65536):
                chunks.append(chunk)
        except (ConnectionResetError, TimeoutError):
            pass
    raw = b"".join(chunks)
    if not raw:
        return Reply(0, {}, b"")
    head, _, body = raw.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    headers = {}
    for line in lines[1:]:
        k, _, v = line.partition(":")
        headers[k.strip().lower()] = v.strip()
    return Reply(int(lines[0].split()[1]), headers, body)


def request(
    port: int,
    method: str,
    path: str,
    headers: dict[str, str] | None = None,
    body: bytes = b"",
    host: str = "127.0.0.1",
) -> Reply:
    hdrs = {"Host": f"{host}:{port}", **(headers or {})}
    if body or method == "POST":
        hdrs.setdefault("Content-Length", str(len(body)))
    head = f"{method} {path} HTTP/1.1\r\n" + "".join(f"{k}: {v}\r\n" for k, v in hdrs.items())
    return send(port, head.encode() + b"\r\n" + body, host=host)


def mark_body(mark: str = "rejected", **extra: str) -> bytes:
    return json.dumps({"mark": mark, **extra}).encode()


class Station:
    """A state with two holes and its page, one operator (Ana) paired;
    :meth:`fingerprint` = everything a change touches."""

    def __init__(self, folder: Path, host: str = "127.0.0.1", limits: Limits | None = None):
        self.state = StationState.open(folder)
        self.state.on_statustext("HOLE 1 0.88 43.6533100 -79.3831200")
        self.state.on_statustext("HOLE 2 0.41 43.6533400 -79.3831500")
        self.web = StationWeb(self.state, host, 0, limits=limits).__enter__()
        self.port = self.web.port
        self.pairing, self.token = self.web.pairings.issue("Ana")
        self.auth = {"Authorization": f"Bearer {self.token}"}

    def fingerprint(self) -> tuple[object, ...]:
        audit = self.state.folder / "audit.jsonl"
        return (
            self.state.version,
            self.state.path.read_bytes(),
            audit.read_bytes() if audit.is_file() else None,
            [h.mark for h in self.state.snapshot()[1]],
        )

    def close(self) -> None:
        self.web.__exit__(None, None, None)


@pytest.fixture
def station(tmp_path: Path) -> Iterator[Station]:
    s = Station(tmp_path / "st")
    yield s
    s.close()


def test_cross_site_text_plain_post_is_refused_and_changes_nothing(station: Station) -> None:
    # issue 23: a page of evil.example posts a text/plain body (no CORS preflight)
    before = station.fingerprint()
    for extra in ({}, station.auth):  # refused on its Origin, even if it had the token
        r = request(
            station.port,
            "POST",
            "/holes/1/mark",
            {"Origin": "http://evil.example", "Content-Type": "text/plain", **extra},
            b"rejected",
        )
        assert r.status == 403, r
    # the same from a browser that only says Sec-Fetch-Site (no Origin)
    r = request(
        station.port, "POST", "/holes/1/mark", {"Sec-Fetch-Site": "cross-site"}, mark_body()
    )
    assert r.status == 403
    # a cross-site form that navigates (Sec-Fetch-Mode: navigate) is still a POST: refused
    nav = {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate"}
    r = request(station.port, "POST", "/holes/1/mark", {**nav, **station.auth}, mark_body())
    assert r.status == 403
    # while the pairing link clicked on another site (a chat) opens the page
    r = request(station.port, "GET", "/?token=x", {**nav, "Sec-Fetch-Dest": "document"})
    assert r.status == 200 and b"holescan ground station" in r.body
    assert "frame-ancestors 'none'" in r.headers["content-security-policy"]
    # a sandboxed frame's Origin is "null"
    r = request(station.port, "POST", "/holes/1/mark", {"Origin": "null"}, mark_body())
    assert r.status == 403
    # even with the right Origin, an old-style text/plain mark is not one: no token -> 401
    origin = {"Origin": f"http://127.0.0.1:{station.port}", "Content-Type": "text/plain"}
    assert request(station.port, "POST", "/holes/1/mark", origin, b"rejected").status == 401
    # nor can another site pair a browser (the pairing check is a POST too)
    r = request(station.port, "POST", "/pair", {"Origin": "http://evil.example", **station.auth})
    assert r.status == 403 and "set-cookie" not in r.headers
    assert station.fingerprint() == before
    assert station.web.refused >= 6


def test_dns_rebinding_host_is_refused(station: Station) -> None:
    # issue 23: GET /state.json with Host evil.example:PORT (DNS rebinding) is not answered
    for path in ("/state.json", "/", "/events", "/cards/hole-1.jpg", "/static/review.js"):
        r = request(station.port, "GET", path, {"Host": f"evil.example:{station.port}"})
        assert r.status == 403, (path, r)
        assert b"43.65" not in r.body
    for bad in (
        "evil.example",
        f"127.0.0.1:{station.port + 1}",  # another port
        "127.0.0.1",  # port 80 implied
        f"192.0.2.99:{station.port}",  # an address it does not serve
        f"127.0.0.1:{station.port}@evil.example",
        "",
    ):
        r = request(station.port, "GET", "/state.json", {"Host": bad})
        assert r.status == 403, (bad, r)
    # no Host at all, or two
    assert send(station.port, b"GET /state.json HTTP/1.0\r\n\r\n").status in (400, 403)
    two = f"GET /state.json HTTP/1.1\r\nHost: 127.0.0.1:{station.port}\r\nHost: evil\r\n\r\n"
    assert send(station.port, two.encode()).status == 400
    # the station's own names are answered
    for good in (f"127.0.0.1:{station.port}", f"localhost:{station.port}"):
        r = request(station.port, "GET", "/state.json", {"Host": good})
        assert r.status == 200, good
        assert [h["id"] for h in json.loads(r.body)["holes"]] == [1, 2]
    # a foreign Origin cannot read either
    r = request(station.port, "GET", "/state.json", {"Origin": "http://evil.example"})
    assert r.status == 403


def _addresses() -> list[str]:
    """This machine's IPv4 addresses other than loopback (the incident WiFi's)."""
    out = set()
    for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET):
        out.add(str(info[4][0]))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("10.255.255.255", 1))
            out.add(str(s.getsockname()[0]))
        except OSError:
            pass
    return sorted(a for a in out if not a.startswith("127."))


def test_all_interfaces_without_the_token_reads_but_cannot_change(tmp_path: Path) -> None:
    # issue 23: --http 0.0.0.0:PORT: anyone on the WiFi could mark holes
    st = Station(tmp_path / "st", host="0.0.0.0")
    try:
        for addr in ["127.0.0.1", *_addresses()]:
            before = st.fingerprint()
            r = request(st.port, "GET", "/state.json", host=addr)
            assert r.status == 200, addr
            doc = json.loads(r.body)
            assert doc["can_mark"] is False and len(doc["holes"]) == 2
            for auth in ({}, {"Authorization": "Bearer " + "x" * 43}, {"Authorization": "Basic a"}):
                hdrs = {"Content-Type": "application/json", **auth}
                r = request(st.port, "POST", "/holes/1/mark", hdrs, mark_body(), host=addr)
                assert r.status == 401, (addr, r)
                assert "bearer" in r.headers["www-authenticate"].lower()
            assert st.fingerprint() == before
        # with a pairing the operator's mark is made and audited under it (a name in the
        # body is not who marked: the pairing is)
        bea, token = st.web.pairings.issue("Bea Roy")
        hdrs = {"Content-Type": "application/json", "Authorization": f"Bearer {token}"}
        r = request(st.port, "POST", "/holes/1/mark", hdrs, mark_body("confirmed", operator="Ana"))
        assert r.status == 200 and json.loads(r.body)["tier"] == "confirmed"
        doc = json.loads(request(st.port, "GET", "/state.json", hdrs).body)
        assert doc["can_mark"] is True and doc["paired"] == {"pairing": "p2", "operator": "Bea Roy"}
        assert doc["holes"][0]["marked_by"]["operator"] == "Bea Roy"
        assert doc["holes"][0]["marked_by"]["pairing"] == bea.id == "p2"
        (entry,) = AuditTrail(st.state.folder).read()
        assert entry["operator"] == "Bea Roy" and entry["client"] == "127.0.0.1"
        assert entry["pairing"] == "p2"
        assert (entry["hole"], entry["mark_from"], entry["mark_to"]) == (1, "new", "confirmed")
        assert (entry["tier_from"], entry["tier_to"]) == ("announced", "confirmed")
        assert "0.0.0.0" not in st.web.url  # the printed link is one a browser can open
    finally:
        st.close()


def test_a_pairing_survives_a_restart_and_is_private(tmp_path: Path) -> None:
    st = Station(tmp_path / "st")
    token = st.token
    st.close()
    path = tmp_path / "st" / ".station-pairings.json"
    assert path.stat().st_mode & 0o077 == 0  # readable by the station's user only
    assert token not in path.read_text()  # only its hash is kept
    st = Station(tmp_path / "st")
    try:
        assert len(token) >= 40
        first = st.web.pairings.check(token)  # still paired after the restart
        assert first is not None and (first.id, first.operator) == ("p1", "Ana")
        assert token not in repr(st.web.pairings)
        assert st.web.pair_url(token).endswith(f"?token={token}")
        hdrs = {"Content-Type": "application/json", "Authorization": f"Bearer {token}"}
        assert request(st.port, "POST", "/holes/1/mark", hdrs, mark_body()).status == 200
        # removed from the file (by hand, while the station runs): un-paired at once
        path.write_text(json.dumps({"pairings": []}))
        assert request(st.port, "POST", "/holes/2/mark", hdrs, mark_body()).status == 401
    finally:
        st.close()


def test_a_mark_needs_a_pairing_a_known_hole_and_json(station: Station) -> None:
    before = station.fingerprint()
    json_only = {"Content-Type": "application/json"}
    hdrs = {**json_only, **station.auth}
    cases = [
        ("/holes/1/mark", {**hdrs, "Authorization": "Bearer " + "x" * 43}, mark_body(), 401),
        (
            "/holes/1/mark",
            {**json_only, "Cookie": "holescan_pairing=" + "x" * 43},
            mark_body(),
            401,
        ),
        ("/holes/1/mark", hdrs, mark_body(mark="deleted"), 400),
        ("/holes/1/mark", hdrs, b'{"operator": "Ana"}', 400),
        ("/holes/1/mark", hdrs, b"[1, 2]", 400),
        ("/holes/1/mark", hdrs, b"\xff\xfe", 400),
        ("/holes/9/mark", hdrs, mark_body(), 404),
        ("/holes/1/mark", {**station.auth, "Content-Type": "text/plain"}, mark_body(), 415),
        ("/holes/1/delete", hdrs, mark_body(), 404),
    ]
    for path, h, body, code in cases:
        assert request(station.port, "POST", path, h, body).status == code, (path, body)
    assert station.fingerprint() == before
    # a trail that cannot be written: the mark is not made (503, the station's fault)
    trail = station.state.folder / "audit.jsonl"
    trail.mkdir()
    assert request(station.port, "POST", "/holes/2/mark", hdrs, mark_body()).status == 503
    assert station.fingerprint() == before
    trail.rmdir()
    # a rejected hole is kept: rejected, not deleted
    r = request(station.port, "POST", "/holes/2/mark", hdrs, mark_body("rejected"))
    assert r.status == 200
    holes = json.loads(request(station.port, "GET", "/state.json").body)["holes"]
    assert [(h["id"], h["tier"]) for h in holes] == [(1, "announced"), (2, "rejected")]


def test_requests_are_bounded(tmp_path: Path) -> None:
    limits = Limits(max_head_bytes=2048, max_body_bytes=256, rate_per_s=0.01, burst=8.0)
    st = Station(tmp_path / "st", limits=limits)
    p = st.port
    try:
        before = st.fingerprint()
        hdrs = {"Content-Type": "application/json", **st.auth}
        assert request(p, "POST", "/holes/1/mark", hdrs, b" " * 257).status == 413
        no_length = f"POST /holes/1/mark HTTP/1.1\r\nHost: 127.0.0.1:{p}\r\n\r\n{mark_body()!r}"
        assert send(p, no_length.encode()).status == 411
        chunked = {**hdrs, "Transfer-Encoding": "chunked"}
        assert request(p, "POST", "/holes/1/mark", chunked, mark_body()).status == 411
        lie = {**hdrs, "Content-Length": "200"}  # says 200, sends fewer, then closes
        # (the connection is gone before the body is: nothing can be answered, or 400)
        assert request(p, "POST", "/holes/1/mark", lie, mark_body()).status in (0, 400)
        assert request(p, "GET", "/", {"X-Pad": "a" * 3000}).status == 431
        assert request(p, "GET", "/" + "a" * 3000).status == 414
        # dripped in pieces, a head over the bound is h11's to refuse (400)
        s = socket.create_connection(("127.0.0.1", p), timeout=10)
        s.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{p}\r\n".encode())
        for _ in range(3):
            time.sleep(0.05)
            s.sendall(b"X-Pad: " + b"a" * 1000 + b"\r\n")
        assert s.recv(4096).startswith(b"HTTP/1.1 400")
        s.close()
        assert st.fingerprint() == before
        # the rate: 8 at once (4 used above: a head too large is refused before), then
        # one per 100 s
        codes = [request(p, "GET", "/state.json").status for _ in range(6)]
        assert codes == [200, 200, 200, 200, 429, 429]
        assert request(p, "GET", "/state.json").headers["retry-after"] == "1"
    finally:
        st.close()


def test_event_streams_and_connections_are_bounded(tmp_path: Path) -> None:
    st = Station(tmp_path / "st", limits=Limits(max_event_clients=2, max_per_client=4))
    p = st.port
    socks: list[socket.socket] = []
    try:
        for _ in range(2):
            s = socket.create_connection(("127.0.0.1", p), timeout=10)
            s.sendall(f"GET /events HTTP/1.1\r\nHost: 127.0.0.1:{p}\r\n\r\n".encode())
            assert s.recv(4096).startswith(b"HTTP/1.1 200")
            socks.append(s)
        assert request(p, "GET", "/events").status == 503  # the third stream
        # connections from one address beyond 4 are closed unanswered (2 streams + 2 idle;
        # accepted in order, so the idle ones are counted before the fifth)
        for _ in range(2):
            socks.append(socket.create_connection(("127.0.0.1", p), timeout=10))
        assert request(p, "GET", "/").status == 0
        for s in socks:
            s.close()
        t0 = time.monotonic()
        while request(p, "GET", "/").status != 200:  # taken again once they are closed
            assert time.monotonic() - t0 < 30, "the server never took connections again"
            time.sleep(0.2)
    finally:
        for s in socks:
            s.close()
        st.close()


def test_a_slow_loris_client_is_cut_off(tmp_path: Path) -> None:
    st = Station(tmp_path / "st", limits=Limits(request_s=1.0))
    p = st.port
    try:
        # header lines dripped one by one: cut at the request deadline, not served
        s = socket.create_connection(("127.0.0.1", p), timeout=10)
        s.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{p}\r\n".encode())
        closed = False
        for i in range(100):  # 10 s of dripping: 10x the deadline
            try:
                s.sendall(f"X-Drip-{i}: a\r\n".encode())
            except OSError:
                closed = True
                break
            time.sleep(0.1)
        s.close()
        assert closed and st.web.cut >= 1
        assert request(p, "GET", "/").status == 200  # the others are served
    finally:
        st.close()


def _fuzz_request(rng: random.Random, port: int) -> bytes:
    methods = ["GET", "POST", "PUT", "DELETE", "OPTIONS", "HEAD", "PATCH", "TRACE", "CONNECT"]
    method = rng.choice([*methods, "GET", "POST", "POST", "G\x00T", "X" * rng.randint(1, 40), ""])
    path = rng.choice(
        [
            "/",
            "/state.json",
            "/holes/1/mark",
            "/holes/2/mark",
            "/holes/-1/mark",
            "/holes/99999999999/mark",
            "/cards/hole-1.jpg",
            "/cards/hole-../../station.json",
            "/static/../station.json",
            "/static/station.html",
            "/%2e%2e/station.json",
            "/holes/1/mark?token=x",
            "//holes/1/mark",
            "*",
            "http://evil.example/",
            "/" + "".join(rng.choice("abc/%.?#\x7f") for _ in range(rng.randint(0, 60))),
        ]
    )
    version = rng.choice(["HTTP/1.1"] * 8 + ["HTTP/1.0", "HTTP/2.0", "HTTP/9", "", "HTTP/1.1 x"])
    hosts = [f"127.0.0.1:{port}", f"localhost:{port}", "evil.example", "", "[::1]", "a" * 300]
    headers = {}
    for _ in range(rng.randint(0, 6)):
        name = rng.choice(
            [
                *("Host", "Origin", "Content-Type", "Content-Length", "Authorization"),
                *("Sec-Fetch-Site", "Transfer-Encoding", "Expect", "Connection"),
                "X-" + str(rng.random()),
            ]
        )
        value = rng.choice(
            [
                rng.choice(hosts),
                "http://evil.example",
                "null",
                "text/plain",
                "application/json",
                str(rng.randint(-5, 5000)),
                "Bearer " + "x" * rng.randint(0, 60),
                "chunked",
                "100-continue",
                "cross-site",
                "".join(chr(rng.randint(0, 255)) for _ in range(rng.randint(0, 30))),
            ]
        )
        headers[name] = value
    if rng.random() < 0.8:  # mostly a good Host, to reach the routes behind it
        headers.setdefault("Host", rng.choice(hosts[:2] * 4 + hosts))
    body = rng.choice(
        [
            b"",
            b"rejected",
            mark_body(),
            mark_body("confirmed", operator="Eve"),
            bytes(rng.randint(0, 255) for _ in range(rng.randint(0, 3000))),
        ]
    )
    if rng.random() < 0.5:
        headers["Content-Length"] = str(len(body))
    head = f"{method} {path} {version}\r\n" + "".join(f"{k}: {v}\r\n" for k, v in headers.items())
    data = head.encode("latin-1", "replace") + b"\r\n" + body
    if rng.random() < 0.1:
        data = data[: rng.randint(0, len(data))]  # cut mid-request
    return data


def test_fuzz_of_the_http_endpoints(tmp_path: Path) -> None:
    """Random methods, paths, headers, bodies over a real socket, without the token:
    every answer is a 4xx (or a 200 to a good GET), no handler fails, nothing changes,
    and the page is still served after."""
    st = Station(tmp_path / "st", limits=Limits(rate_per_s=1e6, burst=1e6, request_s=2.0))
    rng = random.Random(23)
    try:
        before = st.fingerprint()
        codes: dict[int, int] = {}
        for _ in range(400):
            r = send(st.port, _fuzz_request(rng, st.port))
            codes[r.status] = codes.get(r.status, 0) + 1
            assert r.status == 0 or 200 <= r.status < 500 or r.status == 505, r
        print("fuzz status counts:", dict(sorted(codes.items())))
        assert st.web.errors == 0
        assert st.fingerprint() == before
        assert sum(n for c, n in codes.items() if 400 <= c < 500) > 200
        assert request(st.port, "GET", "/").status == 200
        hdrs = {"Content-Type": "application/json", **st.auth}
        assert request(st.port, "POST", "/holes/1/mark", hdrs, mark_body()).status == 200
    finally:
        st.close()
