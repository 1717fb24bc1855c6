"""Pairing nearest first: the one rule for matching points (holes to truth, mission items to
holes, a flight's holes to another's)."""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["nearest_pairs"]


def nearest_pairs(candidates: Iterable[tuple[float, int, int]]) -> dict[int, tuple[int, float]]:
    """Pair left items with right items, nearest pairs first, each item used at most once.

    Parameters
    ----------
    candidates : (distance, left index, right index) of every pair allowed to match (the
        caller applies its own distance or containment test first).

    Returns
    -------
    left index -> (right index, distance) for every left item that was paired.

    Examples
    --------
    >>> nearest_pairs([(0.4, 0, 0), (0.1, 1, 0), (0.3, 0, 1)])
    {1: (0, 0.1), 0: (1, 0.3)}
    """
    paired: dict[int, tuple[int, float]] = {}
    used: set[int] = set()
    for d, left, right in sorted(candidates):
        if left not in paired and right not in used:
            paired[left] = (right, d)
            used.add(right)
    return paired
