"""``holescan reprocess FLIGHT.mcap... [--out DIR] [--mode ...] [--workers N]``."""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from holescan._args import EXIT_INTERRUPTED
from missions import HOLE_FORMATS

if TYPE_CHECKING:
    from ground import Progress


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "reprocess",
        help="detect again over whole flight logs (other thresholds, another searcher) and "
        "get the holes, hole files and report again",
        description="Read each flight log once (also one cut off by a crash), detect on every "
        "frame in parallel, pose frames from the logged telemetry and merge holes as in flight. "
        "Writes a copy of each log with the new detections and holes on /reprocess/* topics "
        "(the original is never modified), the hole files, an HTML report and summary.json. "
        "Ctrl-C stops cleanly and keeps what is done; a second Ctrl-C aborts.",
    )
    p.add_argument(
        "logs",
        type=Path,
        nargs="+",
        help="flight logs: files of one or more flights (NAME_0000.mcap brings its parts)",
    )
    p.add_argument(
        "-o",
        "--out",
        type=Path,
        default=Path("reprocessed"),
        help="output folder (default ./reprocessed; one subfolder per flight when several)",
    )
    p.add_argument("--mode", choices=("default", "paper"), default="default", help="detector")
    p.add_argument(
        "--searcher",
        choices=("human", "dog", "robot"),
        default="human",
        help="who must fit through the hole (default human)",
    )
    p.add_argument("--min-score", type=float, help="drop detections scoring below this")
    p.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="detection processes (default: one per core; 0 = in this process)",
    )
    p.add_argument(
        "--frames",
        choices=("all", "flight"),
        default="all",
        help="all frames (default), or only those the flight's detector processed "
        "(reproduces the flight's holes exactly with the flight's settings)",
    )
    p.add_argument(
        "--min-sightings",
        type=int,
        default=2,
        metavar="N",
        help="holes seen in at least N frames go to the hole files (default 2)",
    )
    p.add_argument(
        "-f",
        "--format",
        dest="formats",
        action="append",
        choices=HOLE_FORMATS,
        metavar="FORMAT",
        help=f"hole file format, repeatable: {', '.join(HOLE_FORMATS)} "
        "(default: gpx, kml, geojson, plan)",
    )
    p.set_defaults(func=run)


class _Bar:
    """One progress line on a terminal (redrawn), or a line every 5 s elsewhere."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self._last = 0.0

    def __call__(self, p: Progress) -> None:
        now = time.monotonic()
        if not self.tty and now - self._last < 5.0 and p.fraction < 1.0:
            return
        self._last = now
        width = 24
        filled = round(width * min(p.fraction, 1.0))
        eta = "--:--" if p.eta_s != p.eta_s else f"{int(p.eta_s) // 60}:{int(p.eta_s) % 60:02d}"
        flight = f"flight {p.flight_number}/{p.flights} " if p.flights > 1 else ""
        line = (
            f"{flight}{p.flight} [{'#' * filled}{'.' * (width - filled)}] "
            f"{100 * p.fraction:3.0f}% {p.frames_done} frames {p.frames_per_s:5.1f} frames/s "
            f"ETA {eta}"
        )
        self.stream.write(("\r" + line + "\x1b[K") if self.tty else line + "\n")
        self.stream.flush()

    def done(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from detect import DEFAULT, PAPER
    from ground import ReprocessOptions, reprocess

    params = (PAPER if args.mode == "paper" else DEFAULT).with_searcher(args.searcher)
    if args.min_score is not None:
        params = dataclasses.replace(params, min_score=args.min_score)
    opts = ReprocessOptions(
        params=params,
        workers=args.workers,
        frames=args.frames,
        min_sightings=args.min_sightings,
    )
    if args.formats:
        opts = dataclasses.replace(opts, formats=tuple(dict.fromkeys(args.formats)))
    if not args.verbose:  # INFO lines would break the progress display
        logging.getLogger().setLevel(logging.WARNING)
    bar = _Bar(sys.stderr)
    try:
        result = reprocess(args.logs, args.out, opts, progress=bar)
    finally:
        bar.done()
    for line in result.lines():
        print(line)
    return EXIT_INTERRUPTED if result.interrupted else 0
