"""The HOLE STATUSTEXT codec: what the vehicle writes is what the ground reads, tier included."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from holescan.errors import InputError
from holescan.geotag import VEHICLE_TIERS
from holescan.link import HOLE_ID_MAX, STATUSTEXT_MAX, HoleText, hole_text, read_hole_text


@given(
    hole_id=st.integers(0, HOLE_ID_MAX),
    score=st.floats(0.0, 1.0),
    lat=st.floats(-90.0, 90.0),
    lon=st.floats(-180.0, 180.0),
    tier=st.sampled_from(VEHICLE_TIERS),
)
def test_every_hole_text_reads_back_with_its_tier(
    hole_id: int, score: float, lat: float, lon: float, tier: str
) -> None:
    text = hole_text(hole_id, score, lat, lon, tier)
    assert len(text) <= STATUSTEXT_MAX
    said = read_hole_text(text)
    assert said is not None
    assert (said.hole_id, said.tier) == (hole_id, tier)
    assert said.score == pytest.approx(score, abs=0.005)
    # 7 decimals (1 cm) for every id up to HOLE_ID_MAX (fewer only when they do not fit)
    decimals = len(text.split()[-1].split(".")[1])
    assert said.lat_deg == pytest.approx(lat, abs=0.51 * 10**-decimals)
    assert said.lon_deg == pytest.approx(lon, abs=0.51 * 10**-decimals)


def test_known_texts_both_ways() -> None:
    assert hole_text(2, 0.91, 45.12347012, 7.65430877) == "HOLE 2 0.91 45.1234701 7.6543088"
    said = read_hole_text("REVIEW 4 0.30 43.6533100 -79.3831200\x00\x00")  # NUL padded field
    assert said == HoleText(4, "review", 0.3, 43.65331, -79.38312)


@pytest.mark.parametrize(
    "text",
    [
        "PreArm: GPS",
        "HOLE 3 0.88 43.6533100",  # cut short
        "HOLE 3 1.50 43.6533100 -79.3831200",  # score out of range
        "HOLE 3 0.88 93.6533100 -79.3831200",  # latitude out of range
        "REVIEW 3 0.88 43.6533100 -189.3831200",  # longitude out of range
        "CANDIDATE 3 0.88 43.6533100 -79.3831200",  # a tier that never leaves the vehicle
        "HOLE -3 0.88 43.6533100 -79.3831200",
        "HOLE 1000000000 0.88 43.6533100 -79.3831200",  # an id above HOLE_ID_MAX
    ],
)
def test_other_or_bad_texts_are_not_holes(text: str) -> None:
    assert read_hole_text(text) is None


def test_a_candidate_is_never_written_and_an_id_too_long_is_refused() -> None:
    with pytest.raises(InputError, match="announced or review"):
        hole_text(1, 0.5, 0.0, 0.0, "candidate")
    with pytest.raises(InputError, match="too long"):
        hole_text(10**40, 0.5, -89.1, -179.1)
