"""``holescan ground``: the ground station app, composed.

One process on the ground-station laptop beside QGroundControl / Mission Planner, fed the
vehicle's MAVLink stream (MAVProxy ``--out``, a UDP port or a serial radio):

* :class:`~ground.station.link.VehicleLink` collects holes (STATUSTEXT, cards, the hole
  mission of component 191) and the track into a
  :class:`~ground.station.state.StationState` kept in ``DIR/station.json``;
* after each change: the files (``holes.kml``, ``holes_live.kml``, ``holes.geojson``,
  ``holes.gpx``; :mod:`ground.station.files`; ``holes_datapackage.zip``, the TAK data
  package with the pictures, :mod:`ground.station.datapackage`), TAK (each new or changed
  hole of a tier TAK shows re-sent as CoT, a rejected one, or one TAK showed that is no
  longer of such a tier, withdrawn; :mod:`ground.station.cot`, the link
  :mod:`ground.station.tak`), the live page (:mod:`ground.station.web`, Server-Sent
  Events);
* the live map's tiles (coverage, orthophoto) kept in ``DIR/map/``
  (:mod:`ground.station.mapstore`) and drawn on the page (:mod:`ground.station.maplayers`);
* every ``cot_refresh_s`` all holes are sent to TAK again (markers outlive their stale
  time only while the station runs).

The files and TAK follow on the station's own thread (``ground-follow``), never on the
thread of a web request or of the MAVLink link: an operator's mark is in the state (and
the audit trail) when the page is answered, and the follower writes the files and sends
TAK right after; one lock per station keeps a flush whole.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from holescan.errors import InputError
from holescan.ground.station.basemap import Basemap, open_basemap
from holescan.ground.station.cot import hole_cot, hole_tier, on_tak, withdraw_cot
from holescan.ground.station.datapackage import DATAPACKAGE_NAME, write_datapackage
from holescan.ground.station.files import write_station_files
from holescan.ground.station.link import VehicleLink
from holescan.ground.station.mapstore import MapStore
from holescan.ground.station.pairing import Pairing, Pairings, check_operator
from holescan.ground.station.records import GroundHole
from holescan.ground.station.state import StationState
from holescan.ground.station.tak import DEFAULT_COT_URL, CotPublisher, TakTls, tak_settings
from holescan.ground.station.web import StationWeb
from holescan.link import SigningKey
from holescan.outputs import OutputPathError

__all__ = ["GroundOptions", "GroundStation", "run_ground"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GroundOptions:
    """What ``holescan ground`` does.

    mavlink : connection to the vehicles' stream; more_mavlink : further links (each vehicle
    heard on any is followed; one picture). out : the station's folder (state, pictures,
    files). sysid : follow this vehicle only (None: every vehicle heard). http_host,
    http_port : the live page (port 0: any free one; None: no page). http_names : host names
    the page is served as besides its addresses (None: this machine's hostname and
    HOSTNAME.local; see :func:`ground.station.guard.host_allowed`). cot_url : pytak COT_URL
    (None: no TAK). cot_tls : the client certificate for a ``tls://`` TAK server. cot_proto
    : 0 = CoT XML, 1 = TAK protocol v1 (protobuf, via takproto). station : name in the CoT
    uids. cot_stale_s, cot_refresh_s : CoT stale time (from each sending) and re-send
    period, s. kml_refresh_s : Google Earth's NetworkLink reload period. overlay : a map
    overlay (``.kmz``) for the data package. signing : MAVLink 2 signing key shared with
    the vehicle (None: unsigned link). pair : operators to issue a pairing for at start
    (:mod:`ground.station.pairing`; when the folder has none and none is asked for, one
    for "operator 1"). public_url : the station's address as the crew's devices reach it,
    ``http://HOST:PORT`` (the picture links in CoT and in the live feeds; None: the
    address the page is bound to, the primary LAN address when bound to 0.0.0.0).
    basemaps : offline basemaps for the page (MBTiles, GeoTIFF; :mod:`ground.station.basemap`).
    """

    mavlink: str
    out: Path
    sysid: int | None = None
    more_mavlink: tuple[str, ...] = ()
    baud: int = 57600
    http_host: str = "127.0.0.1"
    http_port: int | None = 8080
    http_names: tuple[str, ...] | None = None
    cot_url: str | None = DEFAULT_COT_URL
    cot_proto: int = 0
    cot_tls: TakTls | None = None
    station: str = "ground"
    cot_stale_s: float = 3600.0
    cot_refresh_s: float = 600.0
    kml_refresh_s: float = 5.0
    silence_s: float = 3.0
    signing: SigningKey | None = None
    overlay: Path | None = None
    pair: tuple[str, ...] = ()
    public_url: str | None = None
    basemaps: tuple[Path, ...] = ()

    def check(self) -> None:
        """Raise InputError for options that cannot work together."""
        if not 0 < self.cot_refresh_s < self.cot_stale_s:
            raise InputError(
                f"the CoT re-send period ({self.cot_refresh_s:g} s) must be above 0 and "
                f"below the stale time ({self.cot_stale_s:g} s), or markers blink out"
            )
        if self.cot_proto == 1 and (self.cot_url or "").lower().startswith(("tcp", "tls")):
            raise InputError(
                "--cot-proto 1 (TAK protocol v1) is for mesh udp:// only: a TAK server's "
                "stream starts in CoT XML (--cot-proto 0)"
            )
        links = (self.mavlink, *self.more_mavlink)
        if len(set(links)) != len(links):
            raise InputError(f"a MAVLink link is given twice: {', '.join(links)}")
        if self.sysid is not None and not 1 <= self.sysid <= 255:
            raise InputError(f"--sysid must be 1..255, got {self.sysid}")
        if self.overlay is not None and not self.overlay.is_file():
            raise InputError(f"map overlay {self.overlay}: no such file")
        for name in self.pair:
            check_operator(name)
        if self.public_url is not None:
            from holescan.ground.station.feeds import check_public_url

            url = check_public_url(self.public_url)
            if self.http_port is None:
                raise InputError("--public-url is the live page's address: not with --http off")
            port = urlsplit(url).port
            if self.http_port and port != self.http_port:
                raise InputError(
                    f"--public-url {url} has port {port}, the page is served on port "
                    f"{self.http_port}: give the same port"
                )


class GroundStation:
    """The running app (see the module docstring); a context manager."""

    def __init__(self, opts: GroundOptions) -> None:
        self.opts = opts
        opts.check()  # the options first: a bad one creates nothing
        self.basemaps: list[Basemap] = []
        try:
            for path in opts.basemaps:
                self.basemaps.append(open_basemap(path))
        except InputError:
            for b in self.basemaps:
                b.close()
            raise
        self._tak = tak_settings(opts.cot_url, opts.cot_tls) if opts.cot_url is not None else None
        self.state = StationState.open(opts.out)
        self.map_store = MapStore.open(opts.out / "map")
        self._stack = contextlib.ExitStack()
        self._sent: dict[int, tuple[object, ...]] = {}
        self._on_tak: set[int] = set()
        self._files_key: tuple[object, ...] | None = None
        self._dirty = threading.Event()
        self._stop = threading.Event()
        self._flush_lock = threading.Lock()  # one per station: a flush is whole
        self.pairings = Pairings(opts.out)
        self.new_pairings: list[tuple[Pairing, str]] = []
        """Pairings issued at this start, with their tokens (to be shown once)."""
        self.web: StationWeb | None = None
        self.cot: CotPublisher | None = None
        self.link: VehicleLink | None = None
        """The first link (``opts.mavlink``); :attr:`links` has them all."""
        self.links: list[VehicleLink] = []
        self._worker = threading.Thread(target=self._follow, name="ground-follow", daemon=True)

    def __enter__(self) -> GroundStation:
        o = self.opts
        for b in self.basemaps:
            self._stack.callback(b.close)
        try:
            if o.http_port is not None:
                self.web = self._stack.enter_context(
                    StationWeb(
                        self.state,
                        o.http_host,
                        o.http_port,
                        on_mark=self.mark,
                        map_store=self.map_store,
                        names=o.http_names,
                        pairings=self.pairings,
                        public_url=o.public_url,
                        vehicles=self._vehicles,
                        kml_refresh_s=o.kml_refresh_s,
                        basemaps=self.basemaps,
                    )
                )
                names = list(o.pair) or ([] if self.pairings.all() else ["operator 1"])
                self.new_pairings = [self.pairings.issue(n) for n in names]
            if o.cot_url is not None and self._tak is not None:
                extra = {**self._tak, "TAK_PROTO": str(o.cot_proto)}
                self.cot = self._stack.enter_context(CotPublisher(o.cot_url, extra))
            self.state.listeners.append(lambda _v: self._dirty.set())
            self._dirty.set()
            self._worker.start()
            self._stack.callback(self._halt)
            for conn in (o.mavlink, *o.more_mavlink):
                link = self._stack.enter_context(
                    VehicleLink(
                        conn,
                        self.state,
                        sysid=o.sysid,
                        baud=o.baud,
                        silence_s=o.silence_s,
                        map_store=self.map_store,
                        signing=o.signing,
                    )
                )
                self.links.append(link)
            self.link = self.links[0]
        except BaseException:
            self._stack.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    def _halt(self) -> None:
        self._stop.set()
        self._dirty.set()
        self._worker.join(timeout=5.0)
        self.state.flush()  # a batched save still held
        self._flush()

    def _vehicles(self, h: GroundHole) -> list[int]:
        """The vehicles that reported hole ``h``, in the order they first did; a hole of
        an older state file (vehicles not told apart): the station's first vehicle."""
        if h.vehicles:
            return h.sysids
        primary = self.state.primary_sysid
        return [] if primary is None else [primary]

    def mark(self, hole_id: int, mark: str) -> GroundHole:
        """The operator's mark, in the state; TAK and the files follow on the station's
        thread right after."""
        h = self.state.mark(hole_id, mark)
        self._dirty.set()
        return h

    # -- following the state -----------------------------------------------------------
    def _follow(self) -> None:
        refresh = self.opts.cot_refresh_s
        last_refresh = time.monotonic()
        while not self._stop.is_set():
            if self._dirty.wait(min(refresh, 5.0)):
                self._dirty.clear()
            if time.monotonic() - last_refresh >= refresh:
                last_refresh = time.monotonic()
                with self._flush_lock:
                    self._sent.clear()  # re-send every hole before its CoT goes stale
            self._flush()

    def _flush(self) -> None:
        with self._flush_lock:
            _, holes, _ = self.state.snapshot()
            files_key = tuple(tuple(h.to_json().items()) for h in holes)
            if files_key != self._files_key:  # the track alone changes nothing in the files
                try:
                    write_station_files(self.opts.out, holes, refresh_s=self.opts.kml_refresh_s)
                    self._write_datapackage(holes)
                    self._files_key = files_key
                except (OSError, OutputPathError, InputError) as err:
                    _log.error("hole files not written: %s", err)
            if self.cot is None:
                return
            events: list[bytes] = []
            for gone in self._on_tak - {h.id for h in holes}:  # folded into another's
                events += withdraw_cot(gone, station=self.opts.station)
                self._on_tak.discard(gone)
                self._sent.pop(gone, None)
            for h in holes:
                tier = hole_tier(h)
                key: tuple[object, ...] = (h.lat_deg, h.lon_deg, h.p_hole, h.score, h.sigma_h_m)
                key += (tier, h.mark, h.card_rev)
                if self._sent.get(h.id) == key:
                    continue
                self._sent[h.id] = key
                if not on_tak(tier):
                    # rejected, or held for review: off every map that has it
                    if tier == "rejected" or h.id in self._on_tak:
                        events += withdraw_cot(h.id, station=self.opts.station)
                    self._on_tak.discard(h.id)
                else:
                    self._on_tak.add(h.id)
                    url = None
                    if self.web is not None and h.has_picture:
                        url = f"{self.web.public_url}cards/hole-{h.id}.jpg"
                    events.append(
                        hole_cot(
                            h,
                            station=self.opts.station,
                            stale_s=self.opts.cot_stale_s,
                            picture_url=url,
                        )
                    )
            if events:
                self.cot.publish(events)

    def _write_datapackage(self, holes: list[GroundHole]) -> None:
        pictures = {}
        for h in holes:
            if h.has_picture:
                try:
                    pictures[h.id] = self.state.card_path(h.id).read_bytes()
                except OSError as err:
                    _log.warning("hole %d's picture left out of the data package: %s", h.id, err)
        write_datapackage(
            self.opts.out / DATAPACKAGE_NAME,
            holes,
            pictures,
            station=self.opts.station,
            overlay=self.opts.overlay,
        )


