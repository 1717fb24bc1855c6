"""Holes as Cursor-on-Target events for TAK (ATAK, WinTAK, iTAK).

Each hole is one CoT event:

* ``uid`` ``holescan-<station>-hole-<id>``: stable, so a re-sent hole moves/updates the
  same marker on every TAK device;
* ``type`` ``b-m-p-s-p-i``: the map point type TAK's own type list (``cot-types.xml``,
  as shipped by ``@tak-ps/node-cot``) names "spi", sensor point of interest: a point a
  sensor (our camera) marks for people to look at; ``how`` ``m-g`` (machine, GPS-derived);
* ``point``: lat/lon; ``hae`` from the vehicle's MSL altitude (9999999 when unknown; the
  geoid offset is not applied); ``ce`` from the error model: 1.62 sigma, the 95 % circle
  of the hole's horizontal error (its ``sigma_h_m`` is the 68 % circle). The CoT 2.0
  schema calls ``ce`` "circular 1-sigma or a circular area about the point"; ATAK draws
  and reads it as a circle to search, so the conservative circle is sent and the 1-sigma
  figure is in the remarks. ``le`` = 9999999 (the vertical error is not modelled);
* ``detail``: ``contact callsign`` "HOLE <id>", ``remarks`` starting with the tier, then
  size, score, sightings, uncertainty, the vehicles that saw it (first and last), the
  detector's "why", the operator's mark and the point's age (first seen / last updated,
  from ``now``); a ``holescan`` element with the same facts as attributes (tier, mark,
  score, sightings, sigma, times, ``vehicles``, ``first_vehicle``, ``last_vehicle``) for
  tools; a
  ``link`` to the picture's URL on the station's web page when one is served; a
  ``color`` by tier;
* ``stale``: ``stale_s`` after ``now`` (the time the event is made, never the first
  sighting): the station re-sends every hole before that (``refresh_s``), so a marker
  stays while the station runs and ages out if it stops.

Tiers (:data:`TIERS`): ``announced`` (the vehicle's announce gate passed it),
``review`` (held for an operator: sent to TAK only once confirmed), ``confirmed`` (an
operator confirmed or visited it), ``rejected`` (withdrawn). :func:`hole_tier` is the one
place that reads a hole's tier; :func:`on_tak` says which tiers TAK shows.

A rejected hole is withdrawn: an event of the same uid with ``stale`` = now, followed by a
TAK delete (``t-x-d-d`` with a ``link`` to the uid and ``__forcedelete``).

The link to TAK (mesh multicast, a TAK server over TCP or TLS) is
:class:`~ground.station.tak.CotPublisher`; the offline data package is
:mod:`ground.station.datapackage`.
"""

from __future__ import annotations

import datetime as dt
import json
import xml.etree.ElementTree as ET

from holescan.geotag import CIRCLE_95_PER_SIGMA
from holescan.ground.station.files import hole_summary
from holescan.ground.station.records import TIERS, GroundHole, Tier
from holescan.link import xml_safe_tree
from holescan.utc import utc_datetime, utc_text

__all__ = [
    "COT_TYPE",
    "TIERS",
    "Tier",
    "cot_uid",
    "hole_cot",
    "hole_tier",
    "on_tak",
    "point_age",
    "withdraw_cot",
]

COT_TYPE = "b-m-p-s-p-i"
_UNKNOWN = "9999999.0"
_COLOURS: dict[Tier, int] = {  # ARGB as TAK writes it (signed 32-bit)
    "announced": -256,  # yellow
    "review": -23296,  # orange
    "confirmed": -65536,  # red: go there
    "rejected": -8355712,  # grey
}


def hole_tier(h: GroundHole) -> Tier:
    """The hole's tier (:attr:`GroundHole.tier`: the operator's mark over the vehicle's tier).

    >>> hole_tier(GroundHole(1, 0.0, 0.0, 0.9, mark="visited"))
    'confirmed'
    >>> hole_tier(GroundHole(1, 0.0, 0.0, 0.9))
    'announced'
    """
    return h.tier


def on_tak(tier: Tier) -> bool:
    """Whether TAK shows a hole of this tier (announced and confirmed ones)."""
    return tier in ("announced", "confirmed")


def cot_uid(station: str, hole_id: int) -> str:
    """The hole's CoT uid (one per station and hole id)."""
    return f"holescan-{station}-hole-{hole_id}"


def _span(seconds: float) -> str:
    """A short duration for people.

    >>> _span(42), _span(600), _span(5400), _span(200000)
    ('42 s', '10 min', '1.5 h', '2.3 d')
    """
    s = max(0.0, seconds)
    if s < 90:
        return f"{s:.0f} s"
    if s < 90 * 60:
        return f"{s / 60:.0f} min"
    if s < 48 * 3600:
        return f"{s / 3600:.1f} h"
    return f"{s / 86400:.1f} d"


