"""Merge sightings of the same hole across frames into numbered holes.

A UAV sees each hole in many frames. :class:`HoleTracker` turns the stream of
:class:`HoleSighting` into :class:`Hole` records with ids a ground crew can use ("hole 3"):
ids start at 1 in order of first sighting and never change or get reused.

How sightings are matched (deterministic; no clocks, no randomness):

* GPS error is most of a sighting's ``sigma_h_m`` but it is *shared* by sightings close in
  time (a slowly wandering bias), so it cannot tell holes apart nor split one hole. Each
  hole keeps a local position estimate that follows that bias (a 2-D random-walk Kalman
  filter: process noise ``sigma_gps**2 / gps_decorrelation_s`` per second, capped at
  ``2 * sigma_gps**2``; measurement noise = the sighting's non-GPS variance from attitude,
  depth, timing and the opening's centre).
* A sighting may join a hole when its horizontal distance to that estimate is below
  ``max(floor, n_sigma * sqrt(P + R))`` with ``floor = max(min_radius_m, size_fraction *
  major axis)`` (a big hole's detected centre wanders with the view), and the two major
  axes differ by less than ``max_size_ratio``.
* Sightings of one frame are different holes: each hole takes at most one sighting per
  frame, assigned greedily by the sighting's negative log-likelihood under each hole's
  2-D Gaussian (standard deviation ``gate / n_sigma``; ties: lower hole id, earlier
  sighting): with equal gates that is the normalised distance, and a hole with a tight gate
  that fits wins over one with a loose gate (another flight's, gated on an independent GPS
  error of metres) that is farther in metres but nearer in gate widths. This is what keeps
  two real holes 1.2 m apart separate when the GPS error is metres.
* Sightings from another GPS source (another flight or vehicle: :meth:`HoleTracker.update`'s
  ``source``) carry an independent GPS error: for them the bias drift is at its cap at
  once, however close in time the flights were. The first whole, confident view from the
  new source (score >= ``reframe_min_score``) moves the hole's estimate into that
  source's frame; a view cut by the image border (its centre the visible part's) or a weak
  one (as often a distractor beside the opening as the opening) joins the hole without
  moving it.
* **One opening, one hole**, however the detector boxes it. Sightings of one frame whose
  openings overlap (centres closer than half the sum of their major axes: in one frame
  the GPS error is shared, so their separation is exact to centimetres) are parts of one
  opening, split by the detector (parts up to 0.1 m apart) or boxed twice: the frame's
  view of it is the part not cut by the image border with the best score, and the hole
  takes that one. A view cut by
  the image border shows part of the opening: its size is not compared with the hole's.
  Two holes whose openings come to overlap (their estimates closer than half the sum of
  their major axes), that were never seen apart in one frame and whose estimates were last
  updated from the same GPS source (two estimates each in its own flight's GPS frame cannot
  be compared) are one opening: the younger is fused into the older, whose id stays; the
  younger id is retired (never reused; :meth:`HoleTracker.merged` maps it to the
  survivor).
* A sighting that joins no hole starts a new one. A single false detection therefore
  becomes a hole with ``sightings == 1``: consumers ask :meth:`HoleTracker.confirmed`.

Each hole's confidence ``p_hole`` comes from all its sightings (:mod:`geotag._confidence`:
best and median score, distinct viewpoints rather than frames, size and position
consistency, rim seen).

Reported position: the views that saw the whole opening and the views cut by the image
border are each averaged on their own, weighted by their non-GPS variance (attitude, depth,
timing, and where the detector put the opening: an oblique view or a rim half hidden weighs
less); the GPS error, shared by sightings close in time, cannot tell them apart. The two
means are then combined by their variances, in which the opening's part (the weighted mean
of the sightings' ``sigma_opening_m``) does not average down: views cut on one side share
their error, a centre pulled towards the part in view. Twenty cut views therefore weigh as
one cut view, not as twenty (averaged together with the whole views they once carried a
hole 0.15 m off its opening on a loaded machine that had detected few whole views). The
sigma combines that non-GPS part with the GPS part, which only averages down over
independent stretches of ``gps_decorrelation_s``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from holescan.errors import InputError
from holescan.geotag._confidence import (
    DEFAULT_CONFIDENCE,
    ConfidenceModel,
    EvidenceAccumulator,
    HoleEvidence,
)
from holescan.geotag._local import LocalFrame
from holescan.geotag._project import HoleSighting

__all__ = ["Hole", "HoleTracker", "MergeParams"]

_MIN_REL_SIGMA_M = 0.01


@dataclass(frozen=True)
class MergeParams:
    """When two sightings are the same hole.

    min_radius_m : sightings closer than this (after bias tracking) always may merge.
    n_sigma : gate in standard deviations of the non-GPS error plus GPS drift.
    size_fraction : the gate is at least this fraction of the hole's major axis.
    max_size_ratio : sightings whose major axes differ by more than this factor are
        different holes.
    gps_decorrelation_s : time over which the GPS error becomes independent, seconds.
    reframe_min_score : the least detector score of a view from another GPS source that
        moves a hole's estimate into that source's frame (weaker ones join without moving
        it: a campaign once let a 0.11 distractor beside an opening carry the opening's
        hole 1.4 m off, and that flight's views of the opening went to the next hole).
    """

    min_radius_m: float = 0.5
    n_sigma: float = 3.0
    size_fraction: float = 0.5
    max_size_ratio: float = 3.0
    gps_decorrelation_s: float = 300.0
    reframe_min_score: float = 0.3

    def __post_init__(self) -> None:
        if self.min_radius_m < 0 or self.n_sigma <= 0 or self.size_fraction < 0:
            raise InputError("merge radii and n_sigma must be non-negative (n_sigma > 0)")
        if self.max_size_ratio < 1 or self.gps_decorrelation_s <= 0:
            raise InputError("max_size_ratio must be >= 1 and gps_decorrelation_s > 0")
        if not 0.0 <= self.reframe_min_score <= 1.0:
            raise InputError("reframe_min_score must be within [0, 1]")


@dataclass(frozen=True)
class Hole:
    """One access hole, fused from all its sightings.

    id : stable number from 1 in order of first sighting.
    lat_deg, lon_deg : WGS84; alt_m : metres above mean sea level (fused).
    sigma_h_m : horizontal uncertainty of the fused position, metres: the radius that holds
        about 68 % of its errors (``CIRCLE_95_PER_SIGMA`` times it holds 95 %).
    score : best detector score of any sighting.
    sightings : number of sightings merged (require >= N to drop one-off false alarms).
    t_first_boot_ns, t_last_boot_ns : autopilot boot time of the first and last sighting.
    best_frame_index, best_box : frame and box of the best view (highest
        ``score * (1 - off_centre / 2)``: confident and near the image centre; a view cut
        by the image border only when there is no other).
    major_m, minor_m : opening size seen in the best view, metres.
    p_hole : probability that it is a true access hole, from all its sightings
        (:class:`geotag.ConfidenceModel`); NaN for holes read from logs written before.
    views : distinct viewpoints it was seen from (:func:`geotag.viewpoint_of`; 0: unknown).
    plane_views, surface_views, behind_views : viewpoints that measured its inside against
        its rim's plane, and of those the ones that read it on the plane (an absorbing
        surface) and behind it (a void); 0 for holes read from logs written before
        (:func:`geotag.surface_vote`).
    seen_whole : some sighting saw the opening whole (its box not cut by the image border)
        and scored p_hole >= 0.5; False when it was only seen cut, or weakly whole (True for
        holes read from logs written before: never held for it).
    """

    id: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    sigma_h_m: float
    score: float
    sightings: int
    t_first_boot_ns: int
    t_last_boot_ns: int
    best_frame_index: int | None
    best_box: tuple[int, int, int, int]
    major_m: float
    minor_m: float
    p_hole: float = math.nan
    views: int = 0
    plane_views: int = 0
    surface_views: int = 0
    behind_views: int = 0
    seen_whole: bool = True


class _Track:
    """Mutable state of one hole (private to the tracker)."""

    def __init__(self, hole_id: int, s: HoleSighting, ned: tuple[float, float, float]) -> None:
        self.id = hole_id
        self.count = 0
        self.whole = _Mean()  # the views that saw the whole opening
        self.cut = _Mean()  # the views cut by the image border
        self.gps_sum = 0.0
        self.t_first = s.t_boot_ns
        self.t_last = s.t_boot_ns
        self.kn, self.ke = ned[0], ned[1]
        self.p = _rel_var(s)
        self.best = s
        self.best_quality = -math.inf
        self.best_score = -math.inf
        self.source: str | None = None
        self.seen: list[HoleSighting] = []
        self.acc = EvidenceAccumulator()
        self.apart: set[int] = set()  # holes seen apart from this one in one frame
        self._add(s, ned)

    def evidence(self) -> HoleEvidence:
        """What its sightings say together (kept up to date as they come)."""
        return self.acc.evidence()

    def _add(self, s: HoleSighting, ned: tuple[float, float, float]) -> None:
        self.acc.add(s, ned[0], ned[1])
        self.seen.append(s)
        self.count += 1
        (self.cut if s.cut_by_border else self.whole).add(s, ned)
        self.gps_sum += s.sigma_gps_m
        self.t_first = min(self.t_first, s.t_boot_ns)
        self.t_last = max(self.t_last, s.t_boot_ns)
        self.best_score = max(self.best_score, s.score)
        quality = s.score * (1.0 - 0.5 * s.off_centre) - (1.0 if s.cut_by_border else 0.0)
        if quality > self.best_quality:
            self.best_quality = quality
            self.best = s

    def predicted_var(
        self, s: HoleSighting, params: MergeParams, source: str | None = None
    ) -> float:
        dt_s = abs(s.t_boot_ns - self.t_last) * 1e-9
        gps_var = s.sigma_gps_m**2
        drift = min(gps_var * dt_s / params.gps_decorrelation_s, 2.0 * gps_var)
        if source != self.source:  # another receiver's bias: independent of this one's
            drift = 2.0 * gps_var
        return self.p + drift

    def update(
        self,
        s: HoleSighting,
        ned: tuple[float, float, float],
        params: MergeParams,
        source: str | None = None,
    ) -> None:
        if source != self.source and (s.cut_by_border or s.score < params.reframe_min_score):
            # Another source's view cut by the image border (its centre the visible part's,
            # off the opening's by up to half of it) or weak (as likely a distractor beside
            # the opening). It counts as a sighting but does not carry the estimate into
            # that source's GPS frame (with the independent GPS error the gain is ~1: the
            # estimate would land on this view's centre, and the source's next whole views
            # of the opening would no longer match it).
            self._add(s, ned)
            return
        p = self.predicted_var(s, params, source)
        self.source = source
        r = _rel_var(s)
        k = p / (p + r)
        self.kn += k * (ned[0] - self.kn)
        self.ke += k * (ned[1] - self.ke)
        self.p = (1.0 - k) * p
        self._add(s, ned)

    def absorb(self, o: _Track) -> None:
        """Fuse the younger track ``o`` (the same opening) into this one."""
        p = 1.0 / (1.0 / self.p + 1.0 / o.p)
        self.kn = p * (self.kn / self.p + o.kn / o.p)
        self.ke = p * (self.ke / self.p + o.ke / o.p)
        self.p = p
        self.count += o.count
        self.whole.merge(o.whole)
        self.cut.merge(o.cut)
        self.gps_sum += o.gps_sum
        self.t_first, self.t_last = min(self.t_first, o.t_first), max(self.t_last, o.t_last)
        self.best_score = max(self.best_score, o.best_score)
        if o.best_quality > self.best_quality:
            self.best_quality, self.best = o.best_quality, o.best
        self.seen = sorted(self.seen + o.seen, key=lambda s: s.t_boot_ns)
        self.acc.merge(o.acc)
        self.apart |= o.apart


class _Mean:
    """The weighted mean of one kind of a hole's views, and its non-GPS variance."""

    def __init__(self) -> None:
        self.w_sum = 0.0
        self.wn = self.we = self.wd = 0.0
        self.inv_noise_var = 0.0
        self.w_opening = 0.0

    def add(self, s: HoleSighting, ned: tuple[float, float, float]) -> None:
        w = 1.0 / _rel_var(s)  # GPS error is shared: it cannot tell sightings apart
        self.w_sum += w
        self.wn += w * ned[0]
        self.we += w * ned[1]
        self.wd += w * ned[2]
        self.inv_noise_var += 1.0 / _noise_var(s)
        self.w_opening += w * s.sigma_opening_m

    def merge(self, o: _Mean) -> None:
        self.w_sum += o.w_sum
        self.wn, self.we, self.wd = self.wn + o.wn, self.we + o.we, self.wd + o.wd
        self.inv_noise_var += o.inv_noise_var
        self.w_opening += o.w_opening

    def ned(self) -> tuple[float, float, float]:
        return self.wn / self.w_sum, self.we / self.w_sum, self.wd / self.w_sum

    def var(self) -> float:
        """Where the detector put the opening (shared by these views: it does not average
        down) and the rest (depth noise, attitude, timing: averages down as ``1/n``)."""
        opening = self.w_opening / self.w_sum
        return opening**2 + 1.0 / self.inv_noise_var


