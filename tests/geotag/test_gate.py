"""The announce gate: what is worth a rescuer's look."""

from __future__ import annotations

import math

import pytest

from holescan.detect import p_hole_of_score
from holescan.errors import InputError
from holescan.geotag import AnnounceGate, Hole

S = 1_000_000_000


def hole(hid: int, score: float, n: int, span_s: float, north_m: float = 0.0) -> Hole:
    lat = 45.0 + north_m / 111_132.0
    return Hole(hid, lat, 7.0, 100.0, 0.3, score, n, 5 * S, 5 * S + round(span_s * S), 1,
                (0, 0, 10, 10), 1.0, 0.6)  # fmt: skip


def test_each_condition_is_needed() -> None:
    gate = AnnounceGate(min_p_hole=0.5, min_sightings=3, min_span_s=0.3)
    assert gate.passes(hole(1, 0.37, 3, 0.3))  # p_hole 0.507
    assert not gate.passes(hole(1, 0.36, 30, 5.0))  # p_hole 0.467: seen often, a candidate
    assert not gate.passes(hole(1, 0.95, 2, 5.0))
    assert not gate.passes(hole(1, 0.95, 10, 0.2))  # ten frames of one instant


def test_select_drops_a_second_hole_at_the_same_place_keeps_neighbours() -> None:
    gate = AnnounceGate()
    holes = [
        hole(1, 0.85, 8, 2.0),
        hole(2, 0.2, 8, 2.0, north_m=3.0),  # weak: candidate
        hole(3, 0.83, 10, 2.0, north_m=0.2),  # the same opening boxed twice
        hole(4, 0.80, 5, 1.0, north_m=1.2),  # a real neighbour 1.2 m away
    ]
    assert [h.id for h in gate.select(holes)] == [1, 4]
    # already announced holes stay, whatever came later
    assert [h.id for h in gate.select(holes, announced={3})] == [3, 4]
    assert [h.id for h in gate.select(holes, announced={1, 3})] == [1, 3, 4]


def test_the_threshold_is_the_detectors_calibrated_probability() -> None:
    gate = AnnounceGate(min_p_hole=0.9, min_sightings=1, min_span_s=0.0)
    for score in (0.0, 0.2, 0.36, 0.37, 0.5, 0.55, 0.6, 1.0):
        h = hole(1, score, 1, 0.0)
        assert gate.p_hole(h) == p_hole_of_score(score)
        assert gate.passes(h) == (p_hole_of_score(score) >= 0.9)
    # p_hole is kept within [0.01, 0.99]: the highest threshold still lets the best through
    assert AnnounceGate(min_p_hole=0.99).passes(hole(1, 1.0, 5, 1.0))
    assert AnnounceGate(min_p_hole=0.0).passes(hole(1, 0.0, 5, 1.0))


@pytest.mark.parametrize(
    "kw",
    [
        {"min_p_hole": 1.0},  # never reached: p_hole <= 0.99
        {"min_p_hole": -0.1},
        {"min_p_hole": math.nan},
        {"min_sightings": 0},
        {"min_span_s": -1.0},
    ],
)
def test_bad_settings_are_input_errors(kw: dict[str, float]) -> None:
    with pytest.raises(InputError):
        AnnounceGate(**kw)  # type: ignore[arg-type]


def test_tiers_announced_review_candidate_from_the_hole_level_p_hole() -> None:
    import dataclasses

    gate = AnnounceGate(min_p_hole=0.9, review_min_p_hole=0.1)
    # the case: seen in 240 frames from one hover, p_hole 0.76: for review, not lost
    hover = dataclasses.replace(hole(1, 0.44, 240, 20.0, north_m=10.0), p_hole=0.76)
    assert gate.tier(hover) == "review"
    assert gate.tier(dataclasses.replace(hover, p_hole=0.95)) == "announced"
    # the hole-level p_hole decides, not the best frame: a high score alone is not enough
    assert gate.tier(dataclasses.replace(hole(2, 0.9, 5, 1.0), p_hole=0.3)) == "review"
    assert gate.tier(dataclasses.replace(hole(3, 0.05, 6, 1.0), p_hole=0.02)) == "candidate"
    # strong but seen once: for review until seen again from elsewhere
    assert gate.tier(dataclasses.replace(hole(4, 0.9, 1, 0.0), p_hole=0.99)) == "review"
    # a log from before p_hole: its best frame's
    assert gate.p_hole(hole(5, 0.9, 5, 1.0)) == p_hole_of_score(0.9)
    # for review: not at the place of an announced hole
    strong = dataclasses.replace(hole(6, 0.9, 5, 1.0), p_hole=0.97)
    twin = dataclasses.replace(hole(7, 0.3, 3, 1.0, north_m=0.1), p_hole=0.4)
    apart = dataclasses.replace(hole(8, 0.3, 3, 1.0, north_m=3.0), p_hole=0.4)
    assert [h.id for h in gate.review([strong, twin, apart, hover])] == [1, 8]
    with pytest.raises(InputError):
        AnnounceGate(review_min_p_hole=1.0)
