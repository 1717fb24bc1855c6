"""``holescan pair -o DIR NAME``: a pairing link for one more operator of a station."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "pair",
        help="issue a pairing link for an operator of the ground station's live page",
        description="Issue a pairing for operator NAME in the station folder DIR (the "
        "running station takes it at once) and print its link once: opened in that "
        "operator's browser, it lets the browser mark holes, recorded under NAME and the "
        "pairing's id in DIR/audit.jsonl. The link is not kept anywhere (the folder keeps a "
        "hash of it): to un-pair, delete its line from DIR/.station-pairings.json.",
    )
    p.add_argument("-o", "--out", type=Path, required=True, help="the station folder")
    p.add_argument("name", help="the operator's name (1-40 printable characters)")
    p.add_argument(
        "--http",
        default="127.0.0.1:8080",
        help="the station's live page HOST:PORT, as given to holescan ground "
        "(default 127.0.0.1:8080)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from holescan.errors import InputError
    from holescan.ground.station.pairing import Pairings
    from holescan.ground.station.web import station_url

    host, _, port_text = args.http.rpartition(":")
    if not host or not port_text.isdigit():
        raise InputError(f"--http wants HOST:PORT, got {args.http!r}")
    if not args.out.is_dir():
        raise InputError(f"{args.out}: no such station folder")
    pairing, token = Pairings(args.out).issue(args.name)
    print(f"{pairing}: {station_url(host, int(port_text))}?token={token}")
    return 0
