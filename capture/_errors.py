"""Errors of the capture package."""

from __future__ import annotations

from holescan.errors import HolescanError

__all__ = ["CaptureError", "SensorError"]


class CaptureError(HolescanError):
    """Root of the capture package's errors."""


class SensorError(CaptureError):
    """The camera is missing, cannot be opened, or stopped delivering frames.

    The capture daemon answers it by resetting the sensor on USB and opening it again.
    """
