"""The ground station's live page: a local web server, no internet, no tile server.

``http://HOST:PORT/`` shows the vehicle's track, the camera's footprints and the holes with
their uncertainty circles (95 %: 1.62 sigma, the 68 % radius) drawn to scale in local metres
(:class:`geotag.LocalFrame` at the first hole or track point), with a north arrow and a
scale bar; beside the map, the review queue: each hole's picture, facts, the detector's
"why", its tier and who marked it, and the operator's marks (confirmed / rejected /
visited; keyboard shortcuts, see ``review.js``).

Served by Starlette on uvicorn (:mod:`ground.station.webserver`); the routes are in
:mod:`ground.station.webapp`, the policy every request passes first (Host, Origin, rate) in
:mod:`ground.station.guard`, the event stream in :mod:`ground.station.events`. Marks need an
operator's pairing (:mod:`ground.station.pairing`) and are written to the audit trail
(:mod:`ground.station.audit`) under it, then to the state (TAK and the files follow on the
station's own thread, never on the request's).
"""

from __future__ import annotations

import contextlib
import dataclasses
import ipaddress
import json
import logging
import math
import socket
import threading
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

from holescan.errors import InputError
from holescan.geotag import CIRCLE_95_PER_SIGMA, LocalFrame
from holescan.ground.station.audit import AuditEntry, AuditTrail
from holescan.ground.station.basemap import Basemap
from holescan.ground.station.files import hole_summary
from holescan.ground.station.guard import GuardMiddleware, Limits, RateLimiter, default_names
from holescan.ground.station.locate import bearing_name, mgrs_text, range_bearing
from holescan.ground.station.mapcombine import CombinedCache
from holescan.ground.station.maplayers import Reply, VehicleMaps, basemap_route, map_route
from holescan.ground.station.mapstore import MapStore
from holescan.ground.station.pairing import Pairing, Pairings
from holescan.ground.station.records import MARKS, GroundHole, TrackPoint
from holescan.ground.station.state import StationState
from holescan.ground.station.vehicles import camera_footprint
from holescan.missions import XTION, Camera

if TYPE_CHECKING:
    from holescan.ground.station.events import Changes, EventStream
    from holescan.ground.station.webserver import WebServer

__all__ = ["StationWeb", "state_document", "station_url", "vehicle_colours"]

_log = logging.getLogger(__name__)

MarkedBy = dict[int, tuple[str, int, str]]
"""hole id -> (operator, Unix clock ns, pairing id) of its newest mark."""


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


VEHICLE_COLOURS = ("#1565c0", "#e65100", "#00897b", "#6a1b9a", "#ad1457", "#558b2f")
"""The vehicles' colours on the page, by their order of system id."""


def _place(frame: LocalFrame, lat: float, lon: float) -> list[float]:
    e, n = frame.to_en(lat, lon)
    return [round(float(e), 2), round(float(n), 2)]


def _range(ref: tuple[float, float] | None, lat: float, lon: float) -> dict[str, Any] | None:
    if ref is None:
        return None
    d, b = range_bearing(ref[0], ref[1], lat, lon)
    return {"distance_m": round(d, 1), "bearing_deg": round(b, 1), "compass": bearing_name(b)}


def _colours(sysids: set[int]) -> dict[int, str]:
    """Each vehicle's colour: :data:`VEHICLE_COLOURS` in order of system id."""
    return {s: VEHICLE_COLOURS[k % len(VEHICLE_COLOURS)] for k, s in enumerate(sorted(sysids))}


def vehicle_colours(state: StationState) -> dict[int, str]:
    """Each vehicle's colour on the page (the state document's ``colour``): by order of
    system id among the vehicles heard and those with a track."""
    primary = state.primary_sysid
    sids = {v.sysid for v in state.vehicle_snapshot()}
    sids |= {s if s or primary is None else primary for s in state.track_sysids()}
    return _colours(sids)


