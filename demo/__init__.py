"""``holescan demo``: a whole simulated sortie, flown, served, mapped and scored against the truth.

The demo application, above the device simulators (:mod:`holescan.sim`: world, Xtion,
autopilot, sortie) and the ground station it runs beside the flight:

* :func:`run_demo` with :class:`DemoOptions` (``DEMO_SORTIE`` the built-in sortie), its
  :class:`DemoResult` and :func:`format_result` (the lines ``holescan demo`` prints);
* :class:`DemoMapper` / :func:`views_and_track`: the search map of the flight;
* :func:`score_holes`, :func:`count_in_view`, :func:`frames_in_view`: holes against the
  world's truth (:class:`TruthRow`, :class:`FalseHole`).
"""

from holescan.demo._format import (
    REVIEW_PER_HA_MEASURED,
    format_result,
)
from holescan.demo._map import (
    DemoMap,
    DemoMapper,
    views_and_track,
)
from holescan.demo._run import (
    DEMO_SORTIE,
    DemoOptions,
    DemoProgress,
    DemoResult,
    default_demo_out,
    run_demo,
)
from holescan.demo._scoring import (
    FalseHole,
    TruthRow,
    count_in_view,
    frames_in_view,
    score_holes,
)

__all__ = [
    "DEMO_SORTIE",
    "REVIEW_PER_HA_MEASURED",
    "DemoMap",
    "DemoMapper",
    "DemoOptions",
    "DemoProgress",
    "DemoResult",
    "FalseHole",
    "TruthRow",
    "count_in_view",
    "default_demo_out",
    "format_result",
    "frames_in_view",
    "run_demo",
    "score_holes",
    "views_and_track",
]
