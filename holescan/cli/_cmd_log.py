"""``holescan log info FILE...`` and ``holescan log recover FILE [--out FILE]``."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("log", help="inspect or repair MCAP flight logs")
    verbs = p.add_subparsers(dest="log_verb", required=True, metavar="ACTION")
    info = verbs.add_parser("info", help="duration, topics, frames, drops, metadata")
    info.add_argument("files", type=Path, nargs="+", help="one log, or its rotated files in order")
    info.set_defaults(func=run_info)
    rec = verbs.add_parser("recover", help="rewrite a log cut off by a crash as a valid MCAP")
    rec.add_argument("file", type=Path, help="the damaged .mcap file")
    rec.add_argument("--out", type=Path, help="output file (default: FILE-recovered.mcap)")
    rec.set_defaults(func=run_recover)


def run_info(args: argparse.Namespace) -> int:
    from holescan.flightlog import log_info

    for line in log_info(args.files).lines():
        print(line)
    return 0


def run_recover(args: argparse.Namespace) -> int:
    from holescan.flightlog import recover_log

    out = args.out or args.file.with_name(f"{args.file.stem}-recovered.mcap")
    print(recover_log(args.file, out).line())
    return 0
