"""The ground station's live page: a local web server, no internet, no tile server.

``http://HOST:PORT/`` shows the vehicle's track, the camera's footprints and the holes with
their uncertainty circles (95 %: 1.62 sigma, the 68 % radius) drawn to scale in local metres
(:class:`geotag.LocalFrame` at the first hole or track point), with a north arrow and a
scale bar; beside the map, each hole's picture, facts and the detector's "why", and three
buttons: confirmed / rejected / visited.

Endpoints (stdlib :mod:`http.server`, one thread per request):

* ``GET /`` the page; ``GET /state.json`` everything it draws (local metres included);
* ``GET /events`` Server-Sent Events: ``data: <version>`` after every change, so new holes
  appear without a reload (the page re-reads ``/state.json``);
* ``GET /cards/hole-<id>.jpg`` a hole's picture;
* ``POST /holes/<id>/mark`` with body ``confirmed|rejected|visited|new``: the operator's
  mark, persisted at once (then TAK and the files follow).
"""

from __future__ import annotations

import json
import logging
import math
import threading
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any

from holescan.errors import InputError
from holescan.geotag import CIRCLE_95_PER_SIGMA, LocalFrame
from holescan.ground.station.files import hole_summary
from holescan.ground.station.maplayers import map_route
from holescan.ground.station.mapstore import MapStore
from holescan.ground.station.state import StationState
from holescan.missions import XTION, Camera

__all__ = ["StationWeb", "state_document"]

_log = logging.getLogger(__name__)


def _footprint(
    x: float, y: float, alt: float, yaw: float, camera: Camera = XTION
) -> list[list[float]]:
    """Corners (east, north) of a nadir camera's footprint, image top towards the nose."""
    across, along = camera.footprint_m(alt)
    hw, hh = across / 2, along / 2
    c, s = math.cos(yaw), math.sin(yaw)  # yaw from north, clockwise
    out = []
    for fwd, right in ((hh, -hw), (hh, hw), (-hh, hw), (-hh, -hw)):
        out.append([round(x + fwd * s + right * c, 2), round(y + fwd * c - right * s, 2)])
    return out


def state_document(state: StationState, footprint_every: int = 3) -> dict[str, Any]:
    """What the page draws, with positions in local metres (east, north)."""
    version, holes, track = state.snapshot()
    origin = (
        (holes[0].lat_deg, holes[0].lon_deg)
        if holes
        else (track[0].lat_deg, track[0].lon_deg)
        if track
        else None
    )
    doc: dict[str, Any] = {"version": version, "origin": origin, "holes": [], "track": []}
    if origin is None:
        return doc
    frame = LocalFrame(*origin)
    for h in holes:
        e, n = frame.to_en(h.lat_deg, h.lon_deg)
        d = h.to_json()
        d.update(
            x=round(float(e), 3),
            y=round(float(n), 3),
            r95=round(CIRCLE_95_PER_SIGMA * h.sigma_h_m, 3) if h.sigma_h_m is not None else None,
            summary=hole_summary(h),
            picture=f"/cards/hole-{h.id}.jpg?rev={h.card_rev}" if h.has_picture else None,
        )
        doc["holes"].append(d)
    fps = []
    for i, p in enumerate(track):
        e, n = frame.to_en(p.lat_deg, p.lon_deg)
        x, y = round(float(e), 2), round(float(n), 2)
        doc["track"].append([x, y])
        if i % footprint_every == 0 and p.rel_alt_m > 0.2:
            fps.append(_footprint(x, y, p.rel_alt_m, p.yaw))
    doc["footprints"] = fps[-400:]
    return doc


class StationWeb:
    """The page's HTTP server on its own thread. Use as a context manager.

    on_mark(hole_id, mark) is called for the operator's marks (default: set it in the
    state). port 0 picks a free port (see :attr:`url`). map_store : the live map's tiles
    (:mod:`ground.station.maplayers`; None: no map).
    """

    def __init__(
        self,
        state: StationState,
        host: str = "127.0.0.1",
        port: int = 8080,
        on_mark: Callable[[int, str], Any] | None = None,
        map_store: MapStore | None = None,
    ) -> None:
        self.state = state
        self.map_store = map_store
        self.on_mark = on_mark or state.mark
        self._cond = threading.Condition()
        self._version = state.version
        self._closing = False
        state.listeners.append(self._changed)
        handler = _handler(self)
        try:
            self.httpd = ThreadingHTTPServer((host, port), handler)
        except OSError as err:
            raise InputError(f"cannot serve the page on {host}:{port}: {err.strerror}") from err
        self.httpd.daemon_threads = True
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="web", daemon=True)

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host!s}:{port}/"

    def __enter__(self) -> StationWeb:
        self._thread.start()
        _log.info("live page on %s", self.url)
        return self

    def __exit__(self, *exc: object) -> None:
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        self.httpd.shutdown()
        self.httpd.server_close()
        self._thread.join(timeout=5.0)

    def _changed(self, version: int) -> None:
        with self._cond:
            self._version = version
            self._cond.notify_all()

    def wait_change(self, seen: int, timeout_s: float) -> int:
        with self._cond:
            self._cond.wait_for(lambda: self._version != seen or self._closing, timeout_s)
            return self._version


def _page() -> bytes:
    return resources.files("holescan.ground.station").joinpath("station.html").read_bytes()


def _handler(web: StationWeb) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "holescan-ground"

        def log_message(self, format: str, *args: Any) -> None:
            _log.debug("web: " + format, *args)

        def _reply(self, code: int, body: bytes, ctype: str) -> None:
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self) -> None:
            path, _, query = self.path.partition("?")
            if path in ("/", "/index.html"):
                self._reply(200, _page(), "text/html; charset=utf-8")
            elif path == "/state.json":
                body = json.dumps(state_document(web.state)).encode()
                self._reply(200, body, "application/json")
            elif path == "/events":
                self._events()
            elif path.startswith("/cards/hole-") and path.endswith(".jpg"):
                try:
                    hid = int(path[len("/cards/hole-") : -4])
                    data = web.state.card_path(hid).read_bytes()
                except (ValueError, OSError):
                    self._reply(404, b"no such picture", "text/plain")
                    return
                self._reply(200, data, "image/jpeg")
            elif (mapped := map_route(web.map_store, path, query)) is not None:
                self._reply(*mapped)  # the map layers (maplayers.py)
            else:
                self._reply(404, b"not found", "text/plain")

        def _events(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            seen = -1
            try:
                while not web._closing:
                    version = web.wait_change(seen, 10.0)
                    if version == seen:
                        self.wfile.write(b": keep-alive\n\n")
                    else:
                        self.wfile.write(f"data: {version}\n\n".encode())
                        seen = version
                    self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError):
                return

        def do_POST(self) -> None:
            parts = self.path.strip("/").split("/")
            if len(parts) != 3 or parts[0] != "holes" or parts[2] != "mark":
                self._reply(404, b"not found", "text/plain")
                return
            n = min(int(self.headers.get("Content-Length") or 0), 100)
            mark = self.rfile.read(n).decode("utf-8", "replace").strip()
            try:
                h = web.on_mark(int(parts[1]), mark)
            except (ValueError, InputError) as err:
                self._reply(400, str(err).encode(), "text/plain")
                return
            self._reply(200, json.dumps({"id": h.id, "mark": h.mark}).encode(), "application/json")

    return Handler
