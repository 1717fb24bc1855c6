"""Argument types and exit codes shared by the CLI verbs."""

from __future__ import annotations

import argparse

EXIT_INPUT = 2
EXIT_INTERRUPTED = 130


def positive_float(text: str) -> float:
    """argparse type: a number > 0."""
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value
