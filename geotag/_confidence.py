"""A hole's confidence from all of its sightings, not from its best frame.

The probability that a merged hole is a true access hole, ``p_hole``, is a small logistic
model over what the sightings say together (:class:`HoleEvidence`):

* the best frame's calibrated probability (:func:`detect.p_hole_of_score` of the best
  score: what the vehicle used alone before) and the median of all sightings' (a hole
  that scores high once and low in every other view is less sure than its best frame);
* **how many different views** saw it. Views from one place are not independent
  evidence: a stain seen 240 times from a hover is still a stain, so frames are not
  counted. A sighting's *viewpoint* is its box centre's cell in the image (80 px cells)
  and its range (0.3 m bins): for a downward camera at a steady height, where the opening
  appears in the image is where the vehicle stands relative to it. ``views`` is the number
  of distinct viewpoints; a hover gives 1-3 of them whatever its length, a pass over the
  hole 6-10. ``strong_fraction`` is the fraction of those viewpoints in which the hole
  scored p_hole >= 0.5 (it is what the model multiplies with the views);
* size consistency: the spread of the opening's major axis over the views not cut by the
  image border (interquartile range over median);
* position consistency: the RMS scatter of the sightings' positions about their mean
  over the opening's size (the GPS error is shared by sightings close in time, so it does
  not spread them; a detection that wanders over the rubble does);
* whether its rim was seen (the best ``rim_seen`` of its sightings) and how often it was
  only partly in view (cut by the image border);
* what its views read inside an opening without readings, against the rim's plane
  (:attr:`HoleSighting.plane`): how many viewpoints measured it, how many read it *on* the
  plane (an absorbing surface: soot, char, a wet black patch) and how many *behind* it (a
  void's walls and floor). Not a model input: the announce gate's vote
  (:func:`geotag.surface_vote`).

The coefficients are data (:mod:`geotag._confidence_table`), fitted by
``benchmarks/calibrate_confidence.py`` on hole-level truth; pure, no files or clocks.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass

from holescan.detect import p_hole_of_score
from holescan.errors import InputError
from holescan.geotag._confidence_table import COEFFICIENTS, FEATURES, INTERCEPT
from holescan.geotag._local import LocalFrame
from holescan.geotag._project import HoleSighting

__all__ = [
    "DEFAULT_CONFIDENCE",
    "FEATURE_NAMES",
    "ConfidenceModel",
    "EvidenceAccumulator",
    "HoleEvidence",
    "evidence_of",
    "viewpoint_of",
]

P_MIN, P_MAX = 0.01, 0.99  # as detect's p_hole: never certain either way
VIEW_CELL_PX = 80
VIEW_RANGE_BIN_M = 0.3
STRONG_P = 0.5
FEATURE_NAMES = (
    "best_logit",
    "median_logit",
    "median_gap",
    "log_views",
    "strong_log_views",
    "size_spread",
    "scatter",
    "rim_seen",
    "cut_fraction",
)


def _logit(p: float) -> float:
    p = min(max(p, P_MIN), P_MAX)
    return math.log(p / (1.0 - p))


@dataclass(frozen=True)
class HoleEvidence:
    """What a hole's sightings say together (the model's inputs).

    sightings : frames it was seen in. views : distinct viewpoints (:func:`viewpoint_of`).
    best_p, median_p : best and median of the sightings' ``p_hole_of_score(score)``.
    strong_fraction : fraction of the viewpoints with a sighting of p_hole >= 0.5.
    size_spread : interquartile range / median of the major axis over the sightings not
        cut by the image border (0 with fewer than 4 of them).
    scatter : RMS distance of the sightings from their mean position / the major axis
        (at least 0.3 m).
    rim_seen : the best fraction of the rim seen (0.5 when never measured).
    cut_fraction : fraction of the sightings whose box the image border cut.
    span_s : seconds between first and last sighting.
    plane_views, surface_views, behind_views : viewpoints whose sightings measured the
        inside against the rim plane, and of those the ones that read it on the plane
        (most of their sightings ``surface``) and behind it (half or more ``behind``).
    whole_strong : sightings that saw the opening whole (not cut by the image border) and
        scored p_hole >= 0.5.
    """

    sightings: int
    views: int
    best_p: float
    median_p: float
    strong_fraction: float
    size_spread: float
    scatter: float
    rim_seen: float
    cut_fraction: float
    span_s: float
    plane_views: int = 0
    surface_views: int = 0
    behind_views: int = 0
    whole_strong: int = 0

    def features(self, names: Sequence[str] = FEATURES) -> tuple[float, ...]:
        """The model's inputs ``names`` (see :data:`FEATURE_NAMES`), in that order."""
        values = {
            "best_logit": _logit(self.best_p),
            "median_logit": _logit(self.median_p),
            "median_gap": _logit(self.median_p) - _logit(self.best_p),
            "log_views": math.log(max(self.views, 1)),
            "strong_log_views": self.strong_fraction * math.log(max(self.views, 1)),
            "size_spread": min(self.size_spread, 2.0),
            "scatter": min(self.scatter, 2.0),
            "rim_seen": self.rim_seen,
            "cut_fraction": self.cut_fraction,
        }
        try:
            return tuple(values[name] for name in names)
        except KeyError as err:
            raise InputError(f"unknown confidence feature {err}: one of {FEATURE_NAMES}") from err


