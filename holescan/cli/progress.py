"""The CLI's progress bar: rich, drawn on a terminal only (a log or a pipe gets no progress
text, so an error line is never glued to it)."""

from __future__ import annotations

import sys
from typing import Any, TextIO

__all__ = ["Progress", "end_progress"]


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
