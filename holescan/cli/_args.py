"""Argument types and exit codes shared by the CLI verbs."""

from __future__ import annotations

import argparse
import sys
from typing import Any, TextIO

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
    """A rich progress bar (``label``, bar, ``i/n``, time left) redrawn on stderr, only when
    it is a terminal (a log or a pipe gets no progress text, so an error line is never
    glued to it). Call ``bar(i, n, label)`` as work advances, :meth:`done` at the end."""

    _open: Progress | None = None

    def __init__(self, stream: TextIO | None = None) -> None:
        from rich.console import Console  # imported when a bar is made: the flight needs none

        self.console = Console(file=stream if stream is not None else sys.stderr)
        self.tty = self.console.is_terminal
        self._bar: Any = None
        self._task: Any = None

    def __call__(self, i: int, n: int, label: str = "") -> None:
        if not self.tty:
            return
        if self._bar is None:
            from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeRemainingColumn
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeRemainingColumn(),
                console=self.console,
            )
            self._task = self._bar.add_task(label, total=n)
            self._bar.start()
            Progress._open = self
        self._bar.update(self._task, completed=i, total=n, description=label)

    def done(self) -> None:
        """End the progress bar (it stays drawn, its line ended)."""
        bar, self._bar = self._bar, None
        if bar is not None:
            bar.stop()
        if Progress._open is self:
            Progress._open = None


def end_progress() -> None:
    """Close any open progress line before printing something else on stderr."""
    if Progress._open is not None:
        Progress._open.done()
