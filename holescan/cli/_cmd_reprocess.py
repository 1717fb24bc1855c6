"""``holescan reprocess FLIGHT.mcap... [--out DIR] [--mode ...] [--workers N | --scheduler URL]``.

Also the arguments, progress bar and Ctrl-C handling ``holescan campaign`` shares.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from holescan.cli._args import EXIT_INTERRUPTED
from holescan.missions import HOLE_FORMATS

if TYPE_CHECKING:
    from holescan.ground import Progress, ReprocessOptions, ReprocessResult


def _score(text: str) -> float:
    """argparse type: a number in [0, 1] (NaN refused: it would silently drop nothing)."""
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}") from err
    if math.isnan(value) or not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1], got {text!r}")
    return value


def add_engine_arguments(p: argparse.ArgumentParser, default_out: str) -> None:
    """The arguments ``reprocess`` and ``campaign`` share."""
    p.add_argument(
        "logs",
        nargs="+",
        help="flight logs: files of one or more flights (NAME_0000.mcap brings its parts); "
        "paths every worker can read, or URLs fsspec opens; or recordings (TUM RGB-D folder, "
        "ROS 1/ROS 2 bag, .oni), written as flight logs into OUT/recordings/ first",
    )
    p.add_argument(
        "-o", "--out", type=Path, default=Path(default_out), help=f"output folder ({default_out})"
    )
    p.add_argument("--mode", choices=("default", "paper"), default="default", help="detector")
    p.add_argument(
        "--searcher",
        choices=("human", "dog", "robot"),
        default="human",
        help="who must fit through the hole (default human)",
    )
    p.add_argument("--min-score", type=_score, help="drop detections scoring below this (0-1)")
    engine = p.add_mutually_exclusive_group()
    engine.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="worker processes of the local Dask cluster (default: one per core; "
        "0 = in this process, no cluster)",
    )
    engine.add_argument(
        "--scheduler",
        metavar="tcp://HOST:8786",
        help="use this running Dask scheduler and its workers instead of a local cluster",
    )
    p.add_argument(
        "--partition-mib",
        type=float,
        default=32.0,
        help="log bytes per task, MiB (default 32: about 30 frames)",
    )
    p.add_argument(
        "--no-cache",
        action="store_true",
        help="compute every partition again (default: reuse OUT/.holescan-cache)",
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
        "--announce-min-p-hole",
        type=_score,
        metavar="P",
        help="holes at this hole-level p_hole (and seen often enough) are announced "
        "(default: the flight's own threshold, as its log records it; 0.9 for old logs)",
    )
    p.add_argument(
        "--review-min-p-hole",
        type=_score,
        metavar="P",
        help="other holes at this p_hole are for review (default: the flight's; 0.1 for old logs)",
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
    p.add_argument(
        "--map-cell",
        type=float,
        default=0.02,
        metavar="M",
        help="search map cells, metres (default 0.02); 0 = no map (no ortho/dsm/coverage/"
        "kmz/gaps/re-fly files)",
    )
    p.add_argument(
        "--map-every", type=int, default=3, metavar="N", help="fuse every N-th frame (default 3)"
    )
    p.add_argument(
        "--gap-threshold",
        type=float,
        default=0.5,
        metavar="P",
        help="coverage below which the map's cells are gaps (default 0.5)",
    )
    p.add_argument(
        "--station",
        metavar="DIR",
        action="append",
        default=[],
        help="a ground station's folder (holescan ground --out): its operators' marks "
        "(confirmed, rejected, visited) carry into every output, each to the flight whose "
        "hole has that id at that place (repeat for one station per flight; one station "
        "that followed several flights works too)",
    )
    p.add_argument(
        "--area",
        metavar="AREA.geojson",
        help="the planned area (as `holescan plan` takes it): gaps and the searched fraction "
        "within it (default: the hull of what was seen)",
    )


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "reprocess",
        help="detect again over whole flight logs (other thresholds, another searcher) and "
        "get each flight's holes, hole files and report again",
        description="Detect on every frame of each flight log (also one cut off by a crash) "
        "on a Dask cluster (local by default), pose frames from the logged telemetry and "
        "merge holes as in flight. Writes per flight a sidecar MCAP with the new detections "
        "and holes on /reprocess/* (open it in Foxglove together with the logs), the hole "
        "files, an HTML report and summary.json. Finished partitions are cached: a rerun "
        "does only what is missing. Ctrl-C stops cleanly; a second Ctrl-C aborts.",
    )
    add_engine_arguments(p, "reprocessed")
    p.set_defaults(func=run)


def options(args: argparse.Namespace) -> ReprocessOptions:
    import dataclasses

    from holescan.detect import DEFAULT, PAPER
    from holescan.ground import ReprocessOptions
    from holescan.ground.station.marks import read_station_marks
    from holescan.missions import read_area

    params = (PAPER if args.mode == "paper" else DEFAULT).with_searcher(args.searcher)
    if args.min_score is not None:
        params = dataclasses.replace(params, min_score=args.min_score)
    opts = ReprocessOptions(
        params=params,
        workers=args.workers,
        scheduler=args.scheduler,
        partition_mib=args.partition_mib,
        frames=args.frames,
        min_sightings=args.min_sightings,
        cache=not args.no_cache,
        announce_min_p_hole=args.announce_min_p_hole,
        review_min_p_hole=args.review_min_p_hole,
        map_cell_m=args.map_cell if args.map_cell > 0 else None,
        map_every=args.map_every,
        gap_threshold=args.gap_threshold,
        area=read_area(args.area) if args.area else None,
        station_marks=tuple(
            m for folder in args.station for m in read_station_marks(Path(folder)).values()
        ),
    )
    if args.formats:
        opts = dataclasses.replace(opts, formats=tuple(dict.fromkeys(args.formats)))
    return opts


class ProgressBar:
    """A rich progress bar on a terminal (a line every 5 s elsewhere); prints the Dask
    dashboard's address once it is known."""

    def __init__(self) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

        self.console = Console(stderr=True)
        self._bar = Progress(
            "[progress.description]{task.description}",
            BarColumn(),
            MofNCompleteColumn(),
            "partitions",
            "{task.fields[rate]}",
            TimeRemainingColumn(),
            console=self.console,
            disable=not self.console.is_terminal,
        )
        self._task = self._bar.add_task("reprocessing", total=None, rate="")
        self._dashboard: str | None = None
        self._last_line = -math.inf

    def __enter__(self) -> ProgressBar:
        self._bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._bar.stop()

    def __call__(self, p: Progress) -> None:
        if p.dashboard and p.dashboard != self._dashboard:
            self._dashboard = p.dashboard
            self.console.print(f"Dask dashboard: {p.dashboard}")
        rate = f"{p.frames_done} frames, {p.frames_per_s:.1f}/s"
        cached = f" ({p.partitions_cached} cached)" if p.partitions_cached else ""
        self._bar.update(
            self._task,
            total=p.partitions_total,
            completed=p.partitions_done,
            rate=rate + cached,
            description=f"flights {p.flights_done}/{p.flights}",
        )
        if not self.console.is_terminal and (
            p.elapsed_s - self._last_line >= 5.0 or p.partitions_done == p.partitions_total
        ):
            self._last_line = p.elapsed_s
            print(
                f"{p.partitions_done}/{p.partitions_total} partitions{cached}, {rate}",
                file=sys.stderr,
                flush=True,
            )


