"""The HOLE STATUSTEXT: a hole told in one line every ground station shows, both ways.

``HOLE <id> <score> <lat> <lon>`` for an announced hole, ``REVIEW <id> ...`` for one sent
for review (an operator confirms it), at most 50 characters (STATUSTEXT's text field).
The vehicle's hole server writes it (:func:`hole_text`), the ground station reads it
(:func:`read_hole_text`): one codec, so the tier said is the tier read.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from holescan.errors import InputError
from holescan.geotag import VEHICLE_TIERS, VehicleTier
from holescan.link._values import HOLE_ID_MAX, check_hole_id, link_float, link_lat_lon
from holescan.link.errors import LinkValueError

__all__ = ["STATUSTEXT_MAX", "HoleText", "hole_text", "read_hole_text"]

STATUSTEXT_MAX: Final = 50
"""Characters in STATUSTEXT's text field."""
_TIERS: Final[dict[str, VehicleTier]] = {"HOLE": "announced", "REVIEW": "review"}
_TEXT = re.compile(r"(HOLE|REVIEW) (\d+) ([\d.]+) (-?[\d.]+) (-?[\d.]+)")


@dataclass(frozen=True)
class HoleText:
    """What a HOLE STATUSTEXT says: the hole's id, its tier, score and position (WGS84)."""

    hole_id: int
    tier: VehicleTier
    score: float
    lat_deg: float
    lon_deg: float


def hole_text(
    hole_id: int, score: float, lat_deg: float, lon_deg: float, tier: str = "announced"
) -> str:
    """``HOLE <id> <score> <lat> <lon>`` (``REVIEW ...`` for ``tier="review"``), at most 50
    characters. Seven decimals (1 cm) fit for any id below 10**9; fewer are used only if
    needed.

    >>> hole_text(3, 0.88, 43.65331, -79.38312), hole_text(3, 0.88, 43.65331, -79.38312, "review")
    ('HOLE 3 0.88 43.6533100 -79.3831200', 'REVIEW 3 0.88 43.6533100 -79.3831200')

    Raises :class:`InputError` for a tier that does not reach the ground or an id too long
    for the field.
    """
    if tier not in VEHICLE_TIERS:
        raise InputError(f"a hole sent to the ground is announced or review, not {tier!r}")
    word = "HOLE" if tier == "announced" else "REVIEW"
    for decimals in (7, 6, 5, 4):
        lat, lon = f"{lat_deg:.{decimals}f}", f"{lon_deg:.{decimals}f}"
        text = f"{word} {hole_id} {score:.2f} {lat} {lon}"
        if len(text) <= STATUSTEXT_MAX:
            return text
    raise InputError(f"hole id {hole_id} too long for a STATUSTEXT")


def read_hole_text(text: str) -> HoleText | None:
    """The hole a STATUSTEXT tells of; None for any other text, or values out of range
    (every value checked as the link's values are: an id up to ``HOLE_ID_MAX``, a finite
    score in [0, 1], a position on the Earth).

    >>> read_hole_text("HOLE 3 0.88 43.6533100 -79.3831200")
    HoleText(hole_id=3, tier='announced', score=0.88, lat_deg=43.65331, lon_deg=-79.38312)
    >>> read_hole_text("REVIEW 4 0.30 43.6533100 -79.3831200").tier
    'review'
    >>> read_hole_text("PreArm: GPS") is None
    True
    """
    m = _TEXT.fullmatch(text.strip().rstrip("\x00"))
    if m is None or len(m[2]) > len(str(HOLE_ID_MAX)):
        return None
    try:
        hid = check_hole_id(int(m[2]))
        score = link_float(m[3], 0.0, 1.0, "score")
        lat, lon = link_lat_lon(m[4], m[5])
    except LinkValueError:
        return None
    return HoleText(hid, _TIERS[m[1]], score, lat, lon)
