"""``holescan holes FLIGHT.mcap --format gpx|kml|kmz|geojson|plan|wpl|all [--out FILE]``."""

from __future__ import annotations

import argparse
from pathlib import Path

from holescan.missions import HOLE_FORMATS

_CHOICES = (*HOLE_FORMATS, "all")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "holes",
        help="export the holes of a logged flight as GPX, KML/KMZ, GeoJSON, .plan, WPL",
        description="Read the final hole list of a flight log (and each hole's best view, "
        "for KML/KMZ thumbnails) and write the files ground crews use. A log cut off by a "
        "crash is read up to its last complete chunk.",
    )
    p.add_argument(
        "logs",
        type=Path,
        nargs="+",
        help="the flight log: one file, its rotated parts in order, or PREFIX_0000.mcap "
        "(the parts that follow are read too)",
    )
    p.add_argument(
        "-f",
        "--format",
        dest="formats",
        action="append",
        choices=_CHOICES,
        metavar="FORMAT",
        help=f"output format, repeatable: {', '.join(_CHOICES)} (default: gpx). wpl = QGC "
        "WPL 110 (.waypoints); kmz = KML with the thumbnails as image files",
    )
    p.add_argument(
        "-o",
        "--out",
        type=Path,
        help="output file (one format), or a name whose extension is set per format, or a "
        "directory (default: PREFIX_holes.EXT next to the log)",
    )
    p.add_argument(
        "--min-sightings",
        type=int,
        default=2,
        metavar="N",
        help="export holes seen in at least N frames (default 2)",
    )
    p.add_argument(
        "--altitude",
        type=float,
        default=10.0,
        help="mission waypoint altitude above home, m, for plan/wpl (default 10)",
    )
    p.add_argument(
        "--clearance",
        type=float,
        default=5.0,
        help="plan/wpl waypoints at least this high above the hole when home is known (5)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace existing output files (never a .mcap or one of the logs)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from holescan.ground import export_flight_holes

    chosen = args.formats or ["gpx"]
    formats = list(HOLE_FORMATS) if "all" in chosen else chosen
    report = export_flight_holes(
        args.logs,
        formats,
        out=args.out,
        min_sightings=args.min_sightings,
        rel_alt_m=args.altitude,
        clearance_m=args.clearance,
        force=args.force,
    )
    for line in report.lines():
        print(line)
    return 0
