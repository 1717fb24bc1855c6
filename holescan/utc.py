"""Times for people and files: one UTC formatter for every output (hole files, CoT events,
the flight log's damage report).

Every timestamp in holescan is an ``int`` of nanoseconds; here it becomes an aware
:class:`datetime.datetime` in UTC, or the ISO 8601 text ``YYYY-MM-DDTHH:MM:SS.mmmZ`` that
KML, GPX, GeoJSON and Cursor-on-Target all read: the time to the nearest microsecond (as
:meth:`datetime.datetime.fromtimestamp` gives it), shown to the millisecond (truncated).
Integer arithmetic: no float on the way.
"""

from __future__ import annotations

import datetime as dt

__all__ = ["utc_datetime", "utc_text"]

_EPOCH = dt.datetime(1970, 1, 1, tzinfo=dt.UTC)


def utc_datetime(t_unix_ns: int) -> dt.datetime:
    """An aware UTC datetime (to the nearest microsecond) of nanoseconds since the Unix epoch.

    Raises
    ------
    ValueError : outside the years 1..9999.

    Examples
    --------
    >>> utc_datetime(1_796_300_000_123_456_789)
    datetime.datetime(2026, 12, 3, 12, 13, 20, 123457, tzinfo=datetime.timezone.utc)
    """
    try:
        return _EPOCH + dt.timedelta(microseconds=(t_unix_ns + 500) // 1000)
    except OverflowError as err:
        raise ValueError(f"{t_unix_ns} ns since 1970 is not a date") from err


def utc_text(t: int | dt.datetime) -> str:
    """``YYYY-MM-DDTHH:MM:SS.mmmZ`` of nanoseconds since the Unix epoch (or of a datetime,
    converted to UTC).

    Raises
    ------
    ValueError : outside the years 1..9999.

    Examples
    --------
    >>> utc_text(1_796_300_000_999_499_999), utc_text(1_796_300_000_999_999_999)
    ('2026-12-03T12:13:20.999Z', '2026-12-03T12:13:21.000Z')
    >>> utc_text(dt.datetime(2026, 12, 3, 12, 30, tzinfo=dt.timezone(dt.timedelta(hours=1))))
    '2026-12-03T11:30:00.000Z'
    """
    d = utc_datetime(t) if isinstance(t, int) else t.astimezone(dt.UTC)
    return d.strftime("%Y-%m-%dT%H:%M:%S.") + f"{d.microsecond // 1000:03d}Z"
