"""``holescan ground``: the ground station app, composed.

One process on the ground-station laptop beside QGroundControl / Mission Planner, fed the
vehicle's MAVLink stream (MAVProxy ``--out``, a UDP port or a serial radio):

* :class:`~ground.station.link.VehicleLink` collects holes (STATUSTEXT, cards, the hole
  mission of component 191) and the track into a
  :class:`~ground.station.state.StationState` kept in ``DIR/station.json``;
* after each change: the files (``holes.kml``, ``holes_live.kml``, ``holes.geojson``,
  ``holes.gpx``; :mod:`ground.station.files`), TAK (each new or changed hole re-sent as
  CoT, a rejected one withdrawn; :mod:`ground.station.cot`), the live page
  (:mod:`ground.station.web`, Server-Sent Events);
* the live map's tiles (coverage, orthophoto) kept in ``DIR/map/``
  (:mod:`ground.station.mapstore`) and drawn on the page (:mod:`ground.station.maplayers`);
* every ``cot_refresh_s`` all holes are sent to TAK again (markers outlive their stale
  time only while the station runs).
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from holescan.capture import OutputPathError
from holescan.ground.station.cot import DEFAULT_COT_URL, CotPublisher, hole_cot, withdraw_cot
from holescan.ground.station.files import write_station_files
from holescan.ground.station.link import VehicleLink
from holescan.ground.station.mapstore import MapStore
from holescan.ground.station.state import GroundHole, StationState
from holescan.ground.station.web import StationWeb

__all__ = ["GroundOptions", "GroundStation", "run_ground"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GroundOptions:
    """What ``holescan ground`` does.

    mavlink : connection to the vehicle's stream. out : the station's folder (state,
    pictures, files). sysid : the vehicle (None: first heard). http_host, http_port :
    the live page (port 0: any free one; None: no page). cot_url : pytak COT_URL (None:
    no TAK). cot_proto : 0 = CoT XML, 1 = TAK protocol v1 (protobuf, via takproto).
    station : name in the CoT uids. cot_stale_s, cot_refresh_s : CoT stale time
    and re-send period. kml_refresh_s : Google Earth's NetworkLink reload period.
    """

    mavlink: str
    out: Path
    sysid: int | None = None
    baud: int = 57600
    http_host: str = "127.0.0.1"
    http_port: int | None = 8080
    cot_url: str | None = DEFAULT_COT_URL
    cot_proto: int = 0
    station: str = "ground"
    cot_stale_s: float = 3600.0
    cot_refresh_s: float = 600.0
    kml_refresh_s: float = 5.0
    silence_s: float = 3.0


class GroundStation:
    """The running app (see the module docstring); a context manager."""

    def __init__(self, opts: GroundOptions) -> None:
        self.opts = opts
        self.state = StationState.open(opts.out)
        self.map_store = MapStore.open(opts.out / "map")
        self._stack = contextlib.ExitStack()
        self._sent: dict[int, tuple[object, ...]] = {}
        self._files_key: tuple[object, ...] | None = None
        self._dirty = threading.Event()
        self._stop = threading.Event()
        self.web: StationWeb | None = None
        self.cot: CotPublisher | None = None
        self.link: VehicleLink | None = None
        self._worker = threading.Thread(target=self._follow, name="ground-follow", daemon=True)

    def __enter__(self) -> GroundStation:
        o = self.opts
        try:
            if o.http_port is not None:
                self.web = self._stack.enter_context(
                    StationWeb(
                        self.state,
                        o.http_host,
                        o.http_port,
                        on_mark=self.mark,
                        map_store=self.map_store,
                    )
                )
            if o.cot_url is not None:
                extra = {"TAK_PROTO": str(o.cot_proto)}
                self.cot = self._stack.enter_context(CotPublisher(o.cot_url, extra))
            self.state.listeners.append(lambda _v: self._dirty.set())
            self._dirty.set()
            self._worker.start()
            self._stack.callback(self._halt)
            self.link = self._stack.enter_context(
                VehicleLink(
                    o.mavlink,
                    self.state,
                    sysid=o.sysid,
                    baud=o.baud,
                    silence_s=o.silence_s,
                    map_store=self.map_store,
                )
            )
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
        self._flush()

    def mark(self, hole_id: int, mark: str) -> GroundHole:
        """The operator's mark; TAK and the files follow at once."""
        h = self.state.mark(hole_id, mark)
        self._flush()
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

    _flush_lock = threading.Lock()

    def _flush(self) -> None:
        with self._flush_lock:
            _, holes, _ = self.state.snapshot()
            files_key = tuple(tuple(h.to_json().items()) for h in holes)
            if files_key != self._files_key:  # the track alone changes nothing in the files
                try:
                    write_station_files(self.opts.out, holes, refresh_s=self.opts.kml_refresh_s)
                    self._files_key = files_key
                except (OSError, OutputPathError) as err:
                    _log.error("hole files not written: %s", err)
            if self.cot is None:
                return
            events: list[bytes] = []
            for h in holes:
                key = (h.lat_deg, h.lon_deg, h.score, h.mark, h.card_rev, h.sigma_h_m)
                if self._sent.get(h.id) == key:
                    continue
                self._sent[h.id] = key
                if h.mark == "rejected":
                    events += withdraw_cot(h.id, station=self.opts.station)
                else:
                    url = None
                    if self.web is not None and h.has_picture:
                        url = f"{self.web.url}cards/hole-{h.id}.jpg"
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


def run_ground(opts: GroundOptions, stop: threading.Event) -> GroundStation:
    """Run the station until ``stop`` is set; return it (closed) for its counters."""
    with GroundStation(opts) as station:
        if station.web is not None:
            _log.warning("live page: %s", station.web.url)
        _log.warning(
            "files in %s: holes.kml, holes_live.kml (Google Earth), holes.geojson, holes.gpx",
            opts.out,
        )
        stop.wait()
    return station
