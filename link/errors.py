"""Errors of the MAVLink link: one tree under :class:`holescan.errors.HolescanError`.

::

    LinkError
    ├── LinkValueError           a value from the link missing, not finite or out of range
    ├── TelemetryError           the MAVLink link cannot be opened or used
    │   └── TelemetryTimeoutError    ... nothing came in time (also a TimeoutError)
    └── PoseUnavailable          no trustworthy pose at that time
        └── PoseInvalid              ... the autopilot itself has none (no fix, jump, 0/0)

Imports nothing of the link's: every module of the package can raise these.
"""

from __future__ import annotations

from holescan.errors import HolescanError

__all__ = [
    "LinkError",
    "LinkValueError",
    "PoseInvalid",
    "PoseUnavailable",
    "TelemetryError",
    "TelemetryTimeoutError",
]


class LinkError(HolescanError):
    """Root of the MAVLink link's errors."""


class LinkValueError(LinkError, ValueError):
    """A value from the link is missing, not a number, not finite or out of its range
    (:mod:`link._values`); the packet that carried it is counted and dropped."""


class TelemetryError(LinkError):
    """The MAVLink link could not be opened or used."""


class TelemetryTimeoutError(TelemetryError, TimeoutError):
    """Nothing (heartbeat, command acknowledgement) came in time."""


class PoseUnavailable(LinkError):  # noqa: N818 (name from the design: "pose unavailable")
    """No trustworthy pose at the requested time; the message says why."""


class PoseInvalid(PoseUnavailable):
    """The autopilot reports a position it does not have: no 3-D GPS fix, an estimator
    without a horizontal position, lat = lon = 0, or a jump no vehicle can make. Waiting
    for more telemetry does not help: that instant stays unplaced."""
