"""Reprocessing flights and campaigns: detect again over whole flight logs on Dask.

:func:`reprocess` (each flight on its own) and :func:`run_campaign` (the flights of an
operation, holes merged across them) share one engine (:mod:`.run`):

* :mod:`.plan` - every log's chunk index, checked before any work; partitions;
* :mod:`.engine`, :mod:`.task`, :mod:`.worker` - the partitions detected on Dask (or in
  this process), results back in task order; :mod:`.cache` keeps finished ones on disk;
* :mod:`.merge` - poses from the logged telemetry and holes merged in log order, as in
  flight; :mod:`.campaign` - holes merged across flights;
* :mod:`.sidecar`, :mod:`.outputs` - the sidecar MCAP, hole files, report, JSON summaries;
* :mod:`.options` - what a run is asked to do and how far it is.
"""

from holescan.ground.reprocessing.campaign import CampaignHole, FlightSightings
from holescan.ground.reprocessing.engine import EngineError, EngineStats
from holescan.ground.reprocessing.options import (
    HoleMatch,
    Progress,
    ReprocessOptions,
    match_points,
)
from holescan.ground.reprocessing.outputs import FlightResult, write_hole_outputs
from holescan.ground.reprocessing.plan import group_flights
from holescan.ground.reprocessing.run import ReprocessResult, reprocess, run_campaign

__all__ = [
    "CampaignHole",
    "EngineError",
    "EngineStats",
    "FlightResult",
    "FlightSightings",
    "HoleMatch",
    "Progress",
    "ReprocessOptions",
    "ReprocessResult",
    "group_flights",
    "match_points",
    "reprocess",
    "run_campaign",
    "write_hole_outputs",
]
