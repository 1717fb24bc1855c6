"""The HOLE STATUSTEXT codec: what the vehicle writes is what the ground reads, tier included;
each number named as what it is (``p`` = the hole-level p_hole), the old form still read."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from holescan.errors import InputError
from holescan.geotag import VEHICLE_TIERS
from holescan.link import HOLE_ID_MAX, STATUSTEXT_MAX, HoleText, hole_text, read_hole_text


@given(
    hole_id=st.integers(0, HOLE_ID_MAX),
    p_hole=st.floats(0.0, 1.0),
    lat=st.floats(-90.0, 90.0),
    lon=st.floats(-180.0, 180.0),
    tier=st.sampled_from(VEHICLE_TIERS),
)
def test_every_hole_text_reads_back_with_its_tier_and_p_hole(
    hole_id: int, p_hole: float, lat: float, lon: float, tier: str
) -> None:
    text = hole_text(hole_id, p_hole, lat, lon, tier)
    assert len(text) <= STATUSTEXT_MAX
    said = read_hole_text(text)
    assert said is not None
    assert (said.hole_id, said.tier, said.score) == (hole_id, tier, None)
    assert said.p_hole == pytest.approx(p_hole, abs=0.0051)  # 2 decimals (0.125 -> "0.12")
    # 7 decimals (1 cm) for every id up to HOLE_ID_MAX (fewer only when they do not fit)
    decimals = len(text.split()[-1].split(".")[1])
    assert decimals == 7
    assert said.lat_deg == pytest.approx(lat, abs=0.51e-7)
    assert said.lon_deg == pytest.approx(lon, abs=0.51e-7)


def test_known_texts_both_ways() -> None:
    assert hole_text(12, 0.99, 43.6532005, -79.3831433) == "HOLE 12 p0.99 43.6532005 -79.3831433"
    assert hole_text(2, 0.68, 45.12347012, 7.65430877, "review") == (
        "REVIEW 2 p0.68 45.1234701 7.6543088"
    )
    said = read_hole_text("REVIEW 4 p0.30 43.6533100 -79.3831200\x00\x00")  # NUL padded field
    assert said == HoleText(4, "review", 43.65331, -79.38312, p_hole=0.3)
    worst = hole_text(HOLE_ID_MAX, 1.0, -89.12345678, -179.12345678, "review")
    assert worst == "REVIEW 999999999 p1.00 -89.1234568 -179.1234568"
    assert len(worst) <= STATUSTEXT_MAX


def test_the_old_form_is_read_as_the_best_frames_score_not_p_hole() -> None:
    """Old vehicles and old logs sent a bare number: the best frame's detector score."""
    said = read_hole_text("HOLE 3 0.88 43.6533100 -79.3831200")
    assert said == HoleText(3, "announced", 43.65331, -79.38312, score=0.88)
    assert said.p_hole is None
    said = read_hole_text("REVIEW 9 0.99 43.6532005 -79.3831433")
    assert said is not None and (said.tier, said.score, said.p_hole) == ("review", 0.99, None)


@pytest.mark.parametrize(
    "text",
    [
        "PreArm: GPS",
        "HOLE 3 p0.88 43.6533100",  # cut short
        "HOLE 3 p1.50 43.6533100 -79.3831200",  # p_hole out of range
        "HOLE 3 1.50 43.6533100 -79.3831200",  # old form: score out of range
        "HOLE 3 p0.88 93.6533100 -79.3831200",  # latitude out of range
        "REVIEW 3 p0.88 43.6533100 -189.3831200",  # longitude out of range
        "CANDIDATE 3 p0.88 43.6533100 -79.3831200",  # a tier that never leaves the vehicle
        "HOLE -3 p0.88 43.6533100 -79.3831200",
        "HOLE 1000000000 p0.88 43.6533100 -79.3831200",  # an id above HOLE_ID_MAX
        "HOLE 3 s0.88 43.6533100 -79.3831200",  # a field named as nothing this codec knows
        "HOLE 3 pp0.88 43.6533100 -79.3831200",
    ],
)
def test_other_or_bad_texts_are_not_holes(text: str) -> None:
    assert read_hole_text(text) is None


def test_a_candidate_a_non_probability_and_an_id_too_long_are_refused() -> None:
    with pytest.raises(InputError, match="announced or review"):
        hole_text(1, 0.5, 0.0, 0.0, "candidate")
    with pytest.raises(InputError, match="p_hole"):
        hole_text(1, float("nan"), 0.0, 0.0)
    with pytest.raises(InputError, match="too long"):
        hole_text(10**40, 0.5, -89.1, -179.1)
