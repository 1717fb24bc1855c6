"""When to fly: dawn and dusk windows by solar elevation (``astral``, NOAA's algorithm).

The Xtion measures depth with a projected infrared pattern that direct sunlight drowns,
while its RGB camera still needs some light. So holescan flies when the sun is low:
by default between -6 deg (end of civil twilight) and +6 deg of apparent elevation.

Times are ``int`` nanoseconds since the Unix epoch (UTC). A "day" is the local *solar*
day of the area: from local mean midnight (UTC + longitude/15 h) for 24 h, so no time-zone
database is needed and the dusk of a date is that evening's, wherever the area is.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

from holescan.errors import InputError
from holescan.missions.errors import SunWindowError
from holescan.utc import utc_datetime

__all__ = [
    "SUNRISE_ELEVATION_DEG",
    "FlightCheck",
    "SunDay",
    "SunWindow",
    "SunWindowError",
    "check_flight",
    "local_solar_day",
    "solar_elevation_deg",
    "sun_day",
    "sun_windows",
    "sunrise_sunset",
]

SUNRISE_ELEVATION_DEG = -0.833
"""Geometric elevation of the sun's centre at sunrise/sunset (NOAA: refraction + radius)."""

_NS = 1_000_000_000
_SCAN_STEP_NS = 60 * _NS
_TOL_NS = _NS // 2

WindowKind = Literal["dawn", "dusk", "low sun"]


@dataclass(frozen=True)
class SunWindow:
    """An interval when the sun's elevation is inside the wanted band.

    kind : "dawn" (sun rising), "dusk" (setting) or "low sun" (the sun passes a
        minimum inside the band, e.g. a midsummer night near the polar circle).
    start_t_unix_ns, end_t_unix_ns : UTC, ns since the Unix epoch.
    """

    kind: WindowKind
    start_t_unix_ns: int
    end_t_unix_ns: int

    @property
    def duration_s(self) -> float:
        return (self.end_t_unix_ns - self.start_t_unix_ns) / _NS

    def contains(self, t_unix_ns: int) -> bool:
        return self.start_t_unix_ns <= t_unix_ns <= self.end_t_unix_ns

    def describe(self, tz: dt.tzinfo = dt.UTC) -> str:
        a, b = _to_dt(self.start_t_unix_ns, tz), _to_dt(self.end_t_unix_ns, tz)
        minutes = self.duration_s / 60
        return f"{self.kind} {a:%Y-%m-%d %H:%M}-{b:%H:%M} {_tzname(a)} ({minutes:.0f} min)"


@dataclass(frozen=True)
class SunDay:
    """Sun facts for one place and local solar day (for printing and checks).

    sunrise_t_unix_ns, sunset_t_unix_ns : None when the sun does not rise/set that day.
    note : a sentence for polar day/night or a day without windows, else "".
    """

    lat_deg: float
    lon_deg: float
    day: dt.date
    min_elev_deg: float
    max_elev_deg: float
    sunrise_t_unix_ns: int | None
    sunset_t_unix_ns: int | None
    windows: tuple[SunWindow, ...]
    note: str = ""

    def describe(self, tz: dt.tzinfo = dt.UTC) -> str:
        """Multi-line text: sunrise, sunset, windows."""
        where = f"{self.lat_deg:.5f}, {self.lon_deg:.5f}"
        lines = [f"sun on {self.day.isoformat()} (local solar day) at {where}:"]
        for label, t in (("sunrise", self.sunrise_t_unix_ns), ("sunset", self.sunset_t_unix_ns)):
            if t is not None:
                lines.append(
                    f"  {label} {_to_dt(t, tz):%Y-%m-%d %H:%M:%S} {_tzname(_to_dt(t, tz))}"
                )
        band = f"{self.min_elev_deg:+.1f}..{self.max_elev_deg:+.1f} deg"
        if self.windows:
            for w in self.windows:
                lines.append(f"  window (sun {band}): {w.describe(tz)}")
        if self.note:
            lines.append(f"  {self.note}")
        return "\n".join(lines)


