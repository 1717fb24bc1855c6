"""Errors of the capture package (the flight): one tree under
:class:`holescan.errors.HolescanError`.

::

    CaptureError
    ├── SensorError              the camera is missing or stopped (the daemon resets it)
    ├── ClockUnavailable         no clock estimate yet
    └── DiskBudgetError          the planned flight does not fit on the log's disk

The link's errors (telemetry, poses) are in :mod:`holescan.link.errors`, the flight log's
in :mod:`holescan.flightlog.errors`, an output path's is
:class:`holescan.outputs.OutputPathError`. Imports nothing of capture's: every module of
the package can raise these.
"""

from __future__ import annotations

from holescan.errors import HolescanError

__all__ = ["CaptureError", "ClockUnavailable", "DiskBudgetError", "SensorError"]


class CaptureError(HolescanError):
    """Root of the capture package's errors."""


class SensorError(CaptureError):
    """The camera is missing, cannot be opened, or stopped delivering frames.

    The capture daemon answers it by resetting the sensor on USB and opening it again.
    """


class ClockUnavailable(CaptureError):  # noqa: N818 (reads as a state, like PoseUnavailable)
    """No estimate yet: no TIMESYNC reply, no stamped message (or no SYSTEM_TIME for UTC)."""


class DiskBudgetError(CaptureError):
    """The planned flight does not fit on the log's disk (``fly`` refuses to take off)."""
