"""The HOLE STATUSTEXT: a hole told in one line every ground station shows, both ways.

``HOLE <id> p<p_hole> <lat> <lon>`` for an announced hole, ``REVIEW <id> ...`` for one sent
for review (an operator confirms it), at most 50 characters (STATUSTEXT's text field):

- ``<id>``: the vehicle's hole id, the same on the station, in TAK and in every file;
- ``p<p_hole>``: the hole-level probability that it is a real access hole (from all its
  sightings; what the tiers are decided on), two decimals, named by its ``p``;
- ``<lat> <lon>``: WGS84 degrees of the fused position, latitude first (7 decimals: 1 cm;
  fewer only when a long id needs the room).

Example: ``HOLE 12 p0.99 43.6532005 -79.3831433``. The vehicle's hole server writes it
(:func:`hole_text`), the ground station reads it (:func:`read_hole_text`): one codec, so
the tier and numbers said are the ones read.

Vehicles before this form sent ``HOLE <id> <score> <lat> <lon>`` with a bare number: the
best frame's *detector score*, not p_hole (a hole could say 0.99 there while its picture's
why-line said p_hole 0.68). :func:`read_hole_text` still reads that form (old logs, old
vehicles) and says which number it carried: :attr:`HoleText.score` set, :attr:`HoleText.p_hole`
None.
"""

from __future__ import annotations

import math
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
# "p0.99": the hole-level p_hole (this form); a bare "0.99": the old form's detector score
_TEXT = re.compile(r"(HOLE|REVIEW) (\d+) (p?)([\d.]+) (-?[\d.]+) (-?[\d.]+)")


@dataclass(frozen=True)
class HoleText:
    """What a HOLE STATUSTEXT says: the hole's id, its tier and position (WGS84), and its
    confidence: ``p_hole`` (the hole-level probability, this form) or, from a vehicle
    that sent the old form, ``score`` (the best frame's detector score). Exactly one of
    the two is set."""

    hole_id: int
    tier: VehicleTier
    lat_deg: float
    lon_deg: float
    p_hole: float | None = None
    score: float | None = None


def hole_text(
    hole_id: int, p_hole: float, lat_deg: float, lon_deg: float, tier: str = "announced"
) -> str:
    """``HOLE <id> p<p_hole> <lat> <lon>`` (``REVIEW ...`` for ``tier="review"``), at most
    50 characters. Seven decimals (1 cm) fit for any id up to ``HOLE_ID_MAX``; fewer are
    used only if needed.

    >>> hole_text(12, 0.99, 43.6532005, -79.3831433)
    'HOLE 12 p0.99 43.6532005 -79.3831433'
    >>> hole_text(3, 0.68, 43.65331, -79.38312, "review")
    'REVIEW 3 p0.68 43.6533100 -79.3831200'

    Raises :class:`InputError` for a tier that does not reach the ground, a p_hole that is
    not a probability or an id too long for the field.
    """
    if tier not in VEHICLE_TIERS:
        raise InputError(f"a hole sent to the ground is announced or review, not {tier!r}")
    if not (math.isfinite(p_hole) and 0.0 <= p_hole <= 1.0):
        raise InputError(f"p_hole must be a probability in 0..1, got {p_hole!r}")
    word = "HOLE" if tier == "announced" else "REVIEW"
    for decimals in (7, 6, 5, 4):
        lat, lon = f"{lat_deg:.{decimals}f}", f"{lon_deg:.{decimals}f}"
        text = f"{word} {hole_id} p{p_hole:.2f} {lat} {lon}"
        if len(text) <= STATUSTEXT_MAX:
            return text
    raise InputError(f"hole id {hole_id} too long for a STATUSTEXT")


def read_hole_text(text: str) -> HoleText | None:
    """The hole a STATUSTEXT tells of; None for any other text, or values out of range
    (every value checked as the link's values are: an id up to ``HOLE_ID_MAX``, a finite
    p_hole or score in [0, 1], a position on the Earth). Reads this form and the old one
    (module docstring).

    >>> said = read_hole_text("HOLE 12 p0.99 43.6532005 -79.3831433")
    >>> said.hole_id, said.tier, said.p_hole, said.score, said.lat_deg, said.lon_deg
    (12, 'announced', 0.99, None, 43.6532005, -79.3831433)
    >>> said = read_hole_text("REVIEW 4 0.30 43.6533100 -79.3831200")  # the old form: a score
    >>> said.tier, said.p_hole, said.score
    ('review', None, 0.3)
    >>> read_hole_text("PreArm: GPS") is None
    True
    """
    m = _TEXT.fullmatch(text.strip().rstrip("\x00"))
    if m is None or len(m[2]) > len(str(HOLE_ID_MAX)):
        return None
    named_p = m[3] == "p"
    try:
        hid = check_hole_id(int(m[2]))
        value = link_float(m[4], 0.0, 1.0, "p_hole" if named_p else "score")
        lat, lon = link_lat_lon(m[5], m[6])
    except LinkValueError:
        return None
    if named_p:
        return HoleText(hid, _TIERS[m[1]], lat, lon, p_hole=value)
    return HoleText(hid, _TIERS[m[1]], lat, lon, score=value)
