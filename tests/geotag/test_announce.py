"""The announce policy: which changed holes are news for the ground, and when again."""

from __future__ import annotations

from dataclasses import replace

from holescan.geotag import AnnounceGate, AnnouncePolicy, Hole, Told

S = 1_000_000_000


def hole(
    hid: int, p_hole: float, north_m: float = 0.0, score: float = 0.8, sigma: float = 0.3
) -> Hole:
    lat = 45.0 + north_m / 111_132.0
    return Hole(hid, lat, 7.0, 100.0, sigma, score, 5, 5 * S, 7 * S, 1, (0, 0, 10, 10), 1.0,
                0.6, p_hole=p_hole)  # fmt: skip


def test_tiers_follow_the_gate() -> None:
    policy = AnnouncePolicy(AnnounceGate())
    holes = [hole(1, 0.95), hole(2, 0.3, north_m=5.0), hole(3, 0.05, north_m=9.0)]
    served, tiers = policy.tiers(holes)
    assert [h.id for h in served] == [1]
    assert tiers == {1: "announced", 2: "review", 3: "candidate"}


def test_news_once_then_again_on_a_move_or_a_rise_only() -> None:
    policy = AnnouncePolicy(AnnounceGate())
    h = hole(1, 0.95)
    _, tiers = policy.tiers([h])
    assert [(n.hole.id, n.tier) for n in policy.tell([h], tiers)] == [(1, "announced")]
    assert policy.announced == {1: Told(h)}
    assert policy.tell([h], tiers) == []  # nothing new
    assert policy.tell([hole(1, 0.95, north_m=0.4)], tiers) == []  # 0.4 m: not news
    assert len(policy.tell([hole(1, 0.95, north_m=0.7)], tiers)) == 1  # 0.7 m from told
    assert policy.tell([hole(1, 0.95, north_m=0.7, score=0.84)], tiers) == []  # +0.04
    assert len(policy.tell([hole(1, 0.95, north_m=0.7, score=0.86)], tiers)) == 1  # +0.06


def test_a_review_hole_that_becomes_announced_is_told_again_a_candidate_never() -> None:
    policy = AnnouncePolicy(AnnounceGate())
    weak, strong, faint = hole(1, 0.3), hole(1, 0.95), hole(2, 0.05, north_m=9.0)
    _, tiers = policy.tiers([weak, faint])
    assert [(n.hole.id, n.tier) for n in policy.tell([weak, faint], tiers)] == [(1, "review")]
    assert set(policy.reviewed) == {1} and not policy.announced
    _, tiers = policy.tiers([strong, faint])
    assert [(n.hole.id, n.tier) for n in policy.tell([strong, faint], tiers)] == [(1, "announced")]
    assert set(policy.announced) == {1}


def test_a_noticeable_sigma_or_p_hole_change_is_news_a_small_one_waits_for_the_end() -> None:
    policy = AnnouncePolicy(AnnounceGate())
    h = hole(1, 0.95, sigma=1.2)
    _, tiers = policy.tiers([h])
    assert len(policy.tell([h], tiers)) == 1
    assert policy.tell([replace(h, sigma_h_m=1.155)], tiers) == []  # 4.5 cm: waits
    assert len(policy.tell([replace(h, sigma_h_m=1.05)], tiers)) == 1  # 15 cm, 12.5 %
    assert policy.announced[1].hole.sigma_h_m == 1.05
    assert policy.tell([replace(h, sigma_h_m=0.96)], tiers) == []  # 9 cm: under 0.1 m
    small = hole(2, 0.95, north_m=9.0, sigma=0.3)
    _, tiers = policy.tiers([h, small])
    assert len(policy.tell([small], tiers)) == 1
    assert policy.tell([replace(small, sigma_h_m=0.25)], tiers) == []  # 17 %, but 5 cm
    assert len(policy.tell([replace(small, sigma_h_m=0.18)], tiers)) == 1  # 12 cm and 40 %
    assert len(policy.tell([replace(small, p_hole=0.999, sigma_h_m=0.18)], tiers)) == 0  # +0.049
    assert len(policy.tell([replace(small, p_hole=0.89, sigma_h_m=0.18)], tiers)) == 1  # -0.06


def test_the_end_tells_every_hole_that_changed_since_it_was_told_once() -> None:
    policy = AnnouncePolicy(AnnounceGate())
    a, b, c = hole(1, 0.95, sigma=1.2), hole(2, 0.3, north_m=5.0), hole(3, 0.05, north_m=9.0)
    _, tiers = policy.tiers([a, b, c])
    assert [n.hole.id for n in policy.tell([a, b, c], tiers)] == [1, 2]
    a_end = replace(a, sigma_h_m=1.155, sightings=9)  # a little better: not told in flight
    assert policy.tell([a_end], tiers) == []
    final = policy.final([a_end, b, c], tiers)  # b unchanged, c a candidate: not told
    assert [(n.hole, n.tier) for n in final] == [(a_end, "announced")]
    assert policy.announced[1] == Told(a_end)
    assert policy.final([a_end, b, c], tiers) == []
