"""Checks of the numbers a survey is planned from: finite, and places on the Earth."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from holescan.errors import InputError

__all__ = ["check_latlon", "check_survey_numbers"]


def check_latlon(lat_deg: float, lon_deg: float, what: str = "position") -> None:
    """Raise :class:`InputError` unless -90 <= lat <= 90 and -180 <= lon <= 180 (finite):
    a point off the Earth is a typo, never wrapped silently."""
    if not (math.isfinite(lat_deg) and -90.0 <= lat_deg <= 90.0):
        raise InputError(f"{what}: latitude must be within -90..90 deg, got {lat_deg}")
    if not (math.isfinite(lon_deg) and -180.0 <= lon_deg <= 180.0):
        raise InputError(f"{what}: longitude must be within -180..180 deg, got {lon_deg}")


def check_survey_numbers(params: Any) -> None:
    """Every number of a :class:`missions.SurveyParams` finite; ``home`` on the Earth."""
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if not math.isfinite(value):
            raise InputError(f"{f.name} must be a finite number, got {value}")
    if params.home is not None:
        lat, lon = params.home
        check_latlon(float(lat), float(lon), "home")
