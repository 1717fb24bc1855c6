"""Holes as Cursor-on-Target for TAK (ATAK, WinTAK, iTAK), sent with pytak.

Each hole is one CoT event:

* ``uid`` ``holescan-<station>-hole-<id>``: stable, so a re-sent hole moves/updates the
  same marker on every TAK device;
* ``type`` ``b-m-p-s-p-i``: the map point type TAK's own type list (``cot-types.xml``,
  as shipped by ``@tak-ps/node-cot``) names "spi", sensor point of interest: a point a
  sensor (our camera) marks for people to look at; ``how`` ``m-g`` (machine, GPS-derived);
* ``point``: lat/lon; ``hae`` from the vehicle's MSL altitude (9999999 when unknown; the
  geoid offset is not applied); ``ce`` = 1.62 sigma (the 95 % circle of the horizontal
  error model, whose sigma is the 68 % circle), ``le`` = 9999999 (the vertical error is
  not modelled);
* ``detail``: ``contact callsign`` "HOLE <id>", ``remarks`` with size, score, sightings,
  uncertainty, the detector's "why" and the operator's mark, ``link`` to the picture's
  URL on the station's web page when one is served, a ``color`` by mark;
* ``stale``: ``stale_s`` (default 1 h) after sending; the station re-sends every hole
  before that (``refresh_s``), so a marker stays while the station runs and ages out if
  it stops.

A rejected hole is withdrawn: an event of the same uid with ``stale`` = now, followed by a
TAK delete (``t-x-d-d`` with a ``link`` to the uid and ``__forcedelete``).

:class:`CotPublisher` runs pytak's client (``udp+wo://239.2.3.1:6969`` mesh multicast by
default, ``tcp://HOST:8087`` or ``tls://HOST:8089`` for a TAK server) on its own asyncio
thread; :meth:`CotPublisher.publish` may be called from any thread.
"""

from __future__ import annotations

import asyncio
import configparser
import contextlib
import datetime as dt
import logging
import threading
import xml.etree.ElementTree as ET
from typing import Any

from holescan.geotag import CIRCLE_95_PER_SIGMA
from holescan.ground.errors import CotError
from holescan.ground.station.files import hole_summary
from holescan.ground.station.state import GroundHole

__all__ = ["COT_TYPE", "DEFAULT_COT_URL", "CotError", "CotPublisher", "hole_cot", "withdraw_cot"]

_log = logging.getLogger(__name__)

COT_TYPE = "b-m-p-s-p-i"
DEFAULT_COT_URL = "udp+wo://239.2.3.1:6969"
_UNKNOWN = "9999999.0"
_COLOURS = {  # ARGB as TAK writes it (signed 32-bit)
    "new": -256,  # yellow
    "confirmed": -65536,  # red: go there
    "visited": -16711936,  # green
    "rejected": -8355712,  # grey
}


def _time(t: dt.datetime) -> str:
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


def _uid(station: str, hole_id: int) -> str:
    return f"holescan-{station}-hole-{hole_id}"


def hole_cot(
    h: GroundHole,
    *,
    station: str = "ground",
    now: dt.datetime | None = None,
    stale_s: float = 3600.0,
    picture_url: str | None = None,
) -> bytes:
    """The CoT event (XML bytes) of one hole; see the module docstring."""
    now = now or dt.datetime.now(dt.UTC)
    ev = ET.Element(
        "event",
        {
            "version": "2.0",
            "uid": _uid(station, h.id),
            "type": COT_TYPE,
            "how": "m-g",
            "time": _time(now),
            "start": _time(now),
            "stale": _time(now + dt.timedelta(seconds=stale_s)),
        },
    )
    ce = f"{CIRCLE_95_PER_SIGMA * h.sigma_h_m:.2f}" if h.sigma_h_m is not None else _UNKNOWN
    hae = f"{h.alt_m:.2f}" if h.alt_m is not None else _UNKNOWN
    lat, lon = f"{h.lat_deg:.7f}", f"{h.lon_deg:.7f}"
    ET.SubElement(ev, "point", {"lat": lat, "lon": lon, "hae": hae, "ce": ce, "le": _UNKNOWN})
    detail = ET.SubElement(ev, "detail")
    ET.SubElement(detail, "contact", {"callsign": f"HOLE {h.id}"})
    ET.SubElement(detail, "remarks").text = hole_summary(h)
    ET.SubElement(detail, "color", {"argb": str(_COLOURS.get(h.mark, -256))})
    ET.SubElement(detail, "precisionlocation", {"geopointsrc": "GPS", "altsrc": "GPS"})
    if picture_url is not None:
        ET.SubElement(detail, "link", {"url": picture_url, "relation": "r-u", "mime": "image/jpeg"})
    return bytes(ET.tostring(ev, encoding="utf-8", xml_declaration=False))


