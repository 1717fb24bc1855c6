"""Argument types and exit codes shared by the CLI verbs."""

from __future__ import annotations

import argparse
import sys
from typing import TextIO

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


class Progress:
    """``label: i/n`` redrawn on one line, only when stderr is a terminal (a log or a pipe
    gets no progress text, so an error line is never glued to it)."""

    _open: Progress | None = None

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, i: int, n: int, label: str = "") -> None:
        if not self.tty:
            return
        self.stream.write(f"\r{label}{i}/{n}\x1b[K")
        self.stream.flush()
        Progress._open = self

    def done(self) -> None:
        """End the progress line (a newline, when one was drawn)."""
        if Progress._open is self:
            self.stream.write("\n")
            self.stream.flush()
            Progress._open = None


def end_progress() -> None:
    """Close any open progress line before printing something else on stderr."""
    if Progress._open is not None:
        Progress._open.done()