def _vehicles_document(
    state: StationState,
    frame: LocalFrame,
    track: list[TrackPoint],
    now_ns: int,
    footprint_every: int,
) -> list[dict[str, Any]]:
    """Each vehicle heard: its status, place, track, footprints and colour."""
    status = {v.sysid: v for v in state.vehicle_snapshot()}
    primary = state.primary_sysid
    points: dict[int, list[TrackPoint]] = {}
    for p in track:  # points of an older state file (no system id): the first vehicle's
        sid = p.sysid if p.sysid or primary is None else primary
        points.setdefault(sid, []).append(p)
    out = []
    colours = _colours(set(status) | set(points))
    for sid in sorted(colours):
        v = status.get(sid)
        d: dict[str, Any] = v.to_json(now_ns) if v is not None else {"sysid": sid}
        d["colour"] = colours[sid]
        d["track"] = [_place(frame, p.lat_deg, p.lon_deg) for p in points.get(sid, [])]
        fps = []
        for i, p in enumerate(points.get(sid, [])):
            if i % footprint_every == 0 and p.rel_alt_m > 0.2:
                x, y = d["track"][i]
                fps.append(_footprint(x, y, p.rel_alt_m, p.yaw))
        d["footprints"] = fps[-400:]
        d["xy"] = d["footprint_now"] = None
        if v is not None and v.lat_deg is not None and v.lon_deg is not None:
            x, y = d["xy"] = _place(frame, v.lat_deg, v.lon_deg)
            if v.rel_alt_m is not None and v.yaw is not None:
                fp = camera_footprint(
                    v.rel_alt_m, v.roll or 0.0, v.pitch or 0.0, v.yaw, v.mount_deg
                )
                if fp is not None:
                    d["footprint_now"] = [[round(x + e, 2), round(y + n, 2)] for e, n in fp]
            d["camera"] = "mount" if v.mount_deg is not None else "nadir"
        if v is not None and v.home is not None:
            d["home_xy"] = _place(frame, v.home[0], v.home[1])
        out.append(d)
    return out


def _home(state: StationState, track: list[TrackPoint]) -> tuple[tuple[float, float], str] | None:
    """The launch point distances are given from: the first vehicle's HOME_POSITION, else
    its first position heard."""
    vehicles = {v.sysid: v for v in state.vehicle_snapshot()}
    order = sorted(vehicles, key=lambda s: (s != state.primary_sysid, s))
    for sid in order:
        home = vehicles[sid].home
        if home is not None:
            return (home[0], home[1]), f"vehicle {sid}'s home position"
    for p in track:
        if p.sysid in (0, state.primary_sysid) or state.primary_sysid is None:
            who = p.sysid or state.primary_sysid
            return (p.lat_deg, p.lon_deg), f"vehicle {who}'s first position"
    return None


