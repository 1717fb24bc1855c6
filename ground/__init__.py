"""On the ground: what is done with a flight after it, or beside it at the ground station.

* :func:`reprocess` / :func:`run_campaign` - detect again over whole flight logs (also
  cut-off ones) on Dask, poses from the logged telemetry, holes merged as in flight (and
  across the flights of a campaign); sidecar MCAPs, hole files, reports, summary.json.
* :func:`export_flight_holes` / :func:`read_flight_holes` - the holes of a flight log as
  the ground crew's files (GPX, KML/KMZ with thumbnails, GeoJSON, QGC ``.plan``, WPL).
* :func:`write_report` - a flight's self-contained HTML report.
* :func:`import_csv_dataset` - real frames and a ``file,x,y,w,h`` CSV as a dataset.
* :func:`load_dataset` / :func:`write_dataset` and :func:`evaluate_dataset` - annotated
  RGB-D datasets (COCO layout) and the detector's AP on them.
* :func:`run_ground` / :class:`GroundStation` - ``holescan ground``: the live ground
  station app (holes from the vehicle's MAVLink stream, state file, live page, TAK CoT,
  KML/GeoJSON/GPX always current).
* :func:`read_rgb` / :func:`read_depth` / :func:`read_camera` and :func:`draw_detections` -
  image files and overlays for ``holescan detect``.
"""

from holescan.ground._campaign import CampaignHole, FlightSightings
from holescan.ground._cot import (
    COT_TYPE,
    DEFAULT_COT_URL,
    CotError,
    CotPublisher,
    hole_cot,
    withdraw_cot,
)
from holescan.ground._csvimport import FramePair, find_pairs, import_csv_dataset, read_box_csv
from holescan.ground._datasets import (
    CATEGORY,
    Dataset,
    DatasetImage,
    Sample,
    check_box,
    load_dataset,
    load_image_pair,
    write_dataset,
)
from holescan.ground._evaluation import (
    EvalReport,
    brier_score,
    calibration_outcomes,
    detect_image,
    evaluate_dataset,
    format_table,
    ground_truth,
    plot_pr,
    plot_reliability,
    run_detector,
    write_coco_results,
)
from holescan.ground._flightholes import (
    ExportReport,
    FlightHoles,
    default_out_path,
    export_flight_holes,
    flight_log_files,
    log_stem,
    read_flight_holes,
)
from holescan.ground._flightviews import HoleThumbnail, render_thumbnail
from holescan.ground._images import read_camera, read_depth, read_rgb, write_depth, write_rgb
from holescan.ground._overlay import depth_colour, draw_detections, render_detections, segmentation
from holescan.ground._report import render_report, write_report
from holescan.ground._reportmap import SCORE_BANDS, ScoreBand, score_band
from holescan.ground._reprocess import ReprocessResult, reprocess, run_campaign
from holescan.ground._rpengine import EngineError, EngineStats
from holescan.ground._rpoptions import HoleMatch, Progress, ReprocessOptions, match_points
from holescan.ground._rpoutputs import FlightResult, write_hole_outputs
from holescan.ground._rpplan import group_flights
from holescan.ground._station import GroundOptions, GroundStation, run_ground
from holescan.ground._station_files import hole_summary, hole_waypoint, write_station_files
from holescan.ground._station_link import VehicleLink
from holescan.ground._station_state import (
    MARKS,
    GroundHole,
    StationState,
    TrackPoint,
    atomic_write,
    parse_hole_statustext,
)
from holescan.ground._web import StationWeb, state_document

__all__ = [
    "CATEGORY",
    "COT_TYPE",
    "DEFAULT_COT_URL",
    "MARKS",
    "SCORE_BANDS",
    "CampaignHole",
    "CotError",
    "CotPublisher",
    "Dataset",
    "DatasetImage",
    "EngineError",
    "EngineStats",
    "EvalReport",
    "ExportReport",
    "FlightHoles",
    "FlightResult",
    "FlightSightings",
    "FramePair",
    "GroundHole",
    "GroundOptions",
    "GroundStation",
    "HoleMatch",
    "HoleThumbnail",
    "Progress",
    "ReprocessOptions",
    "ReprocessResult",
    "Sample",
    "ScoreBand",
    "StationState",
    "StationWeb",
    "TrackPoint",
    "VehicleLink",
    "atomic_write",
    "brier_score",
    "calibration_outcomes",
    "check_box",
    "default_out_path",
    "depth_colour",
    "detect_image",
    "draw_detections",
    "evaluate_dataset",
    "export_flight_holes",
    "find_pairs",
    "flight_log_files",
    "format_table",
    "ground_truth",
    "group_flights",
    "hole_cot",
    "hole_summary",
    "hole_waypoint",
    "import_csv_dataset",
    "load_dataset",
    "load_image_pair",
    "log_stem",
    "match_points",
    "parse_hole_statustext",
    "plot_pr",
    "plot_reliability",
    "read_box_csv",
    "read_camera",
    "read_depth",
    "read_flight_holes",
    "read_rgb",
    "render_detections",
    "render_report",
    "render_thumbnail",
    "reprocess",
    "run_campaign",
    "run_detector",
    "run_ground",
    "score_band",
    "segmentation",
    "state_document",
    "withdraw_cot",
    "write_coco_results",
    "write_dataset",
    "write_depth",
    "write_hole_outputs",
    "write_report",
    "write_rgb",
    "write_station_files",
]