def _loopback(url: str) -> bool:
    host = urlsplit(url).hostname or ""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def run_ground(
    opts: GroundOptions, stop: threading.Event, show: Callable[[str], None] | None = None
) -> GroundStation:
    """Run the station until ``stop`` is set; return it (closed) for its counters.

    show : where the pairing links issued at this start are shown, once (the terminal; a
    link is never written to the log). None: not shown (the log says how to issue one).
    """
    with GroundStation(opts) as station:
        if station.web is not None:
            _log.warning("live page (read-only): %s", station.web.url)
            public = station.web.public_url
            _log.warning(
                "live layers: %sholes.geojson, %sgaps.geojson (QGIS, CalTopo), "
                "%sholes_live.kml (Google Earth)",
                public,
                public,
                public,
            )
            if _loopback(public) and opts.cot_url is not None:
                _log.warning(
                    "picture links in CoT point at %s, which no handheld can open: serve the "
                    "page on the team's network (--http 0.0.0.0:PORT) or say its address "
                    "(--public-url http://ADDRESS:PORT)",
                    public,
                )
            if station.new_pairings and show is not None:
                show(
                    "Pairing links (shown once, not logged; each lets one operator's browser "
                    "mark holes under that operator's name; open it once in that browser):"
                )
                for p, token in station.new_pairings:
                    show(f"  {p.operator} ({p.id}): {station.web.pair_url(token)}")
            elif station.new_pairings:
                _log.warning(
                    "%d pairing link(s) issued but not shown (no terminal): issue one to show "
                    "with: holescan pair -o %s NAME",
                    len(station.new_pairings),
                    opts.out,
                )
            _log.warning(
                "operators paired: %s (more: holescan pair -o %s NAME; un-pair: delete the "
                "line from %s)",
                ", ".join(str(p) for p in station.pairings.all()) or "none",
                opts.out,
                station.pairings.path,
            )
        _log.warning(
            "files in %s: holes.kml, holes_live.kml (Google Earth), holes.geojson, holes.gpx, "
            "holes_datapackage.zip (TAK data package)",
            opts.out,
        )
        stop.wait()
    return station
