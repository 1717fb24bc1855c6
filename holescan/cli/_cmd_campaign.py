"""``holescan campaign FLIGHTS... --out DIR``: every flight of an operation, holes merged."""

from __future__ import annotations

import argparse

from holescan.cli._cmd_reprocess import add_engine_arguments, execute


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "campaign",
        help="reprocess every flight of an operation (several vehicles and days) on Dask "
        "and merge their holes: one id per hole, the flights that saw it",
        description="Reprocess the flights as `holescan reprocess` does (each flight's "
        "outputs in OUT/NAME/) and merge holes across flights by position and uncertainty: "
        "OUT/campaign_holes.* for the ground crew, OUT/campaign_report.html, and "
        "OUT/summary.json listing per hole the flights that saw it, first and last seen. "
        "A log cut off or damaged is read up to its last good chunk and reported; a missing "
        "file stops everything before any work. Rerun the same command to finish an "
        "interrupted campaign: finished partitions come from OUT/.holescan-cache.",
    )
    add_engine_arguments(p, "campaign")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from holescan.ground import run_campaign

    return execute(args, run_campaign)
