"""The options ``holescan fly`` and ``holescan check`` share, and the flight configuration
they make (the config file with the command line over it)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from holescan.cli._args import positive_float

if TYPE_CHECKING:
    from holescan.capture import FlyConfig


def add_flight_arguments(p: argparse.ArgumentParser) -> None:
    """The options ``fly`` and ``check`` share (what is flown, where it logs)."""
    p.add_argument(
        "--sensor",
        help="openni2 (the Xtion), oni:PATH, mcap:PATH (replays a flight log), or sim "
        "(the simulated Xtion: with its own simulated autopilot, or with --mavlink rendering "
        "from the pose that autopilot reports, the world placed at its home); default openni2",
    )
    p.add_argument(
        "--mavlink",
        help="autopilot link: /dev/ttyAMA0, udpin:0.0.0.0:14550, tcp:HOST:PORT ... "
        "(with --sensor sim: the autopilot the simulated Xtion flies with, e.g. ArduPilot "
        "SITL's tcp:127.0.0.1:5762; without it a simulated autopilot is started)",
    )
    p.add_argument("--log-dir", type=Path, help="folder for the flight logs")
    p.add_argument("--config", type=Path, help="TOML configuration file")
    p.add_argument(
        "--gcs",
        help="serve found holes as a mission (component 191) and announce them by STATUSTEXT "
        "on this link, e.g. udpout:192.168.1.10:14550",
    )
    p.add_argument(
        "--sysid",
        type=int,
        help="the vehicle's MAVLink system id (1..255; the hole server is component 191 of "
        "it; with --sensor sim also the simulated autopilot's, so two sorties can fly into "
        "one ground station at once); default 1 or the config file's",
    )
    p.add_argument("--duration", type=positive_float, help="stop after this many seconds")
    p.add_argument("--max-frames", type=int, help="stop after this many frames")


def fly_config(args: argparse.Namespace) -> FlyConfig:
    """The flight configuration: the config file with the command line over it."""
    from holescan.capture import load_fly_config

    return load_fly_config(
        args.config,
        {
            "sensor": args.sensor,
            "mavlink": args.mavlink,
            "log_dir": args.log_dir,
            "gcs": args.gcs,
            "sysid": args.sysid,
            "duration_s": args.duration,
            "max_frames": args.max_frames,
        },
    )
