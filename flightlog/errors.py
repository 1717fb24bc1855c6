"""Errors of the flight log: one tree under :class:`holescan.errors.InputError`.

::

    FlightLogError           a flight log cannot be written or read (an InputError)
    ├── TruncatedLogError        ... it was cut off or damaged before its end
    ├── ChunkDamagedError        ... one chunk's bytes are not a valid chunk
    └── RecordError              ... bytes are not the record their header says

Imports nothing of the flight log's: every module of the package can raise these.
Third-party errors are wrapped where they happen (``raise FlightLogError(...) from err``).
"""

from __future__ import annotations

from holescan.errors import InputError

__all__ = ["ChunkDamagedError", "FlightLogError", "RecordError", "TruncatedLogError"]


class FlightLogError(InputError):
    """A flight log cannot be written, or a file is not a readable flight log."""


class TruncatedLogError(FlightLogError):
    """The file was cut off (crash, power loss) or damaged before its end."""


class ChunkDamagedError(FlightLogError):
    """A chunk's bytes are not a valid chunk (bad CRC, cut short, bad compression)."""


class RecordError(FlightLogError):
    """Bytes of a log that are not the record their header says (a damaged record: the
    scanner skips it and reports the bytes lost)."""
