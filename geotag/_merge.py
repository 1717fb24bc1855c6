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
  frame, assigned greedily by normalised distance (ties: lower hole id, earlier sighting).
  This is what keeps two real holes 1.2 m apart separate when the GPS error is metres.
* Sightings from another GPS source (another flight or vehicle: :meth:`HoleTracker.update`'s
  ``source``) carry an independent GPS error: for them the bias drift is at its cap at
  once, however close in time the flights were.
* A sighting that joins no hole starts a new one. A single false detection therefore
  becomes a hole with ``sightings == 1``: consumers ask :meth:`HoleTracker.confirmed`.

Reported position: inverse-variance weighted mean of all sightings, weighted by their
non-GPS variance (attitude, depth, timing, and where the detector put the opening: an
oblique view or a rim half hidden weighs less); the GPS error, shared by sightings close in
time, cannot tell them apart. Its sigma combines three parts: where the detector put the
opening (the weighted mean of the sightings' ``sigma_opening_m``: views from one side share
their error, it does not average down), the rest of the non-GPS error (averages down as
``1/sqrt(n)``), and the GPS part, which only averages down over independent stretches of
``gps_decorrelation_s``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import pymap3d

from holescan.detect import p_hole_of_score
from holescan.errors import InputError
from holescan.geotag._project import HoleSighting

__all__ = ["AnnounceGate", "Hole", "HoleTracker", "MergeParams"]

_MIN_REL_SIGMA_M = 0.01
_P_HOLE_MAX = 0.99  # detect's p_hole is kept within [0.01, 0.99]


@dataclass(frozen=True)
class MergeParams:
    """When two sightings are the same hole.

    min_radius_m : sightings closer than this (after bias tracking) always may merge.
    n_sigma : gate in standard deviations of the non-GPS error plus GPS drift.
    size_fraction : the gate is at least this fraction of the hole's major axis.
    max_size_ratio : sightings whose major axes differ by more than this factor are
        different holes.
    gps_decorrelation_s : time over which the GPS error becomes independent, seconds.
    """

    min_radius_m: float = 0.5
    n_sigma: float = 3.0
    size_fraction: float = 0.5
    max_size_ratio: float = 3.0
    gps_decorrelation_s: float = 300.0

    def __post_init__(self) -> None:
        if self.min_radius_m < 0 or self.n_sigma <= 0 or self.size_fraction < 0:
            raise InputError("merge radii and n_sigma must be non-negative (n_sigma > 0)")
        if self.max_size_ratio < 1 or self.gps_decorrelation_s <= 0:
            raise InputError("max_size_ratio must be >= 1 and gps_decorrelation_s > 0")


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
        ``score * (1 - off_centre / 2)``: confident and near the image centre).
    major_m, minor_m : opening size seen in the best view, metres.
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


class _Track:
    """Mutable state of one hole (private to the tracker)."""

    def __init__(self, hole_id: int, s: HoleSighting, ned: tuple[float, float, float]) -> None:
        self.id = hole_id
        self.count = 0
        self.w_sum = 0.0
        self.wn = self.we = self.wd = 0.0
        self.inv_noise_var = 0.0
        self.w_opening = 0.0
        self.gps_sum = 0.0
        self.t_first = s.t_boot_ns
        self.t_last = s.t_boot_ns
        self.kn, self.ke = ned[0], ned[1]
        self.p = _rel_var(s)
        self.best = s
        self.best_quality = -math.inf
        self.best_score = -math.inf
        self.source: str | None = None
        self._add(s, ned)

    def _add(self, s: HoleSighting, ned: tuple[float, float, float]) -> None:
        w = 1.0 / _rel_var(s)  # GPS error is shared: it cannot tell sightings apart
        self.count += 1
        self.w_sum += w
        self.wn += w * ned[0]
        self.we += w * ned[1]
        self.wd += w * ned[2]
        self.inv_noise_var += 1.0 / _noise_var(s)
        self.w_opening += w * s.sigma_opening_m
        self.gps_sum += s.sigma_gps_m
        self.t_first = min(self.t_first, s.t_boot_ns)
        self.t_last = max(self.t_last, s.t_boot_ns)
        self.best_score = max(self.best_score, s.score)
        quality = s.score * (1.0 - 0.5 * s.off_centre)
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
        p = self.predicted_var(s, params, source)
        self.source = source
        r = _rel_var(s)
        k = p / (p + r)
        self.kn += k * (ned[0] - self.kn)
        self.ke += k * (ned[1] - self.ke)
        self.p = (1.0 - k) * p
        self._add(s, ned)


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