def withdraw_cot(
    hole_id: int, *, station: str = "ground", now: dt.datetime | None = None
) -> list[bytes]:
    """Events that take a hole off TAK maps: stale now, then a ``t-x-d-d`` delete."""
    now = now or dt.datetime.now(dt.UTC)
    uid = _uid(station, hole_id)
    stamp = {"time": _time(now), "start": _time(now), "stale": _time(now)}
    stale = ET.Element(
        "event", {"version": "2.0", "uid": uid, "type": COT_TYPE, "how": "m-g", **stamp}
    )
    ET.SubElement(
        stale, "point", {"lat": "0", "lon": "0", "hae": _UNKNOWN, "ce": _UNKNOWN, "le": _UNKNOWN}
    )
    ET.SubElement(stale, "detail")
    delete = ET.Element(
        "event",
        {
            "version": "2.0",
            "uid": f"{uid}-delete",
            "type": "t-x-d-d",
            "how": "h-g-i-g-o",
            "time": _time(now),
            "start": _time(now),
            "stale": _time(now + dt.timedelta(seconds=20)),
        },
    )
    ET.SubElement(
        delete, "point", {"lat": "0", "lon": "0", "hae": _UNKNOWN, "ce": _UNKNOWN, "le": _UNKNOWN}
    )
    d = ET.SubElement(delete, "detail")
    ET.SubElement(d, "link", {"uid": uid, "relation": "none", "type": COT_TYPE})
    ET.SubElement(d, "__forcedelete")
    return [ET.tostring(e, encoding="utf-8") for e in (stale, delete)]


class CotPublisher:
    """pytak's client on its own asyncio thread; :meth:`publish` queues events.

    url : pytak ``COT_URL`` (``udp+wo://239.2.3.1:6969``, ``udp://HOST:PORT``,
    ``tcp://HOST:8087``, ``tls://HOST:8089`` with ``tls`` settings). extra : more pytak
    settings (``PYTAK_TLS_CLIENT_CERT`` ...). A link that cannot be opened or breaks is
    logged in one line and retried; events wait in the queue meanwhile (newest kept).
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

    async def _send_loop(self) -> None:
        import pytak  # imported here: pytak is needed only when TAK is on

        assert self._queue is not None
        parser = configparser.ConfigParser()
        parser["holescan"] = self._config
        config = parser["holescan"]
        tx: Any = None
        pending: bytes | None = None
        warned = False
        while True:
            if tx is None:
                try:
                    _, writer = await pytak.protocol_factory(config)
                    tx = pytak.TXWorker(self._queue, config, writer)
                    if warned:
                        _log.warning("TAK link %s is up again", self.url)
                    warned = False
                except Exception as err:
                    if not warned:
                        _log.warning("TAK link %s cannot be opened (%s); retrying", self.url, err)
                    warned = True
                    await asyncio.sleep(2.0)
                    continue
            data = pending if pending is not None else await self._queue.get()
            try:
                await tx.send_data(data)
                self.sent += 1
                pending = None
            except Exception as err:
                self.errors += 1
                _log.warning("TAK send to %s failed (%s); reconnecting", self.url, err)
                pending, tx = data, None
                await asyncio.sleep(1.0)