def viewpoint_of(s: HoleSighting) -> tuple[int, int, int]:
    """A sighting's viewpoint: its box centre's 80 px image cell and its 0.3 m range bin.

    Examples
    --------
    >>> from holescan.detect import FeatureScores
    >>> f = FeatureScores(1, 1, 1, 1, 1)
    >>> s = HoleSighting(0, 0, 0, 1, 0.5, 1, 0.6, 0, 0, (300, 200, 40, 40), f, range_m=3.0)
    >>> viewpoint_of(s)
    (4, 2, 10)
    """
    x, y, w, h = s.box
    r = s.range_m if math.isfinite(s.range_m) else 0.0
    return (int((x + w / 2) // VIEW_CELL_PX), int((y + h / 2) // VIEW_CELL_PX), int(r // 0.3))


def _median(xs: list[float]) -> float:
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def _quartiles(xs: list[float]) -> tuple[float, float]:
    """First and third quartiles of sorted ``xs`` (len >= 2), as ``statistics.quantiles(xs,
    n=4)`` (its default, exclusive method)."""
    m = len(xs) + 1
    out = []
    for i in (1, 3):
        j, delta = divmod(i * m, 4)
        j = min(max(j, 1), len(xs) - 1)
        out.append((xs[j - 1] * (4 - delta) + xs[j] * delta) / 4)
    return out[0], out[1]


class EvidenceAccumulator:
    """:class:`HoleEvidence` kept up to date one sighting at a time (the tracker's; each
    :meth:`add` is O(log n) but for a list insertion, :meth:`evidence` O(1)).

    ``north_m, east_m`` of each sighting may be in any local frame (the same for all).
    """

    def __init__(self) -> None:
        self.n = 0
        self._ps: list[float] = []
        self._views: dict[tuple[int, int, int], float] = {}
        self._majors: list[float] = []
        self._sum = [0.0, 0.0, 0.0, 0.0]  # north, east, north^2, east^2
        self._major_max = 0.3
        self._rim: float | None = None
        self._cut = 0
        self._whole_strong = 0
        self._t = (0, 0)
        # viewpoint -> sightings measured against the rim plane, read surface, read behind
        self._planes: dict[tuple[int, int, int], tuple[int, int, int]] = {}

    def add(self, s: HoleSighting, north_m: float, east_m: float) -> None:
        p = p_hole_of_score(s.score)
        bisect.insort(self._ps, p)
        v = viewpoint_of(s)
        self._views[v] = max(self._views.get(v, 0.0), p)
        if s.plane is not None:
            n, su, be = self._planes.get(v, (0, 0, 0))
            self._planes[v] = (n + 1, su + (s.plane == "surface"), be + (s.plane == "behind"))
        if not s.cut_by_border and s.major_m > 0:
            bisect.insort(self._majors, s.major_m)
        if math.isfinite(s.major_m):
            self._major_max = max(self._major_max, s.major_m)
        if math.isfinite(s.rim_seen):
            self._rim = s.rim_seen if self._rim is None else max(self._rim, s.rim_seen)
        self._cut += bool(s.cut_by_border)
        self._whole_strong += not s.cut_by_border and p >= STRONG_P
        t = s.t_boot_ns
        self._t = (t, t) if self.n == 0 else (min(self._t[0], t), max(self._t[1], t))
        acc = self._sum
        acc[0] += north_m
        acc[1] += east_m
        acc[2] += north_m * north_m
        acc[3] += east_m * east_m
        self.n += 1

    def merge(self, other: EvidenceAccumulator) -> None:
        """Take in another's sightings (two holes found to be one opening)."""
        for p in other._ps:
            bisect.insort(self._ps, p)
        for v, p in other._views.items():
            self._views[v] = max(self._views.get(v, 0.0), p)
        for v, (n, su, be) in other._planes.items():
            n0, su0, be0 = self._planes.get(v, (0, 0, 0))
            self._planes[v] = (n0 + n, su0 + su, be0 + be)
        for m in other._majors:
            bisect.insort(self._majors, m)
        self._major_max = max(self._major_max, other._major_max)
        if other._rim is not None:
            self._rim = other._rim if self._rim is None else max(self._rim, other._rim)
        self._cut += other._cut
        self._whole_strong += other._whole_strong
        if other.n:
            self._t = (
                other._t
                if not self.n
                else (
                    min(self._t[0], other._t[0]),
                    max(self._t[1], other._t[1]),
                )
            )
        self._sum = [a + b for a, b in zip(self._sum, other._sum, strict=True)]
        self.n += other.n

    def evidence(self) -> HoleEvidence:
        if not self.n:
            raise InputError("a hole's evidence needs at least one sighting")
        n = self.n
        strong = sum(p >= STRONG_P for p in self._views.values()) / len(self._views)
        if len(self._majors) >= 4:
            q1, q3 = _quartiles(self._majors)
            spread = (q3 - q1) / max(_median(self._majors), 1e-3)
        else:
            spread = 0.0
        sn, se, snn, see = self._sum
        var = max(snn / n - (sn / n) ** 2, 0.0) + max(see / n - (se / n) ** 2, 0.0)
        return HoleEvidence(
            sightings=n,
            views=len(self._views),
            best_p=self._ps[-1],
            median_p=_median(self._ps),
            strong_fraction=strong,
            size_spread=spread,
            scatter=math.sqrt(var) / self._major_max,
            rim_seen=self._rim if self._rim is not None else 0.5,
            cut_fraction=self._cut / n,
            span_s=(self._t[1] - self._t[0]) * 1e-9,
            plane_views=len(self._planes),
            surface_views=sum(2 * su > m for m, su, _ in self._planes.values()),
            behind_views=sum(2 * be >= m for m, _, be in self._planes.values()),
            whole_strong=self._whole_strong,
        )


def evidence_of(sightings: Sequence[HoleSighting]) -> HoleEvidence:
    """:class:`HoleEvidence` of one hole's sightings (any order; at least one)."""
    if not sightings:
        raise InputError("a hole's evidence needs at least one sighting")
    s0 = sightings[0]
    frame = LocalFrame(s0.lat_deg, s0.lon_deg)
    e, n = frame.to_en([s.lat_deg for s in sightings], [s.lon_deg for s in sightings])
    acc = EvidenceAccumulator()
    for s, ee, nn in zip(sightings, e.tolist(), n.tolist(), strict=True):
        acc.add(s, nn, ee)
    return acc.evidence()


@dataclass(frozen=True)
class ConfidenceModel:
    """``p_hole = 1 / (1 + exp(-(intercept + coefficients . features)))``, kept within
    [0.01, 0.99]. ``features`` names the inputs (:meth:`HoleEvidence.features`)."""

    features: tuple[str, ...]
    coefficients: tuple[float, ...]
    intercept: float

    def __post_init__(self) -> None:
        if len(self.features) != len(self.coefficients):
            raise InputError("a confidence model needs one coefficient per feature")

    def p_hole(self, evidence: HoleEvidence) -> float:
        """The probability that the hole is a true access hole."""
        x = evidence.features(self.features)
        z = self.intercept + sum(c * v for c, v in zip(self.coefficients, x, strict=True))
        p = 1.0 / (1.0 + math.exp(-max(min(z, 50.0), -50.0)))
        return min(max(p, P_MIN), P_MAX)


#: The fitted model (:mod:`geotag._confidence_table`).
DEFAULT_CONFIDENCE = ConfidenceModel(FEATURES, COEFFICIENTS, INTERCEPT)
