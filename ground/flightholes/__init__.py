"""The holes of a flight log for the ground crew: read once (:mod:`.read`), with their best
views (:mod:`.views`), exported to their files (:mod:`.export`)."""

from holescan.ground.flightholes.export import (
    ExportReport,
    default_out_path,
    export_flight_holes,
)
from holescan.ground.flightholes.read import (
    FlightHoles,
    flight_log_files,
    log_stem,
    read_flight_holes,
)
from holescan.ground.flightholes.views import HoleThumbnail, render_thumbnail

__all__ = [
    "ExportReport",
    "FlightHoles",
    "HoleThumbnail",
    "default_out_path",
    "export_flight_holes",
    "flight_log_files",
    "log_stem",
    "read_flight_holes",
    "render_thumbnail",
]