class HoleTracker:
    """Merges sightings into holes with stable ids (pure, deterministic).

    Feed it every frame's sightings with :meth:`update`, in time order; sightings of one
    call that share ``(t_boot_ns, frame_index)`` count as one frame.
    """

    def __init__(self, params: MergeParams | None = None) -> None:
        self.params = params if params is not None else MergeParams()
        self._tracks: list[_Track] = []
        self._origin: tuple[float, float, float] | None = None

    def _local(self, s: HoleSighting) -> tuple[float, float, float]:
        if self._origin is None:
            self._origin = (s.lat_deg, s.lon_deg, s.alt_m)
        n, e, d = pymap3d.geodetic2ned(s.lat_deg, s.lon_deg, s.alt_m, *self._origin)
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
        return [self._hole(t) for t in self._tracks if t.id in changed]

    def _update_frame(self, group: list[HoleSighting], source: str | None) -> list[int]:
        p = self.params
        local = [self._local(s) for s in group]
        pairs: list[tuple[float, int, int]] = []
        for i, (s, ned) in enumerate(zip(group, local, strict=True)):
            for ti, t in enumerate(self._tracks):
                if not _size_ok(s.major_m, t.best.major_m, p.max_size_ratio):
                    continue
                major = max(s.major_m, t.best.major_m)
                floor = max(p.min_radius_m, p.size_fraction * major if major > 0 else 0.0)
                var = t.predicted_var(s, p, source) + _rel_var(s)
                gate = max(floor, p.n_sigma * math.sqrt(var))
                dist = math.hypot(ned[0] - t.kn, ned[1] - t.ke)
                if dist < gate:
                    pairs.append((dist / gate, ti, i))
        pairs.sort()
        used_tracks: set[int] = set()
        assigned: dict[int, int] = {}
        for _, ti, i in pairs:
            if ti in used_tracks or i in assigned:
                continue
            used_tracks.add(ti)
            assigned[i] = ti
        changed = []
        for i, (s, ned) in enumerate(zip(group, local, strict=True)):
            if i in assigned:
                track = self._tracks[assigned[i]]
                track.update(s, ned, p, source)
            else:
                track = _Track(len(self._tracks) + 1, s, ned)
                track.source = source
                self._tracks.append(track)
            changed.append(track.id)
        return changed

    def _hole(self, t: _Track) -> Hole:
        assert self._origin is not None
        n, e, d = t.wn / t.w_sum, t.we / t.w_sum, t.wd / t.w_sum
        lat, lon, alt = pymap3d.ned2geodetic(n, e, d, *self._origin)
        span_s = (t.t_last - t.t_first) * 1e-9
        independent = min(float(t.count), 1.0 + span_s / self.params.gps_decorrelation_s)
        gps = (t.gps_sum / t.count) / math.sqrt(independent)
        # The opening's error is shared by views from the same side (it does not average
        # down): the weighted mean of the sightings' opening sigmas. The rest (depth noise,
        # attitude, timing) averages down as 1/sqrt(n).
        opening = t.w_opening / t.w_sum
        rel = math.hypot(opening, 1.0 / math.sqrt(t.inv_noise_var))
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
        )

    def holes(self) -> list[Hole]:
        """All holes so far, sorted by id."""
        return [self._hole(t) for t in self._tracks]

    def confirmed(self, min_sightings: int = 2) -> list[Hole]:
        """Holes seen at least ``min_sightings`` times, sorted by id."""
        return [self._hole(t) for t in self._tracks if t.count >= min_sightings]


