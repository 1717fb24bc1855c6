"""``holescan <verb>``: parse arguments, call one library function, map errors to exit codes.

Each verb lives in a ``holescan/cli/_cmd_*.py`` module exposing ``register(subparsers)``
(:data:`COMMANDS`); the module sets ``func`` on its parser. No logic here.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence

# OpenCV's own "[ WARN ]" lines would land on stderr next to ours (set before cv2 loads).
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")

from holescan import __version__
from holescan.cli._args import EXIT_INPUT, EXIT_INTERRUPTED
from holescan.cli.progress import end_progress
from holescan.errors import HolescanError

GROUND_ONLY = frozenset(
    {"numba", "matplotlib", "dask", "distributed", "fsspec", "pytak", "takproto"}
    | {"cryptography", "rasterio", "rosbags", "starlette", "uvicorn", "h11", "bokeh", "mgrs"}
)
"""Import names of what pyproject's ``ground`` extra installs (the flight install lacks them)."""

COMMANDS: dict[str, str] = {
    "detect": "holescan.cli._cmd_detect",
    "dataset": "holescan.cli._cmd_dataset",
    "eval": "holescan.cli._cmd_eval",
    "log": "holescan.cli._cmd_log",
    "export-oni": "holescan.cli._cmd_export_oni",
    "plan": "holescan.cli._cmd_plan",
    "holes": "holescan.cli._cmd_holes",
    "fly": "holescan.cli._cmd_fly",
    "check": "holescan.cli._cmd_check",
    "reprocess": "holescan.cli._cmd_reprocess",
    "campaign": "holescan.cli._cmd_campaign",
    "demo": "holescan.cli._cmd_demo",
    "ground": "holescan.cli._cmd_ground",
    "pair": "holescan.cli._cmd_pair",
}
"""Each verb and the module that registers it, in the order ``holescan --help`` lists them."""


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser of ``holescan``. With ``argv`` naming a verb, only that verb's module is
    imported and registered: a verb pays for its own imports only (``holescan log info``
    does not load the detector or the ground station, which cost seconds of CPU on a
    companion computer). Without a verb (``--help``, a typo) every verb is registered, so
    the listing and the "invalid choice" error name them all."""
    parser = argparse.ArgumentParser(prog="holescan", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"holescan {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="verb", required=True, metavar="VERB")
    # The top-level options take no value, so the first other word is the verb.
    verb = next((a for a in (argv or ()) if not a.startswith("-")), None)
    names = [COMMANDS[verb]] if verb in COMMANDS else list(COMMANDS.values())
    for name in names:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(words)
    args = parser.parse_args(words)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args) or 0)
    except HolescanError as err:
        end_progress()
        print(f"holescan {args.verb}: error: {_one_line(str(err))}", file=sys.stderr)
        return EXIT_INPUT
    except OSError as err:  # a file or folder the library did not check: still one line
        end_progress()
        where = f": {err.filename}" if err.filename else ""
        print(f"holescan {args.verb}: error: {err.strerror or err}{where}", file=sys.stderr)
        return EXIT_INPUT
    except ModuleNotFoundError as err:  # a ground command on the flight install
        top = (err.name or "").split(".")[0]
        if top not in GROUND_ONLY:
            raise
        end_progress()
        print(
            f"holescan {args.verb}: error: this needs the ground install (module {top!r} is "
            "missing): pip install 'holescan[ground]'",
            file=sys.stderr,
        )
        return EXIT_INPUT
    except KeyboardInterrupt:
        end_progress()
        print(f"holescan {args.verb}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _one_line(text: str) -> str:
    return " ".join(text.split())
