"""``holescan export-oni FLIGHT.mcap [MORE.mcap ...] OUT.oni``: frames of a log as ``.oni``."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "export-oni",
        help="write the RGB-D frames of an MCAP flight log as an OpenNI .oni recording",
    )
    p.add_argument(
        "logs", type=Path, nargs="+", help="the flight log, or its rotated files in order"
    )
    p.add_argument("out", type=Path, help="the .oni file to write")
    p.add_argument("--fps", type=int, default=30, help="nominal frame rate (default 30)")
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing OUT.oni (never a .mcap or one of the logs)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from holescan.capture import export_oni

    n = export_oni(args.logs, args.out, fps=args.fps, force=args.force)
    print(f"{args.out}: {n} frames")
    return 0
