"""Where a hole is, in the words a rescuer reads out: a grid reference, a distance and a
bearing.

* :func:`mgrs_text` - the Military Grid Reference System square of a point to 1 m (PyPI
  ``mgrs``), spaced as it is read over the radio (``17T PJ 30378 34625``);
* :func:`range_bearing` - horizontal distance (m) and true bearing (degrees from north,
  clockwise) from one point to another, in the project's local metres
  (:class:`geotag.LocalFrame`, exact to centimetres over the few kilometres of a
  collapse site);
* :func:`bearing_name` - a bearing as the 16-point compass rose says it (``NE``).
"""

from __future__ import annotations

import math

from holescan.geotag import LocalFrame

__all__ = ["bearing_name", "mgrs_text", "range_bearing"]

_ROSE: tuple[str, ...] = ("N", "NNE", "NE", "ENE", "E", "ESE", "SE", "SSE")
_ROSE += ("S", "SSW", "SW", "WSW", "W", "WNW", "NW", "NNW")


def mgrs_text(lat_deg: float, lon_deg: float) -> str | None:
    """The MGRS reference of a point to 1 m, spaced for reading out; None where MGRS has
    none (beyond 84 N / 80 S it is UPS, which the library does not give) or for a point
    not on the Earth.

    Examples
    --------
    >>> mgrs_text(43.6532, -79.3832)
    '17T PJ 30378 34625'
    >>> mgrs_text(89.9, 0.0) is None
    True
    """
    if not (math.isfinite(lat_deg) and math.isfinite(lon_deg)):
        return None
    if not (-80.0 <= lat_deg <= 84.0 and -180.0 <= lon_deg <= 180.0):
        return None
    import mgrs  # the ground extra; imported when a page is served

    try:
        raw = mgrs.MGRS().toMGRS(lat_deg, lon_deg, MGRSPrecision=5)
    except Exception:  # mgrs raises its own error types for points it cannot place
        return None
    text = raw.decode() if isinstance(raw, bytes) else str(raw)
    zone, square, digits = text[:-12], text[-12:-10], text[-10:]
    return f"{zone} {square} {digits[:5]} {digits[5:]}"


def range_bearing(
    from_lat: float, from_lon: float, to_lat: float, to_lon: float
) -> tuple[float, float]:
    """(horizontal distance m, true bearing degrees 0..360) from the first point to the
    second.

    Examples
    --------
    >>> d, b = range_bearing(43.6532, -79.3832, 43.6532 + 1e-4, -79.3832)
    >>> round(d, 2), round(b, 1)
    (11.11, 0.0)
    """
    east, north = LocalFrame(from_lat, from_lon).to_en(to_lat, to_lon)
    e, n = float(east), float(north)
    return math.hypot(e, n), round(math.degrees(math.atan2(e, n)) % 360.0, 6) % 360.0


def bearing_name(bearing_deg: float) -> str:
    """The 16-point compass name of a bearing.

    >>> bearing_name(44.0), bearing_name(350.0)
    ('NE', 'N')
    """
    return _ROSE[round(bearing_deg / 22.5) % 16]
