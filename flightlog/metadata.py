"""The flight log's ``holescan.mount`` metadata record: how the camera sat on the vehicle
and how well its attitude was known, written with the log and read back for geotagging.

The record's values are strings (MCAP metadata): ``rotation_frd_from_camera`` (a 3x3 JSON
array), ``offset_frd_m`` (3 numbers, JSON) and ``attitude_sigma_deg``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping

import numpy as np

from holescan.errors import InputError
from holescan.flightlog.errors import FlightLogError
from holescan.flightlog.schemas import to_json
from holescan.geotag import CameraMount, ErrorModel

__all__ = ["errors_from_metadata", "mount_from_metadata", "mount_metadata"]


def mount_metadata(mount: CameraMount, errors: ErrorModel) -> dict[str, str]:
    """The ``holescan.mount`` metadata record: the mount's rotation and offset, and the
    attitude sigma of the sightings' error model (read back by :func:`mount_from_metadata`
    and :func:`errors_from_metadata`)."""
    return {
        "rotation_frd_from_camera": to_json(np.asarray(mount.rotation, np.float64)).decode(),
        "offset_frd_m": to_json(tuple(float(v) for v in mount.offset_m)).decode(),
        "attitude_sigma_deg": repr(math.degrees(errors.attitude_sigma_rad)),
    }


def errors_from_metadata(metadata: Mapping[str, Mapping[str, str]]) -> ErrorModel:
    """The sightings' error model of a log: its ``holescan.mount`` record's
    ``attitude_sigma_deg`` (the default model for logs without one). Raises
    :class:`FlightLogError` when the value cannot be read."""
    value = metadata.get("holescan.mount", {}).get("attitude_sigma_deg")
    if value is None:
        return ErrorModel()
    try:
        return ErrorModel(attitude_sigma_rad=math.radians(float(value)))
    except InputError as err:  # a ValueError too: first
        raise FlightLogError(f"holescan.mount {err}") from err
    except ValueError as err:
        raise FlightLogError(f"unreadable holescan.mount attitude_sigma_deg: {value!r}") from err


def mount_from_metadata(metadata: Mapping[str, Mapping[str, str]]) -> CameraMount:
    """The camera mount a log's ``holescan.mount`` metadata record gives (default mount when
    there is none). Raises :class:`FlightLogError` when the record cannot be read."""
    md = metadata.get("holescan.mount")
    if md is None:
        return CameraMount()
    try:
        rot = json.loads(md["rotation_frd_from_camera"])
        offset = tuple(float(v) for v in json.loads(md["offset_frd_m"]))
        rotation = tuple(tuple(float(v) for v in row) for row in rot)
        if len(offset) != 3 or len(rotation) != 3 or any(len(r) != 3 for r in rotation):
            raise ValueError("a 3x3 rotation and a 3-vector offset are expected")
        return CameraMount(rotation, offset)  # type: ignore[arg-type]
    except (KeyError, ValueError, TypeError) as err:
        raise FlightLogError(f"unreadable holescan.mount metadata: {err}") from err
