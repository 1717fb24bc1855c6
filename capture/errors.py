"""Errors of the capture package: one tree under :class:`holescan.errors.HolescanError`.

::

    CaptureError
    ├── SensorError              the camera is missing or stopped (the daemon resets it)
    ├── TelemetryError           the MAVLink link cannot be opened or used
    │   └── TelemetryTimeoutError    ... nothing came in time (also a TimeoutError)
    ├── ClockUnavailable         no clock estimate yet
    ├── PoseUnavailable          no trustworthy pose at that time
    │   └── PoseInvalid              ... the autopilot itself has none (no fix, jump, 0/0)
    ├── DiskBudgetError          the planned flight does not fit on the log's disk
    ├── OutputPathError          an output that must not or cannot be written (an InputError)
    └── FlightLogError           a flight log cannot be written or read (an InputError)
        ├── TruncatedLogError        ... it was cut off or damaged before its end
        ├── ChunkDamagedError        ... one chunk's bytes are not a valid chunk
        └── RecordError              ... bytes are not the record their header says

Imports nothing of capture's: every module of the package can raise these. Third-party
errors are wrapped where they happen (``raise FlightLogError(...) from err``).
"""

from __future__ import annotations

from holescan.errors import HolescanError, InputError

__all__ = [
    "CaptureError",
    "ChunkDamagedError",
    "ClockUnavailable",
    "DiskBudgetError",
    "FlightLogError",
    "OutputPathError",
    "PoseInvalid",
    "PoseUnavailable",
    "RecordError",
    "SensorError",
    "TelemetryError",
    "TelemetryTimeoutError",
    "TruncatedLogError",
]


class CaptureError(HolescanError):
    """Root of the capture package's errors."""


class SensorError(CaptureError):
    """The camera is missing, cannot be opened, or stopped delivering frames.

    The capture daemon answers it by resetting the sensor on USB and opening it again.
    """


class DiskBudgetError(CaptureError):
    """The planned flight does not fit on the log's disk (``fly`` refuses to take off)."""


class TelemetryError(CaptureError):
    """The MAVLink link could not be opened or used."""


class TelemetryTimeoutError(TelemetryError, TimeoutError):
    """Nothing (heartbeat, command acknowledgement) came in time."""


class ClockUnavailable(CaptureError):  # noqa: N818 (reads as a state, like PoseUnavailable)
    """No estimate yet: no TIMESYNC reply, no stamped message (or no SYSTEM_TIME for UTC)."""


class PoseUnavailable(CaptureError):  # noqa: N818 (name from the design: "pose unavailable")
    """No trustworthy pose at the requested time; the message says why."""


class PoseInvalid(PoseUnavailable):
    """The autopilot reports a position it does not have: no 3-D GPS fix, an estimator
    without a horizontal position, lat = lon = 0, or a jump no vehicle can make. Waiting
    for more telemetry does not help: that instant stays unplaced."""


class OutputPathError(CaptureError, InputError):
    """An output path that must not or cannot be written."""


class FlightLogError(CaptureError, InputError):
    """A flight log cannot be written, or a file is not a readable flight log."""


class TruncatedLogError(FlightLogError):
    """The file was cut off (crash, power loss) or damaged before its end."""


class ChunkDamagedError(FlightLogError):
    """A chunk's bytes are not a valid chunk (bad CRC, cut short, bad compression)."""


class RecordError(FlightLogError):
    """Bytes of a log that are not the record their header says (a damaged record: the
    scanner skips it and reports the bytes lost)."""
