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
  only partly in view (cut by the image border).

The coefficients are data (:mod:`geotag._confidence_table`), fitted by
``benchmarks/calibrate_confidence.py`` on hole-level truth; pure, no files or clocks.
"""

from __future__ import annotations

import math
import statistics
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


def evidence_of(sightings: Sequence[HoleSighting]) -> HoleEvidence:
    """:class:`HoleEvidence` of one hole's sightings (any order; at least one)."""
    if not sightings:
        raise InputError("a hole's evidence needs at least one sighting")
    ps = [p_hole_of_score(s.score) for s in sightings]
    views: dict[tuple[int, int, int], float] = {}
    for s, p in zip(sightings, ps, strict=True):
        v = viewpoint_of(s)
        views[v] = max(views.get(v, 0.0), p)
    strong = sum(p >= STRONG_P for p in views.values()) / len(views)
    majors = [s.major_m for s in sightings if not s.cut_by_border and s.major_m > 0]
    if len(majors) >= 4:
        q = statistics.quantiles(majors, n=4)
        spread = (q[2] - q[0]) / max(statistics.median(majors), 1e-3)
    else:
        spread = 0.0
    s0 = sightings[0]
    frame = LocalFrame(s0.lat_deg, s0.lon_deg)
    e, n = frame.to_en([s.lat_deg for s in sightings], [s.lon_deg for s in sightings])
    e_mean, n_mean = float(e.mean()), float(n.mean())
    rms = math.sqrt(float(((e - e_mean) ** 2 + (n - n_mean) ** 2).mean()))
    major = max([s.major_m for s in sightings if math.isfinite(s.major_m)] + [0.3])
    rims = [s.rim_seen for s in sightings if math.isfinite(s.rim_seen)]
    times = [s.t_boot_ns for s in sightings]
    return HoleEvidence(
        sightings=len(sightings),
        views=len(views),
        best_p=max(ps),
        median_p=statistics.median(ps),
        strong_fraction=strong,
        size_spread=spread,
        scatter=rms / major,
        rim_seen=max(rims) if rims else 0.5,
        cut_fraction=sum(s.cut_by_border for s in sightings) / len(sightings),
        span_s=(max(times) - min(times)) * 1e-9,
    )


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
