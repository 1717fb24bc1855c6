"""The live page's routes (Starlette), behind :class:`~ground.station.guard.GuardMiddleware`.

* ``GET /`` the page (``static/station.html``); ``GET /static/NAME`` its scripts and
  styles (no inline script or style anywhere: the page's CSP has no ``'unsafe-inline'``);
* ``GET /state.json`` everything the page draws, with ``can_mark`` and ``paired`` (the
  asker's pairing, or null); ``GET /cards/hole-<id>.jpg`` a hole's picture;
* ``GET /events`` Server-Sent Events (:mod:`ground.station.events`);
* ``GET /map.json``, ``GET /map/...`` the live map's layers, ``GET /basemaps.json``,
  ``GET /basemap/...`` the offline basemaps (:mod:`ground.station.maplayers`);
* ``GET /holes.geojson``, ``/gaps.geojson``, ``/holes.kml``, ``/holes_live.kml`` the live
  layers for QGIS, CalTopo and Google Earth (:mod:`ground.station.feeds`), read-only;
* ``POST /pair`` with ``Authorization: Bearer TOKEN``: the page checks a pairing link's
  token before it keeps anything; 200 ``{"pairing", "operator"}`` and the cookie
  ``holescan_pairing`` (``HttpOnly; SameSite=Strict``), or 401 with the reason;
* ``POST /holes/<id>/mark`` with the pairing (the cookie or ``Authorization: Bearer``),
  ``Content-Type: application/json`` and ``{"mark": "confirmed|rejected|visited|new"}``:
  the mark, audited under the pairing (:mod:`ground.station.audit`).

A mark is checked in this order, each answered with a 4xx that touches nothing: no chunked
body and a ``Content-Length`` (411) within the body bound (413), a pairing (401), a JSON
body (415, 400), a known hole (404).
"""

from __future__ import annotations

import json
import logging
from http.cookies import CookieError, SimpleCookie
from importlib import resources
from typing import Protocol

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect, Request
from starlette.responses import JSONResponse, PlainTextResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from holescan.errors import InputError
from holescan.ground.station.audit import AuditError
from holescan.ground.station.events import EventStream
from holescan.ground.station.feeds import FEEDS
from holescan.ground.station.guard import Limits
from holescan.ground.station.maplayers import Reply
from holescan.ground.station.pairing import Pairing, Pairings
from holescan.ground.station.records import GroundHole

__all__ = ["COOKIE", "Site", "make_app"]

_log = logging.getLogger(__name__)

COOKIE = "holescan_pairing"
"""The page's pairing cookie (HttpOnly, SameSite=Strict, this browser session only)."""

_MAX_ID_DIGITS = 9
_TILE_CACHE = {"Cache-Control": "private, max-age=3600"}


class Site(Protocol):
    """What the routes serve and change (:class:`~ground.station.web.StationWeb`)."""

    limits: Limits
    pairings: Pairings
    events: EventStream
    errors: int

    def state_json(self, paired: Pairing | None) -> bytes: ...

    def card(self, hole_id: int) -> bytes: ...

    def map_reply(self, path: str, query: str) -> Reply | None: ...

    def feed(self, path: str) -> bytes | None: ...

    def mark(self, hole_id: int, mark: str, pairing: Pairing, client: str) -> GroundHole: ...


def _text(code: int, why: str, headers: dict[str, str] | None = None) -> Response:
    return PlainTextResponse(why + "\n", code, headers)


def _bearer(request: Request) -> str | None:
    scheme, _, given = (request.headers.get("authorization") or "").strip().partition(" ")
    return given.strip() if scheme.lower() == "bearer" and given.strip() else None


def _cookie(request: Request) -> str | None:
    jar: SimpleCookie = SimpleCookie()
    try:
        jar.load(request.headers.get("cookie") or "")
    except CookieError:
        return None
    morsel = jar.get(COOKIE)
    return morsel.value if morsel is not None else None


def paired(site: Site, request: Request) -> Pairing | None:
    """The pairing a request carries (``Authorization: Bearer`` first, then the cookie)."""
    return site.pairings.check(_bearer(request) or _cookie(request))


def _client(request: Request) -> str:
    return request.client.host if request.client else "-"


def _hole_id(request: Request) -> int | None:
    text = str(request.path_params["hole_id"])
    return int(text) if text.isascii() and text.isdigit() and len(text) <= _MAX_ID_DIGITS else None


