"""``holescan fly``: capture, log, detect and geotag on the companion computer until stopped.

SIGINT and SIGTERM (``systemctl stop``) end the flight cleanly: capture stops, the
detection worker is drained, the MCAP log is finished and closed, and the summary printed.
A second SIGINT interrupts at once.
"""

from __future__ import annotations

import argparse
import logging
import signal
import threading
from types import FrameType

from holescan.cli._flightargs import add_flight_arguments, fly_config

log = logging.getLogger("holescan.fly")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "fly",
        help="capture RGB-D + MAVLink to an MCAP log, detect and geotag holes, serve them",
        description="The flight daemon: sensor -> MCAP log and -> detection worker -> geotags "
        "-> holes served to the ground station. Command-line options override the config file "
        "(deploy/fly.example.toml documents it). Stop with SIGINT or SIGTERM.",
    )
    add_flight_arguments(p)
    p.add_argument(
        "--check",
        action="store_true",
        help="run the pre-flight check (as `holescan check`) and exit: 0 GO, 1 NO-GO",
    )
    p.add_argument(
        "--json", action="store_true", help="with --check: the checklist as JSON on stdout"
    )
    p.add_argument(
        "--bench",
        action="store_true",
        help="a bench test: fly even without a streaming sensor or an answering autopilot "
        "(else that is a NO-GO and fly exits 2 before flying)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from holescan.capture import fly, format_report, open_sensor, require_go

    if args.check:
        from holescan.cli._cmd_check import run as check

        return check(args)
    cfg = fly_config(args)
    if args.bench:
        log.warning("bench test: flying without requiring a sensor or an autopilot")
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        log.info("%s: finishing the flight", signal.Signals(signum).name)
        stop.set()
        if signum == signal.SIGINT:  # a second Ctrl-C interrupts at once
            signal.signal(signal.SIGINT, signal.default_int_handler)

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    gate = cfg.flight.gate
    try:
        if cfg.sensor.kind == "sim":  # the simulator is loaded only when asked for
            from holescan.sim import fly_sim, format_sim_report

            print(format_sim_report(fly_sim(cfg, stop=stop, bench=args.bench), gate))
        else:
            setup = open_sensor(cfg)
            if not args.bench:
                require_go(cfg, setup)
            print(format_report(fly(cfg, setup, stop=stop), gate))
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    return 0