@dataclass(frozen=True)
class AnnounceGate:
    """When a hole is worth a rescuer's look: announced, served as a waypoint, sent on.

    A hole passes when all three hold:

    min_p_hole : the probability that it is a true access hole, ``p_hole`` of its best
        detector score (:func:`detect.p_hole_of_score`, see :meth:`p_hole`). ``p_hole``
        never leaves [0.01, 0.99], so the threshold must lie in [0, 0.99].
    min_sightings : frames it was seen in (2: the count depends on the detector's frame
        rate, which drops to ~2.5 frames/s on a loaded computer; the time span does not).
    min_span_s : seconds between its first and last sighting. The vehicle moves over the
        hole meanwhile (0.6-1 m/s on a survey), so the views come from different
        positions: a one-view artefact (a glint, a shadow edge) does not repeat.

    min_separation_m, separation_fraction : a passing hole this close to one already
        kept is the same opening seen twice (see :meth:`select`).

    Holes that do not pass stay *candidates*: logged and written to the hole files marked
    as such, never a waypoint.

    The calibration is the **default** detector mode's (Platt scaling fitted on its
    scores). Paper mode's scores are not calibrated (its detections carry ``p_hole =
    None``); the gate still maps them through the same curve, a monotone map, so in paper
    mode ``min_p_hole`` is a raw-score threshold in disguise (0.5 is a paper score of
    0.37), not a probability. One rule for both modes keeps one config key and one meaning
    of "announced" on the ground; paper mode (2.5-3.5 s a frame) is a reference, not a
    flight mode, and falling back to the raw score would silently change what a given
    ``announce_min_p_hole`` lets through.

    The default ``min_p_hole = 0.5`` was measured with the current detector
    (``benchmarks/bench_announce.py``: 8 simulated worlds, 6,000 frames; figures in the
    README, "What is announced"): every true hole seen twice over 0.3 s had p_hole >=
    0.973, every false one (cracks, stains, small holes, a depression) <= 0.112, so any
    threshold from 0.2 to 0.95 delivers the same 23 holes, all true (precision 1.000),
    21 of the 22 true holes in view (the 22nd: one detection at score 0.09 in the whole
    lap), first sighting to delivery median 0.3 s. Through the whole demo path
    (``benchmarks/bench_delivery.py``, the same 8 worlds, 14-21 detected frames/s) 0.5
    announced 20 holes, all true, all 20 true holes in view, median 0.4 s, max 17.6 s. But
    on an idle machine (29 detected frames/s) ``holescan demo`` saw a stain 11 times at
    score 0.43 (p_hole 0.73) and announced it at 0.5: more frames give a weak false box
    more sightings. Hence 0.9: still far below every true hole seen twice (0.973), above
    that stain; on independent single detections it keeps 91 of 101 true ones (0.5: 98),
    and in flight a hole is judged on its best of many views.

    Examples
    --------
    >>> gate = AnnounceGate(min_p_hole=0.5, min_sightings=2, min_span_s=0.3)
    >>> gate.min_p_hole
    0.5
    >>> from detect import p_hole_of_score  # p_hole 0.5 is a best score of 0.368
    >>> p_hole_of_score(0.37) >= gate.min_p_hole > p_hole_of_score(0.36)
    True
    """

    min_p_hole: float = 0.9
    min_sightings: int = 2
    min_span_s: float = 0.3
    min_separation_m: float = 0.5
    separation_fraction: float = 0.5

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_p_hole <= _P_HOLE_MAX:
            raise InputError(
                f"announce min_p_hole must be in [0, {_P_HOLE_MAX}] (p_hole never exceeds "
                f"{_P_HOLE_MAX}), got {self.min_p_hole}"
            )
        if self.min_sightings < 1 or not self.min_span_s >= 0.0:
            raise InputError("announce min_sightings must be >= 1 and min_span_s >= 0")

    def p_hole(self, hole: Hole) -> float:
        """``p_hole`` of ``hole``: of its best detector score."""
        return p_hole_of_score(hole.score)

    def select(self, holes: Sequence[Hole], announced: Iterable[int] = ()) -> list[Hole]:
        """The holes to announce and serve: those that pass, less duplicates.

        A duplicate lies within ``max(min_separation_m, separation_fraction * major
        axis)`` of a hole kept before it: the tracker keeps one sighting per hole per
        frame, so a detector that boxes one opening twice in a frame makes two holes at
        the same place. Holes already ``announced`` are always kept (the ground has them);
        the others in id order. Sorted by id.
        """
        done = set(announced)
        ordered = sorted(
            (h for h in holes if self.passes(h)), key=lambda h: (h.id not in done, h.id)
        )
        kept: list[Hole] = []
        for h in ordered:
            if h.id not in done and any(_duplicate(h, k, self) for k in kept):
                continue
            kept.append(h)
        return sorted(kept, key=lambda h: h.id)

    def passes(self, hole: Hole) -> bool:
        """True when ``hole`` is strong enough to be announced."""
        span_s = (hole.t_last_boot_ns - hole.t_first_boot_ns) * 1e-9
        return (
            self.p_hole(hole) >= self.min_p_hole
            and hole.sightings >= self.min_sightings
            and span_s >= self.min_span_s
        )


def _duplicate(a: Hole, b: Hole, gate: AnnounceGate) -> bool:
    radius = max(gate.min_separation_m, gate.separation_fraction * max(a.major_m, b.major_m))
    n, e, _ = pymap3d.geodetic2ned(a.lat_deg, a.lon_deg, b.alt_m, b.lat_deg, b.lon_deg, b.alt_m)
    return bool(math.hypot(float(n), float(e)) < radius)
