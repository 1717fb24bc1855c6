"""The hole-level confidence: all sightings, views rather than frames."""

from __future__ import annotations

from dataclasses import replace

import pytest

from holescan.detect import p_hole_of_score
from holescan.errors import InputError
from holescan.geotag import (
    DEFAULT_CONFIDENCE,
    ConfidenceModel,
    HoleTracker,
    evidence_of,
    viewpoint_of,
)
from tests.geotag.test_one_opening import sighting


def test_frames_from_one_place_are_one_view_a_pass_is_many() -> None:
    hover = [sighting(k, 0.0, score=0.44, x_px=300) for k in range(240)]  # 240 frames, one place
    moving = [sighting(k, 0.0, score=0.44, x_px=20 + 2 * k) for k in range(240)]  # a pass
    h, m = evidence_of(hover), evidence_of(moving)
    assert (h.sightings, h.views) == (240, 1)
    assert m.views == len({viewpoint_of(s) for s in moving}) >= 6
    once = DEFAULT_CONFIDENCE.p_hole(evidence_of(hover[:1]))
    # a hole seen once keeps its best frame's probability; 239 more frames from the same
    # place add nothing; the same score from many places moves it, the way the fitted table
    # says (a sign of the data: views of a strong sighting, log_views + strong_log_views)
    assert once == pytest.approx(p_hole_of_score(0.44), abs=1e-9)
    assert DEFAULT_CONFIDENCE.p_hole(h) == pytest.approx(once, abs=1e-9)
    c = dict(zip(DEFAULT_CONFIDENCE.features, DEFAULT_CONFIDENCE.coefficients, strict=True))
    views_term = c["log_views"] + c["strong_log_views"]
    assert p_hole_of_score(0.44) >= 0.5 and abs(views_term) > 0.1
    assert (DEFAULT_CONFIDENCE.p_hole(m) - once) * views_term > 0
    assert abs(DEFAULT_CONFIDENCE.p_hole(m) - once) > 0.02


def test_the_tracker_keeps_the_same_evidence_as_a_batch() -> None:
    tracker = HoleTracker()
    for k in range(60):
        tracker.update([sighting(k, 0.02 * (k % 5), score=0.3 + 0.01 * k, x_px=10 * k)])
    (hole,) = tracker.holes()
    ev = evidence_of(tracker.sightings_of(hole.id))
    assert hole.p_hole == pytest.approx(DEFAULT_CONFIDENCE.p_hole(ev), abs=1e-6)
    assert hole.views == ev.views
    shuffled = evidence_of(tracker.sightings_of(hole.id)[::-1])  # any order
    assert shuffled.median_p == ev.median_p and shuffled.size_spread == ev.size_spread


def test_bad_models_and_empty_evidence_are_refused() -> None:
    with pytest.raises(InputError):
        evidence_of([])
    with pytest.raises(InputError):
        ConfidenceModel(("best_logit",), (1.0, 2.0), 0.0)
    with pytest.raises(InputError, match="unknown confidence feature"):
        ConfidenceModel(("nope",), (1.0,), 0.0).p_hole(evidence_of([sighting(0, 0.0)]))
    s = sighting(0, 0.0)
    assert ConfidenceModel(("best_logit",), (1.0,), 50.0).p_hole(evidence_of([s])) == 0.99
    assert replace(s, score=0.0).score == 0.0