def _estimate(parts: Sequence[_Mean]) -> tuple[tuple[float, float, float], float]:
    """The means of ``parts`` (those with views) combined by their variances, and the
    variance of the result: the least of theirs, not less (a whole view and a view cut by
    the border seen from one side share part of their error: counted as independent, the
    merged holes of 35 one-side passes lay within their sigma 63 % of the time, 33 % of
    those 1.6 m beside the track; as the least, 69 % and 56 %)."""
    used = [(m.ned(), m.var()) for m in parts if m.w_sum > 0]
    inv = sum(1.0 / v for _, v in used)
    ned = tuple(sum(p[i] / v for p, v in used) / inv for i in range(3))
    return (ned[0], ned[1], ned[2]), min(v for _, v in used)


def _rel_var(s: HoleSighting) -> float:
    """Variance of the sighting's non-GPS error (attitude, depth, timing, opening), m^2."""
    return max(s.sigma_h_m**2 - s.sigma_gps_m**2, _MIN_REL_SIGMA_M**2)


def _noise_var(s: HoleSighting) -> float:
    """The part of :func:`_rel_var` that is not the opening's (depth, attitude, timing)."""
    return max(_rel_var(s) - s.sigma_opening_m**2, _MIN_REL_SIGMA_M**2)


def _size_ok(a: float, b: float, max_ratio: float) -> bool:
    if not (math.isfinite(a) and math.isfinite(b)) or a <= 0 or b <= 0:
        return True
    return max(a, b) / min(a, b) <= max_ratio