def state_document(
    state: StationState, footprint_every: int = 3, marked_by: MarkedBy | None = None
) -> dict[str, Any]:
    """What the page draws, with positions in local metres (east, north).

    Each hole has its fields (:meth:`GroundHole.to_json`, ``tier``, ``vehicle_tier`` and
    ``vehicles`` included), ``x``/``y``/``r95`` in local metres, ``mgrs`` (its grid
    reference, :func:`~ground.station.locate.mgrs_text`), ``from_home`` and
    ``from_vehicles`` (``{"distance_m", "bearing_deg", "compass"}`` from the launch point
    and from each vehicle's position now), ``summary`` (its facts in one line, without the
    "why", which the page shows on its own line), ``picture`` (its URL or None) and
    ``marked_by`` (``{"operator", "pairing", "t_unix_ns"}`` of its newest mark, or None).
    ``vehicles``: each vehicle heard (:meth:`VehicleStatus.to_json`, with ``colour``,
    ``xy``, ``track``, ``footprints``, ``footprint_now``); ``home``: the launch point
    (``{"lat_deg", "lon_deg", "xy", "source"}``) or None; ``now_unix_ns``: the station's
    clock (ages on the page count from it). ``track`` and ``footprints``: every vehicle's
    together (the page draws each vehicle's own).
    """
    version, holes, track = state.snapshot()
    now_ns = state.clock()
    marked_by = marked_by or {}
    origin = (
        (holes[0].lat_deg, holes[0].lon_deg)
        if holes
        else (track[0].lat_deg, track[0].lon_deg)
        if track
        else None
    )
    if origin is None:
        placed = [v for v in state.vehicle_snapshot() if v.lat_deg is not None]
        if placed and placed[0].lat_deg is not None and placed[0].lon_deg is not None:
            origin = (placed[0].lat_deg, placed[0].lon_deg)
    doc: dict[str, Any] = {
        "version": version,
        "origin": origin,
        "now_unix_ns": now_ns,
        "holes": [],
        "track": [],
        "vehicles": [],
        "home": None,
    }
    if origin is None:
        return doc
    frame = LocalFrame(*origin)
    home = _home(state, track)
    if home is not None:
        doc["home"] = {
            "lat_deg": home[0][0],
            "lon_deg": home[0][1],
            "xy": _place(frame, *home[0]),
            "source": home[1],
        }
    doc["vehicles"] = _vehicles_document(state, frame, track, now_ns, footprint_every)
    here = [
        (v["sysid"], (v["lat_deg"], v["lon_deg"]))
        for v in doc["vehicles"]
        if v.get("lat_deg") is not None
    ]
    for h in holes:
        e, n = frame.to_en(h.lat_deg, h.lon_deg)
        d = h.to_json()
        d.update(
            x=round(float(e), 3),
            y=round(float(n), 3),
            r95=round(CIRCLE_95_PER_SIGMA * h.sigma_h_m, 3) if h.sigma_h_m is not None else None,
            mgrs=mgrs_text(h.lat_deg, h.lon_deg),
            from_home=_range(home[0] if home else None, h.lat_deg, h.lon_deg),
            from_vehicles=[
                {"sysid": sid, **(_range(at, h.lat_deg, h.lon_deg) or {})} for sid, at in here
            ],
            summary=hole_summary(h, why=False, vehicles=False),  # the page shows them apart
            picture=f"/cards/hole-{h.id}.jpg?rev={h.card_rev}" if h.has_picture else None,
            marked_by=(
                {
                    "operator": marked_by[h.id][0],
                    "t_unix_ns": marked_by[h.id][1],
                    "pairing": marked_by[h.id][2],
                }
                if h.id in marked_by
                else None
            ),
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


def station_url(host: str, port: int) -> str:
    """The page's address for a server bound to ``host:port``, as a browser opens it.

    >>> station_url("127.0.0.1", 8080)
    'http://127.0.0.1:8080/'
    """
    return f"http://{_shown_host(host)}:{port}/"


def _shown_host(host: str) -> str:
    """The address to print for a server bound to ``host`` (0.0.0.0: the primary one)."""
    try:
        unspecified = ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return host
    if not unspecified:
        return host
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.connect(("10.255.255.255", 1))  # no packet is sent: only picks the route
        return str(s.getsockname()[0])
    return "127.0.0.1"


class StationWeb:
    """The page's server on its own thread. Use as a context manager.

    on_mark(hole_id, mark) makes an operator's mark (default: set it in the state) after
    :meth:`mark` wrote it to the audit trail. port 0 picks a free port (see :attr:`url`).
    pairings : who may mark (default: the folder's, :class:`Pairings`). names : host names
    the page is served as, besides its addresses (default: this machine's hostname and
    HOSTNAME.local). limits : the request bounds. map_store : the live map's tiles
    (:mod:`ground.station.maplayers`; None: no map).
    """

    def __init__(
        self,
        state: StationState,
        host: str = "127.0.0.1",
        port: int = 8080,
        on_mark: Callable[[int, str], Any] | None = None,
        *,
        pairings: Pairings | None = None,
        names: Iterable[str] | None = None,
        limits: Limits | None = None,
        map_store: MapStore | None = None,
        public_url: str | None = None,
        vehicles: Callable[[GroundHole], list[int]] | None = None,
        kml_refresh_s: float = 5.0,
        basemaps: Sequence[Basemap] = (),
    ) -> None:
        self.state = state
        self._public_url = public_url
        self.vehicles = vehicles or (lambda h: h.sysids)
        self.kml_refresh_s = kml_refresh_s
        self.basemaps = tuple(basemaps)
        self.map_store = map_store
        self._map_cache = CombinedCache(map_store) if map_store is not None else None
        self._vehicle_maps = (
            VehicleMaps(map_store, lambda: vehicle_colours(state))
            if map_store is not None
            else None
        )
        self.on_mark = on_mark or state.mark
        self.pairings = pairings or Pairings(state.folder)
        self.names = tuple(default_names() if names is None else names)
        self.limits = limits = limits or Limits()
        self.audit = AuditTrail(state.folder)
        self.marked_by: MarkedBy = {}
        for e in self.audit.read():
            with contextlib.suppress(KeyError, TypeError, ValueError):
                self.marked_by[int(e["hole"])] = (
                    str(e["operator"]),
                    int(e["t_unix_ns"]),
                    str(e.get("pairing", "")),
                )
        self.refused = 0
        """Requests answered 4xx (or refused before any route) so far."""
        self.errors = 0
        """Requests whose handler raised (a bug: the fuzz tests want none)."""
        self._mark_lock = threading.Lock()
        # the web stack (the ground extra) is imported when a page is served, not with
        # holescan.ground: the flight install can import the ground package's names
        from holescan.ground.station.events import Changes, EventStream
        from holescan.ground.station.feeds import GapsCache, check_public_url
        from holescan.ground.station.webapp import make_app
        from holescan.ground.station.webserver import WebServer

        if public_url is not None:
            self._public_url = check_public_url(public_url)
            name = urlsplit(self._public_url).hostname or ""
            with contextlib.suppress(ValueError):
                ipaddress.ip_address(name)
                name = ""  # an address is checked against the connection's own
            if name and name not in self.names:
                self.names = (*self.names, name)
        self._gaps = GapsCache(self._map_cache) if self._map_cache is not None else None

        self.changes: Changes = Changes(state.version)
        self.events: EventStream = EventStream(self.changes, limits)
        state.listeners.append(self.changes.set)
        app = GuardMiddleware(
            make_app(self),
            names=self.names,
            rate=RateLimiter(limits.rate_per_s, limits.burst),
            on_refuse=self._count_refused,
            max_head_bytes=limits.max_head_bytes,
        )
        self.server: WebServer = WebServer(app, host, port, limits)

    def _count_refused(self) -> None:
        self.refused += 1

    @property
    def port(self) -> int:
        return int(self.server.address[1])

    @property
    def cut(self) -> int:
        """Connections cut off for not sending a whole request in time."""
        return self.server.counters.cut

    @property
    def url(self) -> str:
        """The page, read-only (no pairing)."""
        return station_url(str(self.server.address[0]), self.port)

    @property
    def public_url(self) -> str:
        """The station as the crew's devices reach it (picture links in feeds and CoT)."""
        return self._public_url or self.url

    def feed(self, path: str) -> bytes | None:
        """A live layer for the crew's other tools (:mod:`ground.station.feeds`), or None
        when ``path`` is none."""
        from holescan.ground.station import feeds

        holes = self.state.snapshot()[1]
        if path == "/holes.geojson":
            return feeds.holes_geojson(holes, self.vehicles, self.public_url)
        if path == "/holes.kml":
            return feeds.holes_kml(holes, self.public_url)
        if path == "/holes_live.kml":
            return feeds.live_kml(self.public_url, self.kml_refresh_s)
        if path == "/gaps.geojson":
            return feeds.EMPTY if self._gaps is None else self._gaps.get()
        return None

    def pair_url(self, token: str) -> str:
        """The pairing link of ``token`` (:meth:`Pairings.issue`): opened once in an
        operator's browser, it lets that browser mark under the pairing."""
        return f"{self.url}?token={token}"

    def __enter__(self) -> StationWeb:
        self.server.__enter__()
        _log.info("live page on %s", self.url)
        return self

    def __exit__(self, *exc: object) -> None:
        self.changes.close()
        self.server.__exit__()
        if self.changes.set in self.state.listeners:
            self.state.listeners.remove(self.changes.set)

    def state_json(self, paired: Pairing | None) -> bytes:
        """:func:`state_document` as JSON, with ``can_mark`` and ``paired`` (the asker's
        pairing: ``{"pairing", "operator"}``, or None)."""
        doc = state_document(self.state, marked_by=dict(self.marked_by))
        doc["can_mark"] = paired is not None
        doc["paired"] = (
            None if paired is None else {"pairing": paired.id, "operator": paired.operator}
        )
        return json.dumps(doc, allow_nan=False).encode()

    def card(self, hole_id: int) -> bytes:
        """A hole's picture (raises OSError when there is none)."""
        return self.state.card_path(hole_id).read_bytes()

    def map_reply(self, path: str, query: str) -> Reply | None:
        """The live map's or a basemap's answer to a GET of ``path`` (None: neither)."""
        got = basemap_route(self.basemaps, path, query)
        if got is not None:
            return got
        return map_route(self.map_store, path, query, self._map_cache, self._vehicle_maps)

    def mark(self, hole_id: int, mark: str, pairing: Pairing, client: str) -> GroundHole:
        """An operator's mark: into the audit trail first (a change that cannot be audited
        is not made), then :attr:`on_mark`.

        Raises
        ------
        LookupError : no such hole. InputError : a bad mark. AuditError : the trail cannot
            be written (nothing is changed).
        """
        if mark not in MARKS:
            raise InputError(f"mark must be one of {', '.join(MARKS)}, got {mark!r}")
        with self._mark_lock:
            before = next((h for h in self.state.snapshot()[1] if h.id == hole_id), None)
            if before is None:
                raise LookupError(f"no hole {hole_id}")
            after = dataclasses.replace(before, mark=mark)
            t_ns = self.state.clock()
            entry = AuditEntry(
                t_ns,
                pairing.id,
                pairing.operator,
                client,
                hole_id,
                before.mark,
                mark,
                before.tier,
                after.tier,
            )
            self.audit.append(entry)
            self.marked_by[hole_id] = (pairing.operator, t_ns, pairing.id)
            h: GroundHole = self.on_mark(hole_id, mark)
        _log.info("hole %d marked %s by %s from %s", hole_id, mark, pairing, client)
        return h
