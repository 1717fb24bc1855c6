"""One hole, one id: a second run's holes given the ids the first run gave them.

The vehicle numbers its holes (:class:`geotag.HoleTracker`: 1, 2, ... in order of first
sighting) and the crew knows them by those numbers: on the station, in TAK, in every file.
Reprocessing the flight's log, or merging it into a campaign, runs a tracker again: its own
numbering follows its own order of first sighting (it may merge frames the flight skipped)
and would call the same opening by another number. :func:`carry_ids` gives each hole of
the new run the id of the flight's hole at the same opening, and the holes only the new run
found ids above every id the flight used, so they can never be mistaken for one of its.

Same opening: nearest first (:func:`geotag.nearest_pairs`, each hole used once), within the
tracker's own gate (:class:`geotag.MergeParams`): closer than ``max(min_radius_m,
size_fraction * major axis, n_sigma * hypot(sigma_a, sigma_b))``, and sizes within
``max_size_ratio`` of each other. Pure and deterministic: the same holes give the same ids.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence

from holescan.geotag._local import LocalFrame
from holescan.geotag._matching import nearest_pairs
from holescan.geotag._merge import Hole, MergeParams

__all__ = ["IdMap", "carry_ids", "same_opening_gate_m"]


def _size_ok(a: float, b: float, max_ratio: float) -> bool:
    if not (math.isfinite(a) and math.isfinite(b)) or a <= 0 or b <= 0:
        return True
    return max(a, b) / min(a, b) <= max_ratio


def same_opening_gate_m(a: Hole, b: Hole, params: MergeParams) -> float:
    """How far apart two holes may lie and still be one opening, metres (the tracker's
    gate: see the module docstring).

    Examples
    --------
    >>> h = Hole(1, 43.0, -79.0, 100.0, 0.2, 0.9, 5, 0, 1, 0, (0, 0, 1, 1), 1.2, 0.6)
    >>> round(same_opening_gate_m(h, h, MergeParams()), 3)  # 3 * hypot(0.2, 0.2)
    0.849
    """
    major = max(_finite(a.major_m), _finite(b.major_m))
    sigma = math.hypot(_finite(a.sigma_h_m), _finite(b.sigma_h_m))
    return max(params.min_radius_m, params.size_fraction * major, params.n_sigma * sigma)


def _finite(v: float) -> float:
    return v if math.isfinite(v) else 0.0


@dataclasses.dataclass(frozen=True)
class IdMap:
    """The new run's hole ids -> the ids they carry.

    ids : new-run id -> carried id (every hole of the new run). from_reference : the
    carried ids that are the reference run's (the same opening); the others are new.
    distance_m : carried id -> distance to its reference hole, metres (matched ones only).
    first_new_id : the first id given to a hole only the new run found.
    """

    ids: dict[int, int]
    from_reference: frozenset[int]
    distance_m: dict[int, float]
    first_new_id: int

    @property
    def new_ids(self) -> list[int]:
        """The carried ids of the holes only the new run found, in order."""
        return sorted(i for i in self.ids.values() if i not in self.from_reference)

    def apply(self, holes: Iterable[Hole]) -> list[Hole]:
        """``holes`` of the new run with their carried ids, sorted by id."""
        return sorted(
            (dataclasses.replace(h, id=self.ids[h.id]) for h in holes), key=lambda h: h.id
        )


def carry_ids(
    reference: Sequence[Hole],
    found: Sequence[Hole],
    params: MergeParams | None = None,
    *,
    reference_max_id: int = 0,
) -> IdMap:
    """Give each of ``found`` the id of the ``reference`` hole at the same opening, and the
    others new ids above every reference id (see the module docstring).

    Parameters
    ----------
    reference : the holes whose ids stand (the flight's, as its log records them).
    found : the new run's holes (its own ids, unique).
    params : the tracker's gate (default :class:`MergeParams`).
    reference_max_id : the highest id the reference run ever used (ids it retired when it
        fused two holes are above its surviving ones sometimes); new ids start above both.

    Returns
    -------
    :class:`IdMap`. Holes only ``found`` has get ``first_new_id``, ``first_new_id + 1``, ...
    in the order of their own ids (the new run's order of first sighting).

    Examples
    --------
    >>> def hole(i, lat):
    ...     return Hole(i, lat, -79.0, 100.0, 0.3, 0.9, 5, 0, 1, 0, (0, 0, 1, 1), 1.0, 0.5)
    >>> flight = [hole(9, 43.00000), hole(4, 43.00010)]  # 11 m apart
    >>> again = [hole(1, 43.00010), hole(2, 43.00005), hole(3, 43.000001)]
    >>> m = carry_ids(flight, again, reference_max_id=10)
    >>> m.ids, m.new_ids
    ({1: 4, 2: 11, 3: 9}, [11])
    """
    params = params or MergeParams()
    ref = [h for h in reference if math.isfinite(h.lat_deg) and math.isfinite(h.lon_deg)]
    top = max([reference_max_id, *(h.id for h in reference)])
    pairs: list[tuple[float, int, int]] = []
    if ref and found:
        frame = LocalFrame(ref[0].lat_deg, ref[0].lon_deg)
        fe, fn = frame.to_en([h.lat_deg for h in found], [h.lon_deg for h in found])
        re_, rn = frame.to_en([h.lat_deg for h in ref], [h.lon_deg for h in ref])
        for i, f in enumerate(found):
            for j, r in enumerate(ref):
                if not _size_ok(f.major_m, r.major_m, params.max_size_ratio):
                    continue
                d = math.hypot(float(fe[i] - re_[j]), float(fn[i] - rn[j]))
                if d < same_opening_gate_m(f, r, params):
                    pairs.append((d, i, j))
    paired = nearest_pairs(pairs)
    ids: dict[int, int] = {}
    dist: dict[int, float] = {}
    for i, (j, d) in paired.items():
        ids[found[i].id] = ref[j].id
        dist[ref[j].id] = d
    first_new = top + 1
    nxt = first_new
    for i in sorted(range(len(found)), key=lambda k: found[k].id):
        if i not in paired:
            ids[found[i].id] = nxt
            nxt += 1
    ids = {k: ids[k] for k in sorted(ids)}
    return IdMap(ids, frozenset(dist), dist, first_new)
