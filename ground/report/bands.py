"""The report's confidence classes of holes: score bands and their colours."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["SCORE_BANDS", "ScoreBand", "score_band"]


@dataclass(frozen=True)
class ScoreBand:
    """A confidence class of holes: scores ``>= min_score`` (down to the next band) get ``rgb``."""

    name: str
    min_score: float
    rgb: tuple[int, int, int]

    @property
    def hex(self) -> str:
        """The colour as CSS ``#rrggbb``."""
        return "#{:02x}{:02x}{:02x}".format(*self.rgb)


SCORE_BANDS: tuple[ScoreBand, ...] = (
    ScoreBand("high", 0.7, (211, 47, 47)),
    ScoreBand("medium", 0.5, (239, 108, 0)),
    ScoreBand("low", -math.inf, (96, 125, 139)),
)
"""Colour classes of the detector score, most confident first."""


def score_band(score: float) -> ScoreBand:
    """The :data:`SCORE_BANDS` entry of a detector score in [0, 1] (NaN counts as low)."""
    for band in SCORE_BANDS:
        if score >= band.min_score:
            return band
    return SCORE_BANDS[-1]
