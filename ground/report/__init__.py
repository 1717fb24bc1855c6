"""The offline flight report: one self-contained HTML file (:mod:`.page`), its map
(:mod:`.svgmap`) and the score bands that colour both (:mod:`.bands`)."""

from holescan.ground.report.bands import SCORE_BANDS, ScoreBand, score_band
from holescan.ground.report.page import BestView, render_report, thumbnails, write_report

__all__ = [
    "SCORE_BANDS",
    "BestView",
    "ScoreBand",
    "render_report",
    "score_band",
    "thumbnails",
    "write_report",
]
