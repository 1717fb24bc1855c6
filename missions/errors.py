"""Errors of the missions package: one tree under :class:`holescan.errors.HolescanError`.

::

    MissionsError
    ├── MissionError             a mission transfer failed (bad link, protocol error)
    │   ├── MissionTimeoutError      ... the autopilot did not answer in time (a TimeoutError)
    │   └── MissionRejectedError     ... it answered MISSION_ACK with an error
    ├── MissionServerError       the vehicle-side mission server's link failed or was misused
    └── SunWindowError           no usable sun window, or a flight outside every window

Imports nothing of missions': every module of the package can raise these.
"""

from __future__ import annotations

from holescan.errors import HolescanError

__all__ = [
    "MissionError",
    "MissionRejectedError",
    "MissionServerError",
    "MissionTimeoutError",
    "MissionsError",
    "SunWindowError",
]


class MissionsError(HolescanError):
    """The root of the missions package's errors."""


class MissionError(MissionsError):
    """The mission transfer failed (bad link, protocol error)."""


class MissionTimeoutError(MissionError, TimeoutError):
    """The autopilot did not answer in time (after the retries)."""


class MissionRejectedError(MissionError):
    """The autopilot answered MISSION_ACK with an error; ``result`` is the MAV_MISSION_RESULT."""

    def __init__(self, message: str, result: int) -> None:
        super().__init__(message)
        self.result = result


class MissionServerError(MissionsError):
    """The mission server's link failed or it was used wrongly."""


class SunWindowError(MissionsError):
    """No usable sun window (polar day/night), or a flight outside every window."""
