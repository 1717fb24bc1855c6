"""``holescan check``: the pre-flight check, GO / NO-GO per item (also ``fly --check``)."""

from __future__ import annotations

import argparse
import json
import sys

from holescan.cli._flightargs import add_flight_arguments, fly_config

EXIT_NO_GO = 1

_STYLE = {"GO": "bold green", "NO-GO": "bold red", "WARN": "bold yellow", "SKIP": "dim"}


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "check",
        help="pre-flight check: sensor, autopilot, clock, GPS fix, mount, disk, signing, GCS",
        description="Checks what `holescan fly` with the same options would fly with and "
        "says GO, NO-GO, WARN or SKIP for each item: the sensor streams, the autopilot "
        "answers (heartbeat, TIMESYNC, a parameter and its mission storage: initialised), a "
        "3-D GPS fix, the mount and camera, room on the disk, the signing key, the ground "
        "station. Exit 0 when nothing is NO-GO, 1 otherwise (2: a bad option or file).",
    )
    add_flight_arguments(p)
    p.add_argument("--json", action="store_true", help="the checklist as JSON on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from holescan.capture import preflight

    cfg = fly_config(args)
    if cfg.sensor.kind == "sim":  # the simulator is loaded only when asked for
        from holescan.sim import check_sim

        report = check_sim(cfg)
    else:
        report = preflight(cfg)
    if args.json:
        print(json.dumps(report.as_dict(), indent=2))
    else:
        from rich.console import Console
        from rich.table import Table

        table = Table(title="holescan pre-flight check", title_justify="left")
        table.add_column("item")
        table.add_column("status")
        table.add_column("detail", overflow="fold")
        for item in report.items:
            table.add_row(item.name, f"[{_STYLE[item.status]}]{item.status}[/]", item.detail)
        console = Console()
        console.print(table)
        verdict = "[bold green]GO[/]" if report.go else "[bold red]NO-GO[/]"
        console.print(f"pre-flight: {verdict}")
    if not report.go:
        print(f"holescan check: NO-GO: {report.no_go_line()}", file=sys.stderr)
        return EXIT_NO_GO
    return 0
