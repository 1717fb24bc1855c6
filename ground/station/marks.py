"""The operators' marks of a station folder, read for reprocessing and campaigns.

An operator's mark (``confirmed``, ``rejected``, ``visited``; ``new`` is no mark) is kept
by the station in ``DIR/station.json`` under the vehicle's hole id, and who made it in
``DIR/audit.jsonl`` (:mod:`.audit`). Reprocessing gives its holes the flight's ids
(:func:`geotag.carry_ids`), so the marks apply to them as they are: a confirmed or visited
hole is ``confirmed``, a rejected one ``rejected`` (:func:`tier_with_mark`, the rule the
station itself follows). Reading never creates or changes anything in the folder.

A vehicle numbers each flight's holes from 1, so a hole id alone does not say which
flight a mark belongs to when several flights are reprocessed or merged into a campaign
(or one station followed several flights). A mark therefore also keeps where the station
had the hole, and applies to a flight's hole only when **the id is the same and the
flight's own hole (its log's last ``/holes`` record) is within** ``MARK_MATCH_M`` of it
(:func:`marks_for_flight`). In a campaign a hole takes the marks of every flight that saw
it (through each flight's id, ``flights[].hole_id``); marks that disagree give the most
affirmative one, visited over confirmed over rejected (:func:`strongest_mark`: recall
first, a hole an operator confirmed is never dropped because another flight's operator
rejected it).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from holescan.errors import InputError
from holescan.geotag import Hole, local_en_m
from holescan.ground.station.audit import AuditTrail
from holescan.ground.station.records import MARKS, GroundHole

__all__ = [
    "MARK_MATCH_M",
    "StationMark",
    "marks_for_flight",
    "read_station_marks",
    "strongest_mark",
    "tier_with_mark",
]

MARK_MATCH_M = 1.0
"""How far a flight's hole may lie from where the station had it, metres, for the
station's mark of that id to apply to it. The station holds the position the vehicle last
told, which the vehicle re-tells after a 0.5 m move and once more at the end
(:class:`geotag.AnnouncePolicy`); 1 m leaves room for a link lost before the end and
stays below the spacing of distinct openings a second flight might number alike."""

_AFFIRMATIVE = {"visited": 3, "confirmed": 2, "rejected": 1}


@dataclass(frozen=True)
class StationMark:
    """An operator's mark of hole ``hole_id``; ``operator`` and ``t_unix_ns`` from the
    audit trail's last entry for it (None: not in the trail, e.g. an older station);
    ``lat_deg``, ``lon_deg``: where the station had the hole (None: not known, the id
    alone decides); ``station``: the folder it was read from."""

    hole_id: int
    mark: str
    operator: str | None = None
    t_unix_ns: int | None = None
    lat_deg: float | None = None
    lon_deg: float | None = None
    station: str = ""


def strongest_mark(marks: Iterable[str]) -> str | None:
    """The most affirmative of ``marks`` (visited > confirmed > rejected; None: no mark).

    >>> strongest_mark(["rejected", "confirmed"]), strongest_mark([])
    ('confirmed', None)
    """
    known = [m for m in marks if m in _AFFIRMATIVE]
    return max(known, key=_AFFIRMATIVE.__getitem__) if known else None


def marks_for_flight(
    marks: Iterable[StationMark], flight_holes: Sequence[Hole], match_m: float = MARK_MATCH_M
) -> dict[int, str]:
    """Hole id -> mark for one flight: each mark whose id is one of ``flight_holes``' (the
    flight's own holes, the vehicle's ids and positions) and whose station position lies
    within ``match_m`` of it (a mark without a position: the id alone); several marks of
    one hole give :func:`strongest_mark`.

    >>> h = Hole(3, 43.6532, -79.3832, 100.0, 0.3, 0.8, 4, 0, 10**9, 1, (0, 0, 9, 9), 1.0, 0.6)
    >>> here = StationMark(3, "confirmed", lat_deg=43.6532, lon_deg=-79.38321)
    >>> far = StationMark(3, "rejected", lat_deg=43.6535, lon_deg=-79.3832)  # 33 m away
    >>> marks_for_flight([here, far], [h])  # the rejected one is another flight's hole 3
    {3: 'confirmed'}
    """
    by_id = {h.id: h for h in flight_holes}
    got: dict[int, list[str]] = {}
    for m in marks:
        h = by_id.get(m.hole_id)
        if h is None:
            continue
        if m.lat_deg is not None and m.lon_deg is not None:
            east, north = local_en_m(m.lat_deg, m.lon_deg, h.lat_deg, h.lon_deg)
            if not math.hypot(east, north) <= match_m:
                continue
        got.setdefault(m.hole_id, []).append(m.mark)
    return {hid: mark for hid, ms in got.items() if (mark := strongest_mark(ms)) is not None}


def tier_with_mark(tier: str, mark: str | None) -> str:
    """The tier a hole has for the crews once an operator marked it: ``rejected`` ->
    rejected; ``confirmed`` and ``visited`` -> confirmed; otherwise ``tier``.

    >>> tier_with_mark("review", "confirmed"), tier_with_mark("announced", "rejected")
    ('confirmed', 'rejected')
    >>> tier_with_mark("candidate", None)
    'candidate'
    """
    if mark == "rejected":
        return "rejected"
    if mark in ("confirmed", "visited"):
        return "confirmed"
    return tier


def read_station_marks(folder: Path) -> dict[int, StationMark]:
    """Hole id -> the operator's mark, for every marked hole of the station in ``folder``.

    Raises
    ------
    InputError : no ``station.json`` in ``folder``, or one that is not a station's.
    """
    path = Path(folder) / "station.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        holes = [GroundHole.from_json(d) for d in doc["holes"]]
    except FileNotFoundError as err:
        raise InputError(f"{folder} is not a ground station folder (no station.json)") from err
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise InputError(f"{path} is not a holescan ground station file ({err})") from err
    last: dict[int, tuple[str, int]] = {}
    for e in AuditTrail(Path(folder)).read():
        hid, who, t = e.get("hole"), e.get("operator"), e.get("t_unix_ns")
        if isinstance(hid, int) and isinstance(who, str) and isinstance(t, int):
            last[hid] = (who, t)
    out = {}
    for h in holes:
        if h.mark in MARKS and h.mark != "new":
            who, t = last.get(h.id, (None, None))
            out[h.id] = StationMark(h.id, h.mark, who, t, h.lat_deg, h.lon_deg, str(folder))
    return out