def make_app(site: Site) -> Starlette:
    """The page's routes for ``site`` (wrap it in the guard before serving it)."""
    page = resources.files("holescan.ground.station").joinpath("static/station.html").read_bytes()
    limits = site.limits

    async def index(request: Request) -> Response:
        return Response(page, media_type="text/html; charset=utf-8")

    async def state_json(request: Request) -> Response:
        body = await run_in_threadpool(site.state_json, paired(site, request))
        return Response(body, media_type="application/json")

    async def card(request: Request) -> Response:
        hid = _hole_id(request)
        try:
            data = await run_in_threadpool(site.card, -1 if hid is None else hid)
        except OSError:
            return _text(404, "no such picture")
        cache = {"Cache-Control": "private, max-age=3600"}
        return Response(data, media_type="image/jpeg", headers=cache)

    async def map_layers(request: Request) -> Response:
        path, query = request.url.path, request.url.query
        reply = await run_in_threadpool(site.map_reply, path, query)
        if reply is None:
            return _text(404, "not found")
        code, body, ctype = reply
        if code >= 400:
            return _text(code, body.decode("utf-8", "replace"))
        if path.startswith("/basemap/") and ctype.startswith("image/"):  # a basemap's tile
            return Response(body, code, media_type=ctype, headers=_TILE_CACHE)
        return Response(body, code, media_type=ctype)

    async def feed(request: Request) -> Response:
        path = request.url.path
        body = await run_in_threadpool(site.feed, path)
        if body is None:
            return _text(404, "not found")
        return Response(body, media_type=FEEDS[path])

    async def pair(request: Request) -> Response:
        p = site.pairings.check(_bearer(request))
        if p is None:
            _log.warning("web: %s: a pairing link that is not valid", _client(request))
            return _text(
                401,
                "this pairing link is not valid (mistyped, cut short, or revoked): ask the "
                "station for a new one (holescan pair)",
                {"WWW-Authenticate": 'Bearer realm="holescan ground station"'},
            )
        _log.info("web: %s paired as %s", _client(request), p)
        r = JSONResponse({"pairing": p.id, "operator": p.operator})
        r.set_cookie(COOKIE, _bearer(request) or "", httponly=True, samesite="strict", path="/")
        return r

    async def mark(request: Request) -> Response:
        hid = _hole_id(request)
        if hid is None:
            return _text(404, "not found")
        if "transfer-encoding" in request.headers:
            return _text(411, "send a Content-Length (no chunked bodies)")
        length_text = request.headers.get("content-length")
        if length_text is None:  # h11 has refused one that is not ASCII digits (400)
            return _text(411, "a Content-Length is required")
        length = int(length_text)
        if length > limits.max_body_bytes:
            return _text(413, f"body over {limits.max_body_bytes} bytes")
        who = paired(site, request)
        if who is None:
            _log.warning("web: %s: a mark without a pairing", _client(request))
            return _text(
                401,
                "marking needs a pairing: open your pairing link (holescan pair) once",
                {"WWW-Authenticate": 'Bearer realm="holescan ground station"'},
            )
        ctype = (request.headers.get("content-type") or "").split(";", 1)[0].strip().lower()
        if ctype != "application/json":
            return _text(415, "Content-Type must be application/json")
        try:
            body = await request.body()
        except ClientDisconnect:
            return _text(400, "body shorter than its Content-Length")
        if len(body) != length:
            return _text(400, "body shorter than its Content-Length")
        try:
            req = json.loads(body.decode("utf-8"))
            if not isinstance(req, dict):
                raise ValueError("not an object")
            h = await run_in_threadpool(site.mark, hid, str(req.get("mark")), who, _client(request))
        except LookupError as err:
            return _text(404, str(err))
        except AuditError as err:  # the station's fault, not the request's
            _log.error("mark not made: %s", err)
            return _text(503, f"mark not made: {err}")
        except (ValueError, InputError, UnicodeDecodeError) as err:
            return _text(400, str(err))
        return JSONResponse({"id": h.id, "mark": h.mark, "tier": h.tier})

    async def failed(request: Request, exc: Exception) -> Response:
        site.errors += 1  # a bug: the fuzz tests want none
        _log.error("web: request from %s failed: %r", _client(request), exc)
        return _text(500, "internal error")

    static = StaticFiles(packages=[("holescan.ground.station", "static")])
    routes = [
        Route("/", index),
        Route("/index.html", index),
        Mount("/static", app=static),
        Route("/state.json", state_json),
        Route("/events", site.events),
        Route("/cards/hole-{hole_id}.jpg", card),
        Route("/map.json", map_layers),
        Route("/map/{rest:path}", map_layers),
        Route("/basemaps.json", map_layers),
        Route("/basemap/{rest:path}", map_layers),
        *(Route(path, feed) for path in FEEDS),
        Route("/pair", pair, methods=["POST"]),
        Route("/holes/{hole_id}/mark", mark, methods=["POST"]),
    ]
    return Starlette(routes=routes, exception_handlers={Exception: failed})