def stop_on_sigint(stop: threading.Event) -> Callable[[], None]:
    """First Ctrl-C sets ``stop`` (a clean stop); a second one interrupts at once.
    Returns the undo."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum: int, frame: Any) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        logging.getLogger("holescan").warning(
            "stopping: merging what is done (Ctrl-C again to abort)"
        )
        stop.set()

    signal.signal(signal.SIGINT, handler)

    def restore() -> None:
        signal.signal(signal.SIGINT, previous)

    return restore


def _quiet_dask() -> None:
    """Dask's own loggers (each set to INFO by its configuration) to errors only."""
    import distributed  # noqa: F401 (configures its loggers; set them after)

    for name in list(logging.root.manager.loggerDict):
        if name.split(".")[0] in ("distributed", "dask"):
            logging.getLogger(name).setLevel(logging.ERROR)


def execute(args: argparse.Namespace, fn: Callable[..., ReprocessResult]) -> int:
    """Run ``fn(logs, out, opts, progress=..., stop=...)``; print its lines."""
    from holescan.ground.recordings import flight_logs_of

    opts = options(args)
    if not args.verbose:  # INFO lines would break the progress display
        logging.getLogger().setLevel(logging.WARNING)
        _quiet_dask()
    logs, converted = flight_logs_of(args.logs, args.out)
    for source, done in converted:
        poses = "poses from {} + {}".format(*done.telemetry) if done.telemetry else "no poses"
        what = "kept (made from it before)" if done.reused else f"{done.frames} frames, {poses}"
        print(f"{source}: as the flight log {done.log}: {what}")
    stop = threading.Event()
    restore = stop_on_sigint(stop)
    try:
        with ProgressBar() as bar:
            result = fn(logs, args.out, opts, progress=bar, stop=stop)
    finally:
        restore()
    for line in result.lines():
        print(line)
    return EXIT_INTERRUPTED if result.interrupted else 0


def run(args: argparse.Namespace) -> int:
    from holescan.ground import reprocess

    return execute(args, reprocess)
