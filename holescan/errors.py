"""The project's exception root: a leaf module that every package imports, importing nothing.

Each package subclasses :class:`HolescanError` for its own failures (``capture`` its
``CaptureError``, ``missions`` its ``MissionError`` ...), wrapping third-party errors with
``raise ... from err``; the CLI prints any of them as one line and exits 2.
"""

__all__ = ["HolescanError", "InputError", "NoDepthError"]


class HolescanError(Exception):
    """Root of every error holescan raises on purpose (the CLI prints it as one line)."""


class InputError(HolescanError, ValueError):
    """Bad input: wrong shape/dtype, missing or corrupt file. The message says what to fix."""


class NoDepthError(InputError):
    """The depth image has no reading at all: the sensor is closer than its minimum range
    (an Xtion under 0.5 m, e.g. a vehicle on the ground) or sees nothing it can range.

    Not a detector failure: in flight such frames are counted as "no depth", apart from
    detection errors.
    """
