"""Values that arrive over MAVLink, checked before anything stores or shows them.

Every number and text a peer sends (a hole's STATUSTEXT, a card's facts, a map tile's
facts, the autopilot's position and attitude, a mission item) is possibly hostile: an
unsigned link takes packets from anyone on the incident network, and even a signed one
must not let a bug on the vehicle poison the ground. This module is the one place that
says what a well-formed value is; the ground station (:mod:`ground.station.state`,
:mod:`ground.station.link`) calls it, and a value it refuses raises
:class:`LinkValueError` (the caller counts the packet, logs one line and keeps nothing of
it).

The ranges are the protocol's (what the vehicle side can send) with room for real places:

* positions: latitude -90..90, longitude -180..180 (finite);
* altitudes MSL -1,000..10,000 m; heights above home -1,000..10,000 m;
* sizes (an opening's axes, a hole's 1-sigma) 0..1,000 m; scores and probabilities 0..1;
* angles (yaw) -2 pi..2 pi rad (ATTITUDE says -pi..pi);
* hole ids 0..999,999,999 (:data:`HOLE_ID_MAX`: what a STATUSTEXT carries with 7 decimals,
  and what the station's page marks); card revisions and sightings 0..2**31-1;
* text: what XML 1.0 can hold (:func:`xml_text`: control characters but tab, newline and
  carriage return are dropped, as are surrogates and U+FFFE/U+FFFF), at most a length.

Writers of XML and JSON apply :func:`xml_text` (and strict JSON, ``allow_nan=False``) again
as a last line of defence: a value that slipped past here still cannot make a file that a
parser refuses.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from holescan.link.errors import LinkValueError

__all__ = [
    "HOLE_ID_MAX",
    "CardValues",
    "LinkValueError",
    "card_values",
    "check_hole_id",
    "link_float",
    "link_int",
    "link_lat_lon",
    "link_yaw",
    "optional_float",
    "xml_safe_tree",
    "xml_text",
]

HOLE_ID_MAX = 999_999_999
"""The highest hole id the protocol carries (a STATUSTEXT of 50 characters with 7 decimals)."""
INT32_MAX = 2**31 - 1
ALT_RANGE_M = (-1000.0, 10_000.0)
SIZE_RANGE_M = (0.0, 1000.0)
WHY_MAX_CHARS = 500
# what XML 1.0 cannot hold: C0 controls but \t \n \r, surrogates, U+FFFE and U+FFFF
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def link_float(value: Any, lo: float, hi: float, what: str) -> float:
    """``value`` as a float within ``lo..hi`` (finite), else :class:`LinkValueError`.

    >>> link_float("0.5", 0, 1, "score")
    0.5
    >>> try:
    ...     link_float(float("nan"), 0, 1, "score")
    ... except LinkValueError as err:
    ...     print(err)
    score must be a number within 0..1, got nan
    """
    if isinstance(value, bool):
        raise LinkValueError(f"{what} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise LinkValueError(f"{what} must be a number, got {_short(value)}") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise LinkValueError(f"{what} must be a number within {lo:g}..{hi:g}, got {_short(v)}")
    return v


def optional_float(value: Any, lo: float, hi: float, what: str) -> float | None:
    """None stays None (a fact not told); anything else as :func:`link_float`."""
    return None if value is None else link_float(value, lo, hi, what)


def link_int(value: Any, lo: int, hi: int, what: str) -> int:
    """``value`` as an int within ``lo..hi``: an int or a float holding a whole number;
    never a bool or a text.

    >>> link_int(3.0, 0, 9, "n")
    3
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise LinkValueError(f"{what} must be a whole number, got {_short(value)}")
    if isinstance(value, float) and not (math.isfinite(value) and value == math.floor(value)):
        raise LinkValueError(f"{what} must be a whole number, got {_short(value)}")
    v = int(value)
    if not lo <= v <= hi:
        raise LinkValueError(f"{what} must be within {lo}..{hi}, got {_short(v)}")
    return v


def check_hole_id(value: Any) -> int:
    """A hole id (an int, as the vehicle writes it) in the protocol's range
    0..:data:`HOLE_ID_MAX`.

    >>> check_hole_id(7)
    7
    >>> try:
    ...     check_hole_id(10**9)
    ... except LinkValueError as err:
    ...     print(err)
    hole id must be within 0..999999999, got 1000000000
    """
    if not isinstance(value, int) or isinstance(value, bool):
        raise LinkValueError(f"hole id must be a whole number, got {_short(value)}")
    return link_int(value, 0, HOLE_ID_MAX, "hole id")


