"""The CLI's progress bar (rich): drawn on a terminal, silent in a pipe or a log."""

from __future__ import annotations

import io
import os
import pty

from holescan.cli.progress import Progress, end_progress


def test_no_progress_text_in_a_pipe() -> None:
    out = io.StringIO()
    bar = Progress(out)
    for i in range(1, 4):
        bar(i, 3, "rendering ")
    bar.done()
    end_progress()
    assert out.getvalue() == ""


def test_bar_on_a_terminal() -> None:
    master, slave = pty.openpty()
    try:
        with os.fdopen(slave, "w", closefd=False) as term:
            bar = Progress(term)
            assert bar.tty
            for i in range(1, 11):
                bar(i, 10, "rendering")
            end_progress()  # what the CLI calls before an error line
            assert Progress._open is None
            term.flush()
        text = b""
        while b"10/10" not in text:
            text += os.read(master, 65536)
    finally:
        os.close(master)
        os.close(slave)
    assert b"rendering" in text