@dataclass(frozen=True)
class FlightCheck:
    """Whether a flight of a given length fits a window; ``message`` says why."""

    ok: bool
    message: str
    window: SunWindow | None = None


def _to_dt(t_unix_ns: int, tz: dt.tzinfo = dt.UTC) -> dt.datetime:
    return utc_datetime(t_unix_ns).astimezone(tz)


def _tzname(t: dt.datetime) -> str:
    name = t.tzname() or ""
    return "UTC" if name in {"UTC", "UTC+00:00"} else name


#: Days the sun code handles: it looks one day either side of the local day.
_FIRST_DAY, _LAST_DAY = dt.date(1, 1, 2), dt.date(9999, 12, 30)


def _check_place(lat_deg: float, lon_deg: float, day: dt.date | None = None) -> None:
    if day is not None and not _FIRST_DAY <= day <= _LAST_DAY:
        raise InputError(
            f"date {day.isoformat()} is outside {_FIRST_DAY.isoformat()}..{_LAST_DAY.isoformat()}"
        )
    if not (math.isfinite(lat_deg) and -90.0 <= lat_deg <= 90.0):
        raise InputError(f"latitude must be within -90..90 deg, got {lat_deg}")
    if not (math.isfinite(lon_deg) and -180.0 <= lon_deg <= 180.0):
        raise InputError(f"longitude must be within -180..180 deg, got {lon_deg}")


def local_solar_day(lon_deg: float, day: dt.date) -> tuple[int, int]:
    """``(start, end)`` of ``day`` in local mean solar time at ``lon_deg``, UTC ns."""
    midnight_utc = dt.datetime(day.year, day.month, day.day, tzinfo=dt.UTC)
    start = int(midnight_utc.timestamp()) * _NS - round(lon_deg / 15.0 * 3600 * _NS)
    return start, start + 86_400 * _NS


def solar_elevation_deg(
    lat_deg: float, lon_deg: float, t_unix_ns: int, *, refraction: bool = True
) -> float:
    """Elevation of the sun's centre, degrees (NOAA algorithm via ``astral``).

    refraction : add NOAA's atmospheric refraction (the apparent elevation NOAA's solar
        calculator shows); False gives the geometric elevation.
    """
    from astral import Observer
    from astral.sun import elevation

    when = _to_dt(t_unix_ns)
    return float(elevation(Observer(lat_deg, lon_deg), when, with_refraction=refraction))


def _crossings(
    f: Callable[[int], float], start_ns: int, end_ns: int, levels: Sequence[float]
) -> list[tuple[int, int, bool]]:
    """Times in [start, end] where ``f`` crosses each level: (t, level index, rising).

    ``f`` is sampled every minute (one sampling shared by all levels), then each sign
    change is solved to half a second by scipy's Brent root finder (``brentq``; the
    minute holds one crossing: the sun's elevation turns at most twice a day).
    """
    from scipy.optimize import brentq

    times = [*list(range(start_ns, end_ns, _SCAN_STEP_NS)), end_ns]
    values = [f(t) for t in times]
    out = []
    for index, level in enumerate(levels):
        for k in range(len(times) - 1):
            v0, v1 = values[k] - level, values[k + 1] - level
            if (v0 < 0.0) == (v1 < 0.0):
                continue
            if v0 == 0.0 or v1 == 0.0:  # on the level at a sample
                t = times[k] if v0 == 0.0 else times[k + 1]
            else:
                t0 = times[k]  # solved in seconds from the minute's start: floats stay exact

                def g(x: float, t0: int = t0, level: float = level) -> float:
                    return f(t0 + round(x * _NS)) - level

                dt_s = (times[k + 1] - t0) / _NS
                t = t0 + round(float(brentq(g, 0.0, dt_s, xtol=_TOL_NS / _NS)) * _NS)
            out.append((t, index, v1 >= 0.0))
    return sorted(out)