def link_lat_lon(lat: Any, lon: Any) -> tuple[float, float]:
    """(lat_deg, lon_deg) on the Earth: -90..90, -180..180, finite."""
    return link_float(lat, -90.0, 90.0, "latitude"), link_float(lon, -180.0, 180.0, "longitude")


def link_yaw(value: Any) -> float:
    """A heading in radians (ATTITUDE's yaw): finite, within -2 pi..2 pi."""
    return link_float(value, -2 * math.pi, 2 * math.pi, "yaw")


def xml_text(text: Any, max_chars: int | None = None) -> str:
    """``text`` as a str XML 1.0 can hold (see the module docstring), cut to ``max_chars``.

    >>> xml_text("dark\\x0b opening\\x00", 20)
    'dark opening'
    """
    s = text if isinstance(text, str) else str(text)
    s = _NOT_XML.sub("", s)
    return s if max_chars is None else s[:max_chars]


def xml_safe_tree(root: ET.Element) -> ET.Element:
    """Every text, tail, attribute name and value under ``root`` made XML-safe in place
    (:func:`xml_text`); ``root`` returned. For writers built on ElementTree, which writes
    a control character as it is (an ill-formed file)."""
    for el in root.iter():
        if el.text is not None:
            el.text = xml_text(el.text)
        if el.tail is not None:
            el.tail = xml_text(el.tail)
        if el.attrib:
            el.attrib = {xml_text(k): xml_text(v) for k, v in el.attrib.items()}
    return root


@dataclass(frozen=True)
class CardValues:
    """A hole card's facts (:func:`missions.card_facts`), every one checked.

    hole_id, rev : the vehicle's id and the card's revision. lat_deg, lon_deg : WGS84.
    score, p_hole : 0..1 (p_hole None: not told). alt_m : MSL; sigma_h_m, major_m, minor_m :
    metres (None: not told). sightings : count. why : XML-safe text. tier : the vehicle's.
    """

    hole_id: int
    rev: int
    lat_deg: float
    lon_deg: float
    score: float
    alt_m: float | None
    sigma_h_m: float | None
    major_m: float | None
    minor_m: float | None
    sightings: int | None
    why: str | None
    tier: Literal["announced", "review"]
    p_hole: float | None


def card_values(facts: Mapping[str, Any]) -> CardValues:
    """Check a card's facts (:func:`missions.read_card`); raise :class:`LinkValueError`
    for any value missing, of the wrong kind or out of range (the whole card is refused:
    a card is the vehicle's, a half-kept one would mix two stories).

    >>> card_values({"id": 3, "lat": 43.6, "lon": -79.4, "score": 0.9}).hole_id
    3
    >>> try:
    ...     card_values({"id": 3, "lat": 1e308, "lon": -79.4, "score": 0.9})
    ... except LinkValueError as err:
    ...     print(err)
    latitude must be a number within -90..90, got 1e+308
    """
    if not isinstance(facts, Mapping):
        raise LinkValueError("card facts must be a JSON object")
    try:
        hid, lat, lon, score = facts["id"], facts["lat"], facts["lon"], facts["score"]
    except KeyError as err:
        raise LinkValueError(f"card facts lack {err}") from None
    lat_deg, lon_deg = link_lat_lon(lat, lon)
    tier = facts.get("tier", "announced")
    if tier not in ("announced", "review"):
        raise LinkValueError(f"card tier must be announced or review, got {_short(tier)}")
    why = facts.get("why")
    if why is not None and not isinstance(why, str):
        raise LinkValueError("card why must be text")
    n = facts.get("n")
    return CardValues(
        hole_id=check_hole_id(hid),
        rev=link_int(facts.get("rev", 1), 0, INT32_MAX, "card revision"),
        lat_deg=lat_deg,
        lon_deg=lon_deg,
        score=link_float(score, 0.0, 1.0, "score"),
        alt_m=optional_float(facts.get("alt"), *ALT_RANGE_M, "altitude"),
        sigma_h_m=optional_float(facts.get("sigma"), *SIZE_RANGE_M, "sigma"),
        major_m=optional_float(facts.get("major"), *SIZE_RANGE_M, "major axis"),
        minor_m=optional_float(facts.get("minor"), *SIZE_RANGE_M, "minor axis"),
        sightings=None if n is None else link_int(n, 0, INT32_MAX, "sightings"),
        why=None if why is None else xml_text(why, WHY_MAX_CHARS),
        tier=tier,
        p_hole=optional_float(facts.get("p"), 0.0, 1.0, "p_hole"),
    )


def _short(value: Any) -> str:
    """A value for a log line: its repr, at most 40 characters."""
    r = repr(value)
    return r if len(r) <= 40 else r[:37] + "..."
