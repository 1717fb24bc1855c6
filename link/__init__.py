"""The MAVLink link: the one door to pymavlink, and what the autopilot says as SI records.

Below the flight (:mod:`holescan.capture`), the missions and the ground station, which all
speak MAVLink through it:

* :func:`open_link`, :func:`parser`, ``mavlink`` (the dialect module: messages and every
  enum), ``mavutil``: MAVLink 2 set up in one place (:mod:`~link._connection`);
  :class:`SigningKey` its message signing;
* :class:`MavlinkStream`: bytes -> packets, so that garbage costs only itself;
* the adapters (``time_boot_ms``, degE7, mm, cm/s -> ns, deg, m, m/s, converted once):
  :func:`telemetry_sample` and its per-message functions, for the live link and log replay
  alike; the records they make (:class:`PositionSample`, :class:`AttitudeSample`,
  :class:`GpsFix`, :class:`NavStatus`);
* :class:`PoseBuffer` (with :class:`PoseValidity`): the vehicle's pose at any instant from
  those samples; :class:`TelemetryReplay` fills one from logged packets;
* :class:`RateRequests`: asking the autopilot for messages (commands with acknowledgement,
  message intervals), :func:`read_signing_key`;
* the checks of every value that arrives (:mod:`~link._values`: finite, in range, ids in
  the protocol's range, text XML can hold), raising :class:`LinkValueError`.

Errors in :mod:`link.errors`.
"""

from holescan.link._adapt import (
    TelemetrySample,
    attitude_from_attitude,
    attitude_from_quaternion,
    gps_from_gps_raw_int,
    home_from_home_position,
    is_autopilot_heartbeat,
    nav_from_ekf_status,
    position_from_global_position_int,
    telemetry_sample,
)
from holescan.link._connection import (
    MavConnection,
    mavlink,
    mavutil,
    open_link,
    parser,
)
from holescan.link._holetext import STATUSTEXT_MAX, HoleText, hole_text, read_hole_text
from holescan.link._posebuffer import (
    AttitudeSample,
    PoseBuffer,
    quat_from_euler,
)
from holescan.link._posevalidity import (
    GpsFix,
    NavStatus,
    PoseValidity,
    PositionSample,
    is_null_island,
)
from holescan.link._rates import (
    RateMethod,
    RateRequests,
    read_signing_key,
)
from holescan.link._replay import (
    TelemetryReplay,
)
from holescan.link._signing import (
    SigningKey,
    verified_signature,
)
from holescan.link._stream import (
    MavlinkStream,
)
from holescan.link._values import (
    HOLE_ID_MAX,
    CardValues,
    card_values,
    check_hole_id,
    link_float,
    link_int,
    link_lat_lon,
    link_yaw,
    optional_float,
    xml_safe_tree,
    xml_text,
)
from holescan.link.errors import (
    LinkError,
    LinkValueError,
    PoseInvalid,
    PoseUnavailable,
    TelemetryError,
    TelemetryTimeoutError,
)

__all__ = [
    "HOLE_ID_MAX",
    "STATUSTEXT_MAX",
    "AttitudeSample",
    "CardValues",
    "GpsFix",
    "HoleText",
    "LinkError",
    "LinkValueError",
    "MavConnection",
    "MavlinkStream",
    "NavStatus",
    "PoseBuffer",
    "PoseInvalid",
    "PoseUnavailable",
    "PoseValidity",
    "PositionSample",
    "RateMethod",
    "RateRequests",
    "SigningKey",
    "TelemetryError",
    "TelemetryReplay",
    "TelemetrySample",
    "TelemetryTimeoutError",
    "attitude_from_attitude",
    "attitude_from_quaternion",
    "card_values",
    "check_hole_id",
    "gps_from_gps_raw_int",
    "hole_text",
    "home_from_home_position",
    "is_autopilot_heartbeat",
    "is_null_island",
    "link_float",
    "link_int",
    "link_lat_lon",
    "link_yaw",
    "mavlink",
    "mavutil",
    "nav_from_ekf_status",
    "open_link",
    "optional_float",
    "parser",
    "position_from_global_position_int",
    "quat_from_euler",
    "read_hole_text",
    "read_signing_key",
    "telemetry_sample",
    "verified_signature",
    "xml_safe_tree",
    "xml_text",
]