def sunrise_sunset(lat_deg: float, lon_deg: float, day: dt.date) -> tuple[int, int]:
    """Sunrise and sunset of the local solar ``day`` (NOAA definition), UTC ns.

    Sunrise/sunset is when the sun's centre is at geometric elevation -0.833 deg (NOAA's
    solar calculator). Raises :class:`SunWindowError` with a clear message on polar
    day or night.
    """
    _check_place(lat_deg, lon_deg, day)
    start, end = local_solar_day(lon_deg, day)

    def f(t: int) -> float:
        return solar_elevation_deg(lat_deg, lon_deg, t, refraction=False)

    cross = _crossings(f, start, end, [SUNRISE_ELEVATION_DEG])
    rises = [t for t, _, rising in cross if rising]
    sets = [t for t, _, rising in cross if not rising]
    if not rises or not sets:
        noon_elev = max(f(start + k * 3600 * _NS) for k in range(25))
        where = f"{lat_deg:.3f}, {lon_deg:.3f} on {day.isoformat()}"
        if not cross and noon_elev > SUNRISE_ELEVATION_DEG:
            raise SunWindowError(f"the sun does not set at {where} (polar day)")
        if not cross:
            raise SunWindowError(f"the sun does not rise at {where} (polar night)")
        missing = "rise" if not rises else "set"
        raise SunWindowError(f"the sun does not {missing} during the local day at {where}")
    return rises[0], sets[-1]


def sun_windows(
    lat_deg: float,
    lon_deg: float,
    day: dt.date,
    *,
    min_elev_deg: float = -6.0,
    max_elev_deg: float = 6.0,
    refraction: bool = True,
) -> tuple[SunWindow, ...]:
    """Intervals of the local solar ``day`` with ``min_elev_deg <= elevation <= max_elev_deg``.

    A window that runs over local midnight is kept whole and belongs to the evening it
    starts in. Raises :class:`SunWindowError` (with the reason: polar day, polar night,
    band never reached) when there is none.
    """
    _check_place(lat_deg, lon_deg, day)
    if not min_elev_deg < max_elev_deg:
        raise InputError(
            f"sun band must have min < max elevation, got {min_elev_deg}..{max_elev_deg} deg"
        )
    day_start, day_end = local_solar_day(lon_deg, day)
    start, end = day_start - 43_200 * _NS, day_end + 43_200 * _NS

    def f(t: int) -> float:
        return solar_elevation_deg(lat_deg, lon_deg, t, refraction=refraction)

    events = _crossings(f, start, end, [min_elev_deg, max_elev_deg])
    inside = min_elev_deg <= f(start) <= max_elev_deg
    w_start = start if inside else None
    entered_rising = False
    windows: list[SunWindow] = []
    for t, which, rising in events:
        # which: 0 = the lower edge, 1 = the upper edge of the band.
        enters = (which == 0 and rising) or (which == 1 and not rising)
        if enters and w_start is None:
            w_start, entered_rising = t, rising
        elif not enters and w_start is not None:
            left_rising = rising
            kind: WindowKind
            if w_start == start:
                kind = "dawn" if left_rising else "dusk"
            elif entered_rising == left_rising:
                kind = "dawn" if rising else "dusk"
            else:
                kind = "low sun"
            windows.append(SunWindow(kind, w_start, t))
            w_start = None
    if w_start is not None:
        windows.append(SunWindow("low sun", w_start, end))
    # A window cut by the scan's ends (the sun stays in the band for over a day, near
    # the poles) is reported for this day only.
    clipped = [
        SunWindow(
            w.kind,
            day_start if w.start_t_unix_ns == start else w.start_t_unix_ns,
            day_end if w.end_t_unix_ns == end else w.end_t_unix_ns,
        )
        for w in windows
    ]
    # A window belongs to the day holding its middle, with the day's edges moved one hour
    # later: a window around local midnight (low sun all night near the polar circle) is
    # centred within minutes of midnight and belongs to the evening it starts in.
    shift = 3600 * _NS
    mine = tuple(
        w
        for w in clipped
        if day_start + shift <= (w.start_t_unix_ns + w.end_t_unix_ns) // 2 < day_end + shift
    )
    if not mine:
        raise SunWindowError(
            _no_window_reason(f, day_start, lat_deg, lon_deg, day, min_elev_deg, max_elev_deg)
        )
    return mine


