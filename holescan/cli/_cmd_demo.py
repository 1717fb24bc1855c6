"""``holescan demo [--out DIR] [--duration S] [--min-frames N]``: the whole system on a
simulated sortie."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import time
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, TextIO

from holescan.cli._args import EXIT_INTERRUPTED, positive_float

if TYPE_CHECKING:
    from holescan.demo import DemoProgress


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "demo",
        help="fly a simulated dawn survey with the whole system and score it against the truth",
        description="No hardware needed: a simulated autopilot (MAVLink over loopback) flies a "
        "survey planned over a synthetic rubble field; the capture daemon flies it with the "
        "simulated Xtion (MCAP log, detection worker, geotags, STATUSTEXT announcements, hole "
        "mission server for a simulated ground station). At the end it prints the holes found "
        "against the simulator's truth and writes the hole files and the report. About 1-2 "
        "minutes on two cores. Ctrl-C ends the flight early and still scores it.",
    )
    p.add_argument(
        "-o",
        "--out",
        type=Path,
        help="folder for the log, hole files and report (default: a new folder "
        "holescan/demo/YYYYmmdd-HHMMSS in the user's data folder, $XDG_DATA_HOME or "
        "~/.local/share; printed when the demo starts)",
    )
    p.add_argument(
        "--duration",
        type=positive_float,
        help="seconds of capture (default: one lap of the survey, about 75 s)",
    )
    p.add_argument(
        "--min-frames",
        type=_count,
        default=0,
        metavar="N",
        help="fly on past the duration until the simulated camera delivered N frames (it "
        "renders as fast as the CPU lets it: a slow or busy machine gets few in the duration)",
    )
    p.add_argument(
        "--size",
        type=positive_float,
        nargs=2,
        metavar=("EAST", "NORTH"),
        help="surveyed area, metres (default 10 10)",
    )
    p.add_argument("--seed", type=int, help="world seed (default 3)")
    p.add_argument("--holes", type=int, help="access holes in the field (default 4)")
    p.set_defaults(func=run)


def _count(text: str) -> int:
    """A whole number >= 0 (argparse type)."""
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return n


class _Display:
    """A progress line (redrawn on a terminal, every 10 s elsewhere) and the announcements."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self._last = 0.0
        self._phase = ""
        self._open_line = False
        self.at_least = ""  # ", at least N frames"

    def _line(self, text: str, final: bool) -> None:
        if self.tty:
            self.stream.write("\r" + text + "\x1b[K" + ("\n" if final else ""))
            self._open_line = not final
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def __call__(self, p: DemoProgress) -> None:
        if p.phase != self._phase:
            self._phase = p.phase
            if self._open_line:
                self._line("", True)
            text = {
                "world": "building the rubble world and planning the survey ...",
                "start": f"starting autopilot, capture daemon, mission server; flying "
                f"{p.duration_s:.0f} s{self.at_least} ...",
                "scoring": "landed; scoring against the truth, writing files ...",
            }.get(p.phase)
            if text:
                self._line(text, True)
        for text in p.announcements:
            self._line(f"  ground station: {text}", True)
        if p.phase != "flying":
            return
        now = time.monotonic()
        if not self.tty and now - self._last < 10.0 and not p.announcements:
            return
        self._last = now
        width = 30
        f = min(p.elapsed_s / p.duration_s, 1.0) if p.duration_s else 0.0
        bar = "#" * round(width * f) + "." * (width - round(width * f))
        self._line(
            f"  [{bar}] {p.elapsed_s:3.0f}/{p.duration_s:.0f} s  {p.frames} frames  "
            f"{p.detected} detected  {p.holes} holes confirmed",
            not self.tty,
        )


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from holescan.demo import DEMO_SORTIE, DemoOptions, default_demo_out, format_result, run_demo

    sortie = DEMO_SORTIE
    changes: dict[str, object] = {}
    if args.size:
        changes["size_m"] = (args.size[0], args.size[1])
    if args.seed is not None:
        changes["world_seed"] = args.seed
    if args.holes is not None:
        changes["n_access_holes"] = args.holes
    if changes:
        sortie = dataclasses.replace(sortie, **changes)  # type: ignore[arg-type]
    out = args.out or default_demo_out()
    print(f"holescan demo: writing to {out}", file=sys.stderr, flush=True)
    opts = DemoOptions(out=out, sortie=sortie, duration_s=args.duration, min_frames=args.min_frames)
    stop = threading.Event()

    def on_sigint(signum: int, _frame: FrameType | None) -> None:
        stop.set()
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a second one aborts

    if not args.verbose:  # INFO lines would break the progress display
        logging.getLogger().setLevel(logging.WARNING)
    previous = signal.signal(signal.SIGINT, on_sigint)
    display = _Display(sys.stderr)
    if args.min_frames:
        display.at_least = f", at least {args.min_frames} frames"
    try:
        result = run_demo(opts, progress=display, stop=stop)
    finally:
        signal.signal(signal.SIGINT, previous)
    for line in format_result(result):
        print(line)
    return EXIT_INTERRUPTED if result.interrupted and stop.is_set() else 0