def _major(s: HoleSighting) -> float:
    return s.major_m if math.isfinite(s.major_m) and s.major_m > 0 else 0.0


def _overlap_m(a: float, b: float) -> float:
    """Centres of two openings of major axes ``a`` and ``b`` closer than this overlap."""
    return 0.5 * (a + b)


_PART_GAP_M = 0.1  # parts of one opening split by the detector: the rubble between them


def _parts(group: list[HoleSighting], local: list[tuple[float, float, float]]) -> list[int]:
    """Indices of the sightings that stand for their opening in this frame: of each set
    whose openings overlap (parts of one opening), the one not cut by the border with the
    best score (ties: the earlier)."""
    n = len(group)
    root = list(range(n))

    def find(i: int) -> int:
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            d = math.hypot(local[i][0] - local[j][0], local[i][1] - local[j][1])
            if d < _overlap_m(_major(group[i]), _major(group[j])) + _PART_GAP_M:
                root[find(j)] = find(i)
    best: dict[int, int] = {}
    for i in range(n):
        r = find(i)
        s, k = group[i], best.get(r)
        if k is None or (not s.cut_by_border, s.score) > (
            not group[k].cut_by_border,
            group[k].score,
        ):
            best[r] = i
    return sorted(best.values())


class HoleTracker:
    """Merges sightings into holes with stable ids (pure, deterministic).

    Feed it every frame's sightings with :meth:`update`, in time order; sightings of one
    call that share ``(t_boot_ns, frame_index)`` count as one frame.
    """

    def __init__(
        self, params: MergeParams | None = None, confidence: ConfidenceModel | None = None
    ) -> None:
        self.params = params if params is not None else MergeParams()
        self.confidence = confidence if confidence is not None else DEFAULT_CONFIDENCE
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._merged: dict[int, int] = {}
        self._origin: LocalFrame | None = None

    def _local(self, s: HoleSighting) -> tuple[float, float, float]:
        if self._origin is None:
            self._origin = LocalFrame(s.lat_deg, s.lon_deg, s.alt_m)
        n, e, d = self._origin.to_ned(s.lat_deg, s.lon_deg, s.alt_m)
        return (float(n), float(e), float(d))

    def update(self, sightings: Sequence[HoleSighting], source: str | None = None) -> list[Hole]:
        """Merge new sightings; return the holes they created or changed, sorted by id.

        ``source`` names where the sightings' positions come from (a flight, a vehicle):
        a hole last seen from another source is matched with that source's GPS error taken
        as independent of its own (one flight's tracker leaves it None).
        """
        frames: dict[tuple[int, int | None], list[HoleSighting]] = {}
        for s in sightings:
            if not (math.isfinite(s.lat_deg) and math.isfinite(s.lon_deg)):
                raise InputError(f"sighting has no finite position: {s!r}")
            frames.setdefault((s.t_boot_ns, s.frame_index), []).append(s)
        changed: set[int] = set()
        for key in sorted(frames, key=lambda k: k[0]):
            changed.update(self._update_frame(frames[key], source))
        changed = {self._merged.get(i, i) for i in changed}
        return [self._hole(t) for t in self._tracks if t.id in changed]

    def sightings_of(self, hole_id: int) -> tuple[HoleSighting, ...]:
        """The sightings merged into hole ``hole_id`` (a retired id: its survivor's)."""
        hole_id = self._merged.get(hole_id, hole_id)
        for t in self._tracks:
            if t.id == hole_id:
                return tuple(t.seen)
        raise InputError(f"no hole {hole_id}")

    def merged(self) -> dict[int, int]:
        """Retired id -> the id of the hole it was fused into (the same opening)."""
        return dict(self._merged)

    def _update_frame(self, all_of_frame: list[HoleSighting], source: str | None) -> list[int]:
        p = self.params
        local_all = [self._local(s) for s in all_of_frame]
        keep = _parts(all_of_frame, local_all)
        group = [all_of_frame[i] for i in keep]
        local = [local_all[i] for i in keep]
        pairs: list[tuple[float, int, int]] = []
        for i, (s, ned) in enumerate(zip(group, local, strict=True)):
            for ti, t in enumerate(self._tracks):
                cut = s.cut_by_border or t.best.cut_by_border
                if not cut and not _size_ok(s.major_m, t.best.major_m, p.max_size_ratio):
                    continue
                major = max(s.major_m, t.best.major_m)
                floor = max(p.min_radius_m, p.size_fraction * major if major > 0 else 0.0)
                var = t.predicted_var(s, p, source) + _rel_var(s)
                gate = max(floor, p.n_sigma * math.sqrt(var))
                dist = math.hypot(ned[0] - t.kn, ned[1] - t.ke)
                if dist < gate:
                    # The sighting's negative log-likelihood under the hole's 2-D Gaussian
                    # (sigma = gate / n_sigma): a tight hole that fits beats a loose one
                    # (another flight's, gated on its independent GPS error) that fits
                    # "relatively" better; holes with equal gates rank by distance / gate.
                    sigma = gate / p.n_sigma
                    pairs.append((0.5 * (dist / sigma) ** 2 + 2.0 * math.log(sigma), ti, i))
        pairs.sort()
        used_tracks: set[int] = set()
        assigned: dict[int, int] = {}
        for _, ti, i in pairs:
            if ti in used_tracks or i in assigned:
                continue
            used_tracks.add(ti)
            assigned[i] = ti
        fed: list[_Track] = []
        for i, (s, ned) in enumerate(zip(group, local, strict=True)):
            if i in assigned:
                track = self._tracks[assigned[i]]
                track.update(s, ned, p, source)
            else:
                track = _Track(self._next_id, s, ned)
                self._next_id += 1
                track.source = source
                self._tracks.append(track)
            fed.append(track)
        for t in fed:  # seen apart in one frame: two openings, never fused
            t.apart.update(o.id for o in fed if o is not t)
        changed = [t.id for t in fed]
        for t in fed:
            self._fuse(t)
        return changed

    def _fuse(self, t: _Track) -> None:
        """Fuse ``t`` with every other hole whose opening overlaps its own (see the module
        docstring); the older id survives. Only holes last seen from the same source: each
        estimate follows its last source's GPS bias (another flight's or vehicle's first
        sighting moves it into that source's frame), and two estimates in two frames cannot
        be compared by their openings' overlap (two openings 2 m apart were once fused)."""
        while True:
            other = next(
                (
                    o
                    for o in self._tracks
                    if o is not t
                    and o.source == t.source
                    and o.id not in t.apart
                    and t.id not in o.apart
                    and (
                        o.best.cut_by_border
                        or t.best.cut_by_border
                        or _size_ok(o.best.major_m, t.best.major_m, self.params.max_size_ratio)
                    )
                    and math.hypot(o.kn - t.kn, o.ke - t.ke)
                    < _overlap_m(_major(o.best), _major(t.best))
                ),
                None,
            )
            if other is None:
                return
            old, young = (t, other) if t.id < other.id else (other, t)
            old.absorb(young)
            self._tracks.remove(young)
            self._merged[young.id] = old.id
            for k, v in self._merged.items():
                if v == young.id:
                    self._merged[k] = old.id
            for o in self._tracks:
                if young.id in o.apart:
                    o.apart.add(old.id)
            t = old

    def _hole(self, t: _Track) -> Hole:
        assert self._origin is not None
        (n, e, d), rel_var = _estimate((t.whole, t.cut))
        lat, lon, alt = self._origin.ned_to_geodetic(n, e, d)
        span_s = (t.t_last - t.t_first) * 1e-9
        independent = min(float(t.count), 1.0 + span_s / self.params.gps_decorrelation_s)
        gps = (t.gps_sum / t.count) / math.sqrt(independent)
        ev = t.evidence()
        rel = math.sqrt(rel_var)
        return Hole(
            id=t.id,
            lat_deg=float(lat),
            lon_deg=float(lon),
            alt_m=float(alt),
            sigma_h_m=math.hypot(rel, gps),
            score=t.best_score,
            sightings=t.count,
            t_first_boot_ns=t.t_first,
            t_last_boot_ns=t.t_last,
            best_frame_index=t.best.frame_index,
            best_box=t.best.box,
            major_m=t.best.major_m,
            minor_m=t.best.minor_m,
            p_hole=self.confidence.p_hole(ev),
            views=ev.views,
            plane_views=ev.plane_views,
            surface_views=ev.surface_views,
            behind_views=ev.behind_views,
            seen_whole=ev.whole_strong > 0,
        )

    def holes(self) -> list[Hole]:
        """All holes so far, sorted by id."""
        return [self._hole(t) for t in self._tracks]

    def confirmed(self, min_sightings: int = 2) -> list[Hole]:
        """Holes seen at least ``min_sightings`` times, sorted by id."""
        return [self._hole(t) for t in self._tracks if t.count >= min_sightings]