def _no_window_reason(
    f: Callable[[int], float],
    day_start: int,
    lat_deg: float,
    lon_deg: float,
    day: dt.date,
    lo: float,
    hi: float,
) -> str:
    elevs = [f(day_start + k * 600 * _NS) for k in range(145)]
    where = f"{lat_deg:.3f}, {lon_deg:.3f} on {day.isoformat()}"
    band = f"{lo:+.1f}..{hi:+.1f} deg"
    if min(elevs) > hi:
        return (
            f"no dawn/dusk window at {where}: the sun stays above {hi:+.1f} deg all day "
            f"(polar day; lowest {min(elevs):+.1f} deg)"
        )
    if max(elevs) < lo:
        return (
            f"no dawn/dusk window at {where}: the sun stays below {lo:+.1f} deg all day "
            f"(polar night; highest {max(elevs):+.1f} deg)"
        )
    return f"no window with the sun at {band} at {where}"


def sun_day(
    lat_deg: float,
    lon_deg: float,
    day: dt.date,
    *,
    min_elev_deg: float = -6.0,
    max_elev_deg: float = 6.0,
    refraction: bool = True,
) -> SunDay:
    """Sunrise, sunset and windows for printing; polar cases become a ``note``, not errors."""
    _check_place(lat_deg, lon_deg, day)
    notes = []
    try:
        rise: int | None
        sset: int | None
        rise, sset = sunrise_sunset(lat_deg, lon_deg, day)
    except SunWindowError as err:
        rise = sset = None
        notes.append(str(err))
    try:
        windows = sun_windows(
            lat_deg,
            lon_deg,
            day,
            min_elev_deg=min_elev_deg,
            max_elev_deg=max_elev_deg,
            refraction=refraction,
        )
    except SunWindowError as err:
        windows = ()
        notes.append(str(err))
    return SunDay(
        lat_deg, lon_deg, day, min_elev_deg, max_elev_deg, rise, sset, windows, "; ".join(notes)
    )


def check_flight(
    windows: Sequence[SunWindow],
    duration_s: float,
    takeoff_t_unix_ns: int | None = None,
    tz: dt.tzinfo = dt.UTC,
) -> FlightCheck:
    """Does a flight of ``duration_s`` fit a window?

    Without a take-off time: is any window at least that long. With one: does the window
    holding the take-off time last until landing.
    """
    if not windows:
        return FlightCheck(False, "no sun window on that day")
    minutes = duration_s / 60.0
    if takeoff_t_unix_ns is None:
        fitting = [w for w in windows if w.duration_s >= duration_s]
        if fitting:
            return FlightCheck(
                True, f"the {minutes:.0f} min flight fits the {fitting[0].describe(tz)}", fitting[0]
            )
        longest = max(windows, key=lambda w: w.duration_s)
        return FlightCheck(
            False,
            f"the {minutes:.0f} min flight is longer than every window "
            f"(longest: {longest.describe(tz)}); split the area",
        )
    takeoff = _to_dt(takeoff_t_unix_ns, tz)
    landing_ns = takeoff_t_unix_ns + round(duration_s * _NS)
    for w in windows:
        if w.contains(takeoff_t_unix_ns):
            if landing_ns <= w.end_t_unix_ns:
                return FlightCheck(True, f"take-off {takeoff:%H:%M} fits the {w.describe(tz)}", w)
            late = (landing_ns - w.end_t_unix_ns) / _NS / 60.0
            return FlightCheck(
                False,
                f"take-off {takeoff:%H:%M} {_tzname(takeoff)} lands {late:.0f} min after "
                f"the {w.describe(tz)} ends",
                w,
            )
    later = [w for w in windows if w.start_t_unix_ns > takeoff_t_unix_ns]
    hint = f"; next: {later[0].describe(tz)}" if later else ""
    return FlightCheck(
        False,
        f"take-off {takeoff:%Y-%m-%d %H:%M} {_tzname(takeoff)} is outside every sun window{hint}",
    )
