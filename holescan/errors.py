"""The project's exception root: a leaf module that every package imports, importing nothing.

Each package subclasses :class:`HolescanError` for its own failures (``capture`` its
``CaptureError``, ``missions`` its ``MissionError`` ...), wrapping third-party errors with
``raise ... from err``; the CLI prints any of them as one line and exits 2.
"""

__all__ = ["HolescanError", "InputError"]


class HolescanError(Exception):
    """Root of every error holescan raises on purpose (the CLI prints it as one line)."""


class InputError(HolescanError, ValueError):
    """Bad input: wrong shape/dtype, missing or corrupt file. The message says what to fix."""
