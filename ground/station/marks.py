"""The operators' marks of a station folder, read for reprocessing and campaigns.

An operator's mark (``confirmed``, ``rejected``, ``visited``; ``new`` is no mark) is kept
by the station in ``DIR/station.json`` under the vehicle's hole id, and who made it in
``DIR/audit.jsonl`` (:mod:`.audit`). Reprocessing gives its holes the flight's ids
(:func:`geotag.carry_ids`), so the marks apply to them as they are: a confirmed or visited
hole is ``confirmed``, a rejected one ``rejected`` (:func:`tier_with_mark`, the rule the
station itself follows). Reading never creates or changes anything in the folder.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from holescan.errors import InputError
from holescan.ground.station.audit import AuditTrail
from holescan.ground.station.state import MARKS, GroundHole

__all__ = ["StationMark", "read_station_marks", "tier_with_mark"]


@dataclass(frozen=True)
class StationMark:
    """An operator's mark of hole ``hole_id``; ``operator`` and ``t_unix_ns`` from the
    audit trail's last entry for it (None: not in the trail, e.g. an older station)."""

    hole_id: int
    mark: str
    operator: str | None = None
    t_unix_ns: int | None = None


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
            out[h.id] = StationMark(h.id, h.mark, who, t)
    return out
