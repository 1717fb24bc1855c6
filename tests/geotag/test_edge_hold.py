"""A hole unread inside that no view saw whole (only cut by the image border) is held for
review, never announced, until a view sees it whole or its walls are read behind the rim
plane from two viewpoints; holes with a read floor and holes from older logs never are.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from holescan.detect import PlaneVerdict
from holescan.errors import InputError
from holescan.geotag import AnnounceGate, HoleSighting
from tests.geotag.test_one_opening import sighting
from tests.geotag.test_surface_vote import PX_STEP, merged_hole, with_reading


def _views(
    verdicts: list[PlaneVerdict | None], *, cut: bool = True, score: float = 0.95
) -> list[HoleSighting]:
    """One opening seen from len(verdicts) viewpoints, cut by the border (``cut``)."""
    return [
        with_reading(sighting(k, 0.0, score=score, cut=cut, x_px=20 + PX_STEP * k), v)
        for k, v in enumerate(verdicts)
    ]


def test_an_unread_opening_seen_only_cut_by_the_border_is_for_review() -> None:
    gate = AnnounceGate()
    # an absorbing stain at the frame's edge: unread inside, too little read for the vote
    edge = merged_hole(_views(["unread", "unread", "mixed", "unread"]))
    assert not edge.seen_whole and edge.plane_views == 4 and not gate.surface_held(edge)
    assert edge.p_hole >= gate.min_p_hole and edge.sightings >= gate.min_sightings
    assert gate.edge_held(edge) and gate.tier(edge) == "review"  # never dropped
    assert gate.tier(replace(edge, seen_whole=True)) == "announced"  # held for that alone
    assert gate.select([edge]) == [] and gate.review([edge]) == [edge]
    # one view that reads behind the plane is not enough (a rim fitted to a cut piece)
    assert gate.tier(merged_hole(_views(["behind", "unread", "unread", "unread"]))) == "review"


def test_a_whole_view_or_walls_behind_the_plane_announce_it() -> None:
    gate = AnnounceGate()
    cut = _views(["unread", "unread", "mixed", "unread"])
    # the vehicle moves on and a view sees the opening whole, with a hole's score
    whole = _views(["unread"], cut=False)[0]
    later = merged_hole([*cut, replace(whole, frame_index=9, t_boot_ns=whole.t_boot_ns + 10**9)])
    assert later.seen_whole and gate.tier(later) == "announced"
    # a weak whole view is not one: the opening seen whole did not look like a hole
    weak = _views(["unread"], cut=False, score=0.1)[0]
    assert not merged_hole([*cut, weak]).seen_whole
    # two viewpoints read walls behind the rim plane: a void, announced though cut
    walls = merged_hole(_views(["behind", "unread", "behind", "unread"]))
    assert walls.behind_views == 2 and gate.tier(walls) == "announced"


def test_a_read_floor_or_an_older_log_is_never_held() -> None:
    gate = AnnounceGate()
    floor = merged_hole(_views([None] * 4))  # a basin with a read floor: not measured
    assert not floor.seen_whole and floor.plane_views == 0
    assert not gate.edge_held(floor) and gate.tier(floor) == "announced"
    old = replace(merged_hole(_views(["unread"] * 4)), seen_whole=True)  # the field's default
    assert gate.tier(old) == "announced"
    assert (
        AnnounceGate(edge_behind_views=0).tier(merged_hole(_views(["unread"] * 4))) == "announced"
    )
    with pytest.raises(InputError, match="edge_behind_views"):
        AnnounceGate(edge_behind_views=-1)
