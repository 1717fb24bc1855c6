"""The page's server over raw HTTP: malformed framing, pairings, event-stream bounds, tokens
kept out of the logs, and a hypothesis fuzz of request lines, headers, query strings and
bodies (every answer a well-formed status, nothing changed, the server still up).

A real :class:`StationWeb` (Starlette on uvicorn) on a free port, real sockets.
"""

from __future__ import annotations

import json
import logging
import re
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import quote

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_station import wait_for
from test_station_guard import Station, mark_body, request, send

from holescan.ground import GroundOptions, run_ground
from holescan.ground.station.guard import Limits
from tests._support import free_udp_port


@pytest.fixture
def station(tmp_path: Path) -> Iterator[Station]:
    s = Station(tmp_path / "st")
    yield s
    s.close()


def test_a_malformed_content_length_gets_400_and_changes_nothing(station: Station) -> None:
    before = station.fingerprint()
    p = station.port
    for bad in ("²", "١٢", "12a", "-1", "+5", "0x10", "1e3", "5, 6", "", "9" * 40):
        head = (
            f"POST /holes/1/mark HTTP/1.1\r\nHost: 127.0.0.1:{p}\r\n"
            f"Authorization: Bearer {station.token}\r\nContent-Type: application/json\r\n"
            f"Content-Length: {bad}\r\n\r\n"
        )
        r = send(p, head.encode("utf-8") + mark_body())
        assert r.status in (400, 413), (bad, r)  # 40 nines: a number, over the body bound
    assert station.fingerprint() == before
    assert station.web.errors == 0
    assert request(p, "GET", "/").status == 200


def test_pairing_is_checked_before_the_page_keeps_it(station: Station) -> None:
    p = station.port
    for bad in ("x" * 43, "%E2%82%AC", "", "a b"):
        r = request(p, "POST", "/pair", {"Authorization": f"Bearer {bad}"})
        assert r.status == 401 and b"not valid" in r.body and "set-cookie" not in r.headers
    # a non-ASCII token on the wire (the page never sends one; a script might)
    head = f"POST /pair HTTP/1.1\r\nHost: 127.0.0.1:{p}\r\nContent-Length: 0\r\n"
    r = send(p, head.encode() + "Authorization: Bearer €\r\n\r\n".encode())
    assert r.status == 401
    r = request(p, "POST", "/pair", station.auth)
    assert r.status == 200 and json.loads(r.body) == {"pairing": "p1", "operator": "Ana"}
    cookie = r.headers["set-cookie"]
    assert "httponly" in cookie.lower() and "samesite=strict" in cookie.lower()
    assert "max-age" not in cookie.lower() and "expires" not in cookie.lower()  # this session
    value = cookie.split(";", 1)[0]
    doc = json.loads(request(p, "GET", "/state.json", {"Cookie": value}).body)
    assert doc["can_mark"] is True and doc["paired"] == {"pairing": "p1", "operator": "Ana"}
    hdrs = {"Cookie": value, "Content-Type": "application/json"}
    assert request(p, "POST", "/holes/2/mark", hdrs, mark_body("visited")).status == 200
    assert station.state.holes[2].mark == "visited"


