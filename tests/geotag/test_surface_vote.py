"""The absorbing-surface vote: a hole whose views read its inside on the rim's plane is held
for review, never announced, never dropped; one that some views see behind the plane is not.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from holescan.detect import PlaneVerdict
from holescan.errors import InputError
from holescan.geotag import AnnounceGate, Hole, HoleSighting, HoleTracker, evidence_of
from tests.geotag.test_one_opening import sighting

PX_STEP = 100  # one sighting per 80 px image cell: each a viewpoint of its own


# What a view read inside (on the plane, behind it) for each verdict (detect.plane_verdict).
READ: dict[PlaneVerdict | None, tuple[float, float]] = {
    "surface": (0.35, 0.02),
    "behind": (0.01, 0.3),
    "unread": (0.0, 0.0),
    "mixed": (0.08, 0.02),
    None: (float("nan"), float("nan")),
}


def with_reading(s: HoleSighting, verdict: PlaneVerdict | None) -> HoleSighting:
    """``s`` with its inside read as ``verdict`` (the fractions on and behind its rim plane)."""
    on, behind = READ[verdict]
    out = replace(s, inside_on_plane=on, inside_behind=behind)
    assert out.plane == verdict
    return out


def _pass(verdicts: list[PlaneVerdict | None], score: float = 0.95) -> list[HoleSighting]:
    """One opening seen from len(verdicts) viewpoints, each reading ``verdicts[i]``."""
    return [
        with_reading(sighting(k, 0.0, score=score, x_px=20 + PX_STEP * k), v)
        for k, v in enumerate(verdicts)
    ]


def merged_hole(sightings: list[HoleSighting]) -> Hole:
    """The one hole ``sightings`` make, each given to a tracker on its own."""
    tracker = HoleTracker()
    for s in sightings:
        tracker.update([s])
    (hole,) = tracker.holes()
    return hole


def test_a_surface_read_on_its_plane_from_most_views_is_held_for_review() -> None:
    gate = AnnounceGate()
    stain = merged_hole(_pass(["surface", "surface", "unread", "surface", None]))
    # four viewpoints measured it (the fifth did not: not counted), three on the plane
    assert (stain.plane_views, stain.surface_views, stain.behind_views) == (4, 3, 0)
    assert stain.p_hole >= gate.min_p_hole and stain.sightings >= gate.min_sightings
    assert gate.surface_held(stain)
    assert not gate.passes(stain)
    assert gate.tier(stain) == "review"  # never announced, never dropped
    assert gate.tiers([stain]) == {stain.id: "review"}
    assert gate.select([stain]) == [] and gate.review([stain]) == [stain]


def test_a_void_seen_behind_its_plane_is_announced() -> None:
    gate = AnnounceGate()
    # a deep hole: mostly unread inside, its walls read behind the plane from one view
    void = merged_hole(_pass(["unread", "behind", "unread", "mixed", "unread"]))
    assert (void.plane_views, void.surface_views, void.behind_views) == (5, 0, 1)
    assert not gate.surface_held(void) and gate.tier(void) == "announced"
    # one view on the plane, two behind it: a void's walls outnumber it, announced
    walls = merged_hole(_pass(["surface", "behind", "behind", "unread", "mixed"]))
    assert (walls.surface_views, walls.behind_views) == (1, 2)
    assert not gate.surface_held(walls) and gate.tier(walls) == "announced"
    # views that read both, or nothing, count neither way
    unclear = merged_hole(_pass(["mixed", "mixed", "unread", "mixed"]))
    assert (unclear.plane_views, unclear.surface_views, unclear.behind_views) == (4, 0, 0)
    assert not gate.surface_held(unclear) and gate.tier(unclear) == "announced"


def test_as_many_views_on_the_plane_as_behind_it_hold_a_hole_for_review() -> None:
    # The vote's second arm (surface_tie_views): no more views read a void's walls than
    # read a surface. Seen on the simulated worlds 76 and 84: stains announced with one view
    # on the plane, at most one behind, the rest mixed.
    gate = AnnounceGate()
    for verdicts in (
        ["surface", "behind", "mixed", "mixed", "mixed"],  # one each: a tie
        ["surface", "mixed", "unread", None],  # one on the plane, none behind
        ["surface", "surface", "behind", "unread", "unread"],  # two on, one behind: not half
    ):
        tie = merged_hole(_pass(verdicts))
        assert tie.surface_views >= max(1, tie.behind_views)
        assert gate.surface_held(tie) and gate.tier(tie) == "review"  # never dropped
        assert AnnounceGate(surface_tie_views=0).tier(tie) == "announced"  # the arm off
    # two views on the plane are needed when the arm asks for two
    one = merged_hole(_pass(["surface", "mixed", "mixed", "mixed", "unread"]))
    assert AnnounceGate(surface_tie_views=2).tier(one) == "announced"
    with pytest.raises(InputError, match="surface_tie_views"):
        AnnounceGate(surface_tie_views=-1)


def test_a_viewpoint_votes_by_the_majority_of_its_sightings() -> None:
    # one viewpoint, three sightings: two on the plane, one behind -> a surface view;
    # one behind and one on the plane -> a behind view (recall first)
    a = [with_reading(sighting(k, 0.0, x_px=300), "surface") for k in range(2)]
    b = with_reading(sighting(2, 0.0, x_px=300), "behind")
    ev = evidence_of([*a, b])
    assert (ev.plane_views, ev.surface_views, ev.behind_views) == (1, 1, 0)
    ev = evidence_of([a[0], b])
    assert (ev.plane_views, ev.surface_views, ev.behind_views) == (1, 0, 1)


def test_the_vote_never_raises_a_weak_hole_and_old_holes_are_untouched() -> None:
    gate = AnnounceGate()
    weak = merged_hole(_pass(["surface"] * 4, score=0.05))
    assert gate.surface_held(weak) and gate.tier(weak) == gate.tier(replace(weak, plane_views=0))
    strong = merged_hole(_pass([None] * 4))  # no plane evidence (older logs, paper mode): as before
    assert strong.plane_views == 0 and gate.tier(strong) == "announced"


def test_holes_fused_later_keep_every_views_verdict() -> None:
    sightings = _pass(["surface", "surface", "unread", "surface"])
    one = merged_hole(sightings)
    two = HoleTracker()
    for s in sightings:
        two.update([s])
    ev = evidence_of(list(two.sightings_of(one.id)))
    assert (ev.plane_views, ev.surface_views, ev.behind_views) == (
        one.plane_views,
        one.surface_views,
        one.behind_views,
    )


def test_the_vote_settings_are_checked() -> None:
    with pytest.raises(InputError, match="surface vote"):
        AnnounceGate(surface_min_views=0)
    with pytest.raises(InputError, match="surface vote"):
        AnnounceGate(surface_min_share=1.5)
    with pytest.raises(InputError, match="surface vote"):
        AnnounceGate(surface_max_behind_ratio=-1.0)
    off = AnnounceGate(surface_min_views=10**9, surface_tie_views=0)
    stain = merged_hole(_pass(["surface"] * 4))
    assert off.tier(stain) == "announced" and AnnounceGate().tier(stain) == "review"
