"""Alien scenes: the command line."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from alien_scenes.dataset import generate_dataset


def main(argv: list[str] | None = None) -> int:
    """Command line: ``python benchmarks/alien_scenes OUT [--n N] [--seed S] [--jobs J]``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("out", type=Path, help="output folder")
    ap.add_argument("--n", type=int, default=60, help="number of images (default 60)")
    ap.add_argument("--seed", type=int, default=7, help="random seed (default 7)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument(
        "--sensor",
        choices=("structured-light", "basic"),
        default="structured-light",
        help="depth model: the measured structured-light model (default) or this generator's "
        "own earlier one, for comparison",
    )
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    summary = generate_dataset(args.out, args.n, args.seed, args.jobs, args.sensor)
    print(
        f"images {summary['images']}, holes {summary['holes']} (+{summary['crowd']} crowd), "
        f"images without a hole {summary['images_without_hole']}, {summary['seconds']} s"
    )
    return 0