def _open_stream(port: int) -> tuple[socket.socket, bytes]:
    """An event stream, and what came with its head."""
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.sendall(f"GET /events HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode())
    first = s.recv(4096)
    assert first.startswith(b"HTTP/1.1 200")
    return s, first


def test_event_streams_are_capped_per_address_and_end_by_a_deadline(tmp_path: Path) -> None:
    limits = Limits(max_events_per_client=2, events_s=1.5)
    st_ = Station(tmp_path / "st", limits=limits)
    p = st_.port
    socks: list[tuple[socket.socket, bytes]] = []
    try:
        socks = [_open_stream(p), _open_stream(p)]
        r = request(p, "GET", "/events")
        assert r.status == 503 and r.headers["retry-after"] == "5"
        assert st_.web.events.refused == 1
        # each stream says how soon to come back, and ends by its deadline (the chunked
        # body's last chunk; the connection may stay open for another request)
        for s, data in socks:
            while not data.endswith(b"\r\n0\r\n\r\n"):
                chunk = s.recv(4096)
                assert chunk, data
                data += chunk
            assert b"retry: 2000" in data and b"data: " in data
        wait_for(lambda: st_.web.events.open == 0, 10.0, "the slots given back")
        assert request(p, "GET", "/state.json").status == 200
        socks = [_open_stream(p)]  # and the address may open one again
    finally:
        for s, _ in socks:
            s.close()
        st_.close()


def test_tokens_never_reach_the_logs(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    shown: list[str] = []
    stop = threading.Event()
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{free_udp_port()}",
        out=tmp_path / "st",
        http_port=0,
        cot_url=None,
        pair=("Ana", "Bea"),
    )
    box: dict[str, object] = {}
    runner = threading.Thread(
        target=lambda: box.update(station=run_ground(opts, stop, shown.append)), daemon=True
    )
    runner.start()
    wait_for(lambda: len(shown) == 3, 30.0, "the pairing links shown")
    tokens = [m[1] for line in shown[1:] if (m := re.search(r"\?token=([\w-]+)", line))]
    assert len(tokens) == 2 and "Ana (p1)" in shown[1] and "Bea (p2)" in shown[2]
    url = shown[1].split(": ", 1)[1].split("?", 1)[0]
    port = int(url.rsplit(":", 1)[1].strip("/"))
    # the links are used: the page with the token, the pairing, a mark that fails (no hole)
    assert request(port, "GET", f"/?token={tokens[0]}").status == 200
    assert request(port, "POST", "/pair", {"Authorization": f"Bearer {tokens[0]}"}).status == 200
    hdrs = {"Authorization": f"Bearer {tokens[1]}", "Content-Type": "application/json"}
    assert request(port, "POST", "/holes/7/mark", hdrs, mark_body()).status == 404
    stop.set()
    runner.join(timeout=30)
    text = caplog.text + "".join(str(r.args) for r in caplog.records)
    assert "paired as Ana (p1)" in caplog.text  # the pairing is logged by its id and name
    for t in tokens:
        assert t not in text
    # nor in any file of the station's folder
    for f in opts.out.rglob("*"):
        if f.is_file():
            assert not any(t.encode() in f.read_bytes() for t in tokens), f


# -- the fuzz -------------------------------------------------------------------------------
_PATHS = [
    "/",
    "/state.json",
    "/events",
    "/pair",
    "/holes/1/mark",
    "/holes/-1/mark",
    "/holes/99999999999/mark",
    "/holes/١/mark",
    "/cards/hole-1.jpg",
    "/cards/hole-../../station.json",
    "/static/../station.json",
    "/static/station.js",
    "/static/%2e%2e/pairing.py",
    "/map.json",
    "/map/all/cov-0_0.png",
    "/map/view/..%2fstation.json",
    "//holes/1/mark",
    "*",
    "http://evil.example/",
]
_LATIN1 = st.characters(min_codepoint=0, max_codepoint=255)
_PRINTABLE = st.characters(min_codepoint=32, max_codepoint=126)
_KNOWN = [
    "Host",
    "Origin",
    "Content-Type",
    "Content-Length",
    "Authorization",
    "Cookie",
    "Sec-Fetch-Site",
    "Sec-Fetch-Mode",
    "Transfer-Encoding",
    "Expect",
    "Connection",
    "Upgrade",
]
_SAMPLES = [
    "http://evil.example",
    "null",
    "text/plain",
    "application/json",
    "chunked",
    "100-continue",
    "cross-site",
    "same-origin",
    "navigate",
    "websocket",
    "close",
    "²",
    "-1",
    "Bearer " + "x" * 43,
    "holescan_pairing=" + "x" * 43,
]
_NAMES = st.sampled_from(_KNOWN) | st.text(
    st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=20
)
_VALUES = st.sampled_from(_SAMPLES) | st.text(_LATIN1, max_size=60)


@st.composite
def raw_requests(draw: st.DrawFn, port: int) -> tuple[bytes, bool]:
    """(a request's bytes, whether its framing is whole: every answer is then due)."""
    sane = draw(st.integers(0, 3)) > 0  # mostly well-formed, to reach the routes
    methods = st.sampled_from(["GET", "POST", "HEAD", "PUT", "DELETE", "OPTIONS", "TRACE"])
    method = draw(methods if sane else methods | st.text(_LATIN1, max_size=10))
    path = draw(
        st.sampled_from(_PATHS) if sane else st.sampled_from(_PATHS) | st.text(_LATIN1, max_size=60)
    )
    text = st.text(max_size=60)  # any unicode: percent-encoded when sane
    quoted = text.map(lambda t: quote(t, safe="=&"))
    query = draw(
        st.none() | quoted | quoted.map(lambda t: "token=" + t)
        if sane
        else st.none() | st.text(_LATIN1, max_size=80) | text.map(lambda t: "token=" + t)
    )
    target = path if query is None else f"{path}?{query}"
    version = draw(
        st.sampled_from(["HTTP/1.1", "HTTP/1.0"])
        if sane
        else st.sampled_from(["HTTP/1.1", "HTTP/2.0", "", "HTTP/9", "HTTP/1.1 x"])
    )
    if sane:
        names = st.sampled_from([n for n in _KNOWN if n != "Host"])
        values = st.sampled_from(_SAMPLES) | st.text(_PRINTABLE, max_size=60)
        headers = draw(st.lists(st.tuples(names, values), max_size=3))
    else:
        headers = draw(st.lists(st.tuples(_NAMES, _VALUES), max_size=8))
    if sane or draw(st.booleans()):
        headers.insert(
            0, ("Host", draw(st.sampled_from([f"127.0.0.1:{port}", f"localhost:{port}"])))
        )
    body = draw(st.binary(max_size=1500) | st.just(mark_body()) | st.just(b""))
    if draw(st.booleans()):
        headers.append(("Content-Length", str(len(body))))
    names = [k.lower() for k, _ in headers]
    lengths = [v for k, v in headers if k.lower() == "content-length"]
    whole = "transfer-encoding" not in names and all(
        not re.fullmatch(r"\s*[0-9]+\s*", v) or int(v) <= len(body) for v in lengths
    )
    head = f"{method} {target} {version}\r\n" + "".join(f"{k}: {v}\r\n" for k, v in headers)
    return head.encode("utf-8") + b"\r\n" + body, whole


_STATUS = re.compile(rb"HTTP/1\.[01] ([1-5]\d\d) [^\r\n]*\r\n")


def test_fuzz_over_http_every_answer_is_a_status_and_the_server_stays_up(tmp_path: Path) -> None:
    limits = Limits(rate_per_s=1e6, burst=1e6, request_s=2.0, events_s=0.5)
    station = Station(tmp_path / "st", limits=limits)
    seen: dict[int, int] = {}
    try:
        before = station.fingerprint()

        @settings(
            max_examples=300,
            deadline=None,
            derandomize=True,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
        )
        @given(req=raw_requests(station.port))
        def one(req: tuple[bytes, bool]) -> None:
            data, whole = req
            raw = _raw(station.port, data)
            if not raw:  # closed unanswered: only when the request could not be whole
                assert not whole, data[:300]
                seen[0] = seen.get(0, 0) + 1
                return
            m = _STATUS.match(raw)
            assert m is not None, raw[:200]
            code = int(m[1])
            seen[code] = seen.get(code, 0) + 1
            assert code < 500 or code == 503, (data[:300], raw[:300])

        one()
        print("fuzz status counts:", dict(sorted(seen.items())))
        assert station.web.errors == 0
        assert station.fingerprint() == before
        assert request(station.port, "GET", "/").status == 200
        hdrs = {"Content-Type": "application/json", **station.auth}
        assert request(station.port, "POST", "/holes/1/mark", hdrs, mark_body()).status == 200
    finally:
        station.close()


def _raw(port: int, data: bytes) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        try:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        chunks = []
        t0 = time.monotonic()
        try:
            while (chunk := s.recv(65536)) and time.monotonic() - t0 < 10:
                chunks.append(chunk)
        except (ConnectionResetError, TimeoutError):
            pass
    return b"".join(chunks)


def test_holescan_pair_prints_one_link_and_refuses_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from holescan.cli import main
    from holescan.ground.station.pairing import Pairings

    folder = tmp_path / "st"
    folder.mkdir()
    assert main(["pair", "-o", str(folder), "Ana", "--http", "127.0.0.1:8081"]) == 0
    out = capsys.readouterr().out.strip()
    m = re.fullmatch(r"Ana \(p1\): http://127\.0\.0\.1:8081/\?token=([\w-]{43})", out)
    assert m is not None, out
    assert Pairings(folder).check(m[1]) is not None
    for argv in (["pair", "-o", str(folder), " "], ["pair", "-o", str(tmp_path / "no"), "Bea"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, err
    assert [p.operator for p in Pairings(folder).all()] == ["Ana"]