def point_age(h: GroundHole, now: dt.datetime) -> str:
    """The point's age at ``now`` in words: first seen and last updated (empty when the
    hole carries no times).

    >>> t = dt.datetime(2026, 12, 3, 12, 30, tzinfo=dt.UTC)
    >>> ns = int(t.timestamp()) * 10**9
    >>> h = GroundHole(1, 0.0, 0.0, 0.9, t_first_unix_ns=ns, t_updated_unix_ns=ns + 540 * 10**9)
    >>> point_age(h, t + dt.timedelta(minutes=12))
    'first seen 12 min ago (12:30Z), updated 3 min ago'
    """
    if h.t_first_unix_ns <= 0:
        return ""
    first = utc_datetime(h.t_first_unix_ns)
    text = f"first seen {_span((now - first).total_seconds())} ago ({first:%H:%MZ})"
    if h.t_updated_unix_ns > h.t_first_unix_ns:
        text += f", updated {_span((now - utc_datetime(h.t_updated_unix_ns)).total_seconds())} ago"
    return text


def hole_cot(
    h: GroundHole,
    *,
    station: str = "ground",
    now: dt.datetime | None = None,
    stale_s: float = 3600.0,
    picture_url: str | None = None,
    attachment_sha256: str | None = None,
    archive: bool = False,
) -> bytes:
    """The CoT event (XML bytes) of one hole; see the module docstring.

    now : when the event is made (default: the clock now); ``time``/``start`` are ``now``,
    ``stale`` is ``now + stale_s``. attachment_sha256 : SHA-256 (hex) of the picture
    packed beside the event in a data package (``attachment_list``, as ATAK's QuickPic
    writes it). archive : ATAK keeps the marker (``<archive/>``), for data packages.
    """
    if stale_s <= 0:
        raise ValueError(f"stale_s must be > 0 seconds, got {stale_s}")
    now = now or dt.datetime.now(dt.UTC)
    tier = hole_tier(h)
    ev = ET.Element(
        "event",
        {
            "version": "2.0",
            "uid": cot_uid(station, h.id),
            "type": COT_TYPE,
            "how": "m-g",
            "time": utc_text(now),
            "start": utc_text(now),
            "stale": utc_text(now + dt.timedelta(seconds=stale_s)),
        },
    )
    ce = f"{CIRCLE_95_PER_SIGMA * h.sigma_h_m:.2f}" if h.sigma_h_m is not None else _UNKNOWN
    hae = f"{h.alt_m:.2f}" if h.alt_m is not None else _UNKNOWN
    lat, lon = f"{h.lat_deg:.7f}", f"{h.lon_deg:.7f}"
    ET.SubElement(ev, "point", {"lat": lat, "lon": lon, "hae": hae, "ce": ce, "le": _UNKNOWN})
    detail = ET.SubElement(ev, "detail")
    ET.SubElement(detail, "contact", {"callsign": f"HOLE {h.id}"})
    age = point_age(h, now)
    remarks = f"{tier.upper()}: {hole_summary(h)}"
    ET.SubElement(detail, "remarks").text = f"{remarks} ({age})" if age else remarks
    facts = {"tier": tier, "mark": h.mark, "sightings": str(h.sightings)}
    if h.p_hole is not None:
        facts["p_hole"] = f"{h.p_hole:.3f}"
    if h.score is not None:
        facts["score"] = f"{h.score:.3f}"
    if h.sigma_h_m is not None:
        facts["sigma_h_m"] = f"{h.sigma_h_m:.3f}"
    first_last = h.first_last
    if first_last is not None:  # system ids: numbers the link checked (1..255)
        facts["vehicles"] = " ".join(map(str, h.sysids))
        facts["first_vehicle"], facts["last_vehicle"] = (str(s) for s in first_last)
    if h.t_first_unix_ns > 0:
        facts["first_seen"] = utc_text(h.t_first_unix_ns)
    if h.t_updated_unix_ns > 0:
        facts["updated"] = utc_text(h.t_updated_unix_ns)
    ET.SubElement(detail, "holescan", facts)
    ET.SubElement(detail, "color", {"argb": str(_COLOURS[tier])})
    ET.SubElement(detail, "precisionlocation", {"geopointsrc": "GPS", "altsrc": "GPS"})
    if picture_url is not None:
        ET.SubElement(detail, "link", {"url": picture_url, "relation": "r-u", "mime": "image/jpeg"})
    if attachment_sha256 is not None:
        ET.SubElement(detail, "attachment_list", {"hashes": json.dumps([attachment_sha256])})
    if archive:
        ET.SubElement(detail, "archive")
    xml_safe_tree(ev)  # the last line of defence: no character a TAK parser refuses
    return bytes(ET.tostring(ev, encoding="utf-8", xml_declaration=False))


def withdraw_cot(
    hole_id: int, *, station: str = "ground", now: dt.datetime | None = None
) -> list[bytes]:
    """Events that take a hole off TAK maps: stale now, then a ``t-x-d-d`` delete."""
    now = now or dt.datetime.now(dt.UTC)
    uid = cot_uid(station, hole_id)
    stamp = {"time": utc_text(now), "start": utc_text(now), "stale": utc_text(now)}
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
            "time": utc_text(now),
            "start": utc_text(now),
            "stale": utc_text(now + dt.timedelta(seconds=20)),
        },
    )
    ET.SubElement(
        delete, "point", {"lat": "0", "lon": "0", "hae": _UNKNOWN, "ce": _UNKNOWN, "le": _UNKNOWN}
    )
    d = ET.SubElement(delete, "detail")
    ET.SubElement(d, "link", {"uid": uid, "relation": "none", "type": COT_TYPE})
    ET.SubElement(d, "__forcedelete")
    return [ET.tostring(xml_safe_tree(e), encoding="utf-8") for e in (stale, delete)]
