"""Sun windows against NOAA's published solar calculations, and the polar cases.

Reference values: NOAA Global Monitoring Laboratory's solar calculator spreadsheet
``NOAA_Solar_Calculations_day.xls`` (https://gml.noaa.gov/grad/solcalc/calcdetails.html;
sunrise/sunset at the sun centre's geometric elevation -0.833 deg, elevation "corrected
for atmospheric refraction"), for its default case (40 N, 105 W, time zone -6, 2010-06-21)
and for 37.4219444 N, 122.0795833 W, time zone -8, 2023-09-21, as tabulated from the
spreadsheet in the test-suite of github.com/pyenergyplus/pysunNOAA (``tests/test_noaa.py``).
The spreadsheet gives sunrise/sunset as fractions of the local day; the elevation columns
are sampled every 6 minutes (first case) and every minute (second case); the window
edges below are the crossings of +-6 deg interpolated linearly between two samples.
"""

from __future__ import annotations

import datetime as dt

import pytest

from holescan.missions import (
    SunWindowError,
    check_flight,
    solar_elevation_deg,
    sun_day,
    sun_windows,
    sunrise_sunset,
)

_NS = 1_000_000_000
TOL_S = 120.0  # the task's bound: within 2 minutes of NOAA


def _utc_ns(text: str) -> int:
    return int(dt.datetime.fromisoformat(text).timestamp()) * _NS


def _day_fraction_ns(day: dt.date, fraction: float, tz_hours: float) -> int:
    """A NOAA spreadsheet time (fraction of the local day, fixed offset) -> UTC ns."""
    start = dt.datetime(
        day.year, day.month, day.day, tzinfo=dt.timezone(dt.timedelta(hours=tz_hours))
    )
    return int((start.timestamp() + fraction * 86400.0) * _NS)


def _crossing_ns(t0: str, e0: float, t1: str, e1: float) -> int:
    """Linear interpolation of the time a sampled elevation crosses +6 or -6 deg."""
    level = 6.0 if e0 > 0 else -6.0
    a, b = _utc_ns(t0), _utc_ns(t1)
    return round(a + (b - a) * (level - e0) / (e1 - e0))


# (lat, lon, local date, tz hours, NOAA sunrise fraction, NOAA sunset fraction)
BOULDER = (40.0, -105.0)  # the spreadsheet's default place
MOUNTAIN_VIEW = (37.4219444444444, -122.079583333333)
NOAA_RISE_SET = [
    (*BOULDER, dt.date(2010, 6, 21), -6, 0.230045084953299, 0.855658120381039),
    (*MOUNTAIN_VIEW, dt.date(2023, 9, 21), -8, 0.246693155717973, 0.755367063181474),
]


@pytest.mark.parametrize(("lat", "lon", "day", "tz", "rise", "sset"), NOAA_RISE_SET)
def test_sunrise_sunset_match_noaa(
    lat: float, lon: float, day: dt.date, tz: float, rise: float, sset: float
) -> None:
    got_rise, got_set = sunrise_sunset(lat, lon, day)
    assert abs(got_rise - _day_fraction_ns(day, rise, tz)) / _NS < TOL_S
    assert abs(got_set - _day_fraction_ns(day, sset, tz)) / _NS < TOL_S


# NOAA's refraction-corrected elevation samples around the +-6 deg crossings.
# 40 N 105 W, 2010-06-21, local = UTC-6: 04:54 -6.61873824277419, 05:00 -5.70383297563267,
# 06:06 5.11490902618878, 06:12 6.12407315254798, 19:48 6.74266941805119,
# 19:54 5.72602704943685, 21:00 -5.14127074415214, 21:06 -6.06559172435652.
# 37.42 N 122.08 W, 2023-09-21, local = UTC-8: 06:28 5.80760970560932, 06:29 6.00168214378279.
D1, D2 = dt.date(2010, 6, 21), dt.date(2023, 9, 21)
NOAA_EDGES = [
    (*BOULDER, D1, "dawn", "start",
     _crossing_ns("2010-06-21T10:54Z", -6.61873824277419, "2010-06-21T11:00Z", -5.70383297563267)),
    (*BOULDER, D1, "dawn", "end",
     _crossing_ns("2010-06-21T12:06Z", 5.11490902618878, "2010-06-21T12:12Z", 6.12407315254798)),
    (*BOULDER, D1, "dusk", "start",
     _crossing_ns("2010-06-22T01:48Z", 6.74266941805119, "2010-06-22T01:54Z", 5.72602704943685)),
    (*BOULDER, D1, "dusk", "end",
     _crossing_ns("2010-06-22T03:00Z", -5.14127074415214, "2010-06-22T03:06Z", -6.06559172435652)),
    (*MOUNTAIN_VIEW, D2, "dawn", "end",
     _crossing_ns("2023-09-21T14:28Z", 5.80760970560932, "2023-09-21T14:29Z", 6.00168214378279)),
]  # fmt: skip


@pytest.mark.parametrize(("lat", "lon", "day", "kind", "edge", "want_ns"), NOAA_EDGES)
def test_window_edges_match_noaa(
    lat: float, lon: float, day: dt.date, kind: str, edge: str, want_ns: int
) -> None:
    windows = sun_windows(lat, lon, day, min_elev_deg=-6.0, max_elev_deg=6.0)
    assert [w.kind for w in windows] == ["dawn", "dusk"]
    (w,) = [w for w in windows if w.kind == kind]
    got = w.start_t_unix_ns if edge == "start" else w.end_t_unix_ns
    assert abs(got - want_ns) / _NS < TOL_S


@pytest.mark.parametrize(
    ("lat", "lon", "when", "refraction", "noaa_deg"),
    [
        (40.0, -105.0, "2010-06-21T06:06Z", True, -25.2334819743467),
        (40.0, -105.0, "2010-06-21T06:06Z", False, -25.245718494866),
        (37.4219444444444, -122.079583333333, "2023-09-21T13:33Z", True, -5.17796026715717),
        (37.4219444444444, -122.079583333333, "2023-09-21T13:33Z", False, -5.24086479367834),
        (40.0, -105.0, "2010-06-21T19:00Z", True, 73.4384793439627),
    ],
)
def test_solar_elevation_matches_noaa(
    lat: float, lon: float, when: str, refraction: bool, noaa_deg: float
) -> None:
    got = solar_elevation_deg(lat, lon, _utc_ns(when), refraction=refraction)
    assert got == pytest.approx(noaa_deg, abs=0.02)


def test_sunrise_lies_in_the_dawn_window_southern_hemisphere() -> None:
    # Sydney, midsummer: dawn and dusk of the local day, sunrise inside the dawn window.
    day = sun_day(-33.8688, 151.2093, dt.date(2024, 12, 21))
    assert day.sunrise_t_unix_ns is not None
    assert day.sunset_t_unix_ns is not None
    dawn, dusk = day.windows
    assert (dawn.kind, dusk.kind) == ("dawn", "dusk")
    assert dawn.contains(day.sunrise_t_unix_ns)
    assert dusk.contains(day.sunset_t_unix_ns)
    assert 40 * 60 < dawn.duration_s < 90 * 60
    assert "sunrise 2024-12-21 05:" in day.describe(dt.timezone(dt.timedelta(hours=11)))


def test_polar_day_and_night_say_so() -> None:
    svalbard = (78.2232, 15.6267)  # Longyearbyen
    with pytest.raises(SunWindowError, match=r"does not set .* \(polar day\)"):
        sunrise_sunset(*svalbard, dt.date(2024, 6, 21))
    with pytest.raises(SunWindowError, match=r"stays above \+6\.0 deg all day \(polar day"):
        sun_windows(*svalbard, dt.date(2024, 6, 21))
    with pytest.raises(SunWindowError, match=r"does not rise .* \(polar night\)"):
        sunrise_sunset(*svalbard, dt.date(2024, 12, 21))
    with pytest.raises(SunWindowError, match=r"stays below -6\.0 deg all day \(polar night"):
        sun_windows(*svalbard, dt.date(2024, 12, 21))
    # sun_day reports the same in words instead of raising.
    day = sun_day(*svalbard, dt.date(2024, 6, 21))
    assert day.windows == ()
    assert "polar day" in day.note
    assert "polar day" in day.describe()


def test_midnight_sun_gives_one_low_sun_window_over_midnight() -> None:
    # Tromso at midsummer: the sun never sets but dips below +6 deg around midnight.
    lat, lon = 69.6492, 18.9553
    day = sun_day(lat, lon, dt.date(2024, 6, 21))
    assert day.sunrise_t_unix_ns is None
    assert "polar day" in day.note
    (w,) = day.windows
    assert w.kind == "low sun"
    # The night of the 21st: the window holds the local midnight that ends that day.
    local_midnight = _utc_ns("2024-06-22T00:00Z") - round(lon / 15.0 * 3600 * _NS)
    assert w.contains(local_midnight)
    lowest = solar_elevation_deg(lat, lon, local_midnight)
    assert -6.0 < lowest < 6.0


def test_band_must_be_ordered() -> None:
    from holescan.errors import InputError

    with pytest.raises(InputError, match="min < max"):
        sun_windows(40.0, -105.0, dt.date(2010, 6, 21), min_elev_deg=5.0, max_elev_deg=-5.0)


def test_check_flight() -> None:
    windows = sun_windows(40.0, -105.0, dt.date(2010, 6, 21))
    dawn = windows[0]
    assert check_flight(windows, 20 * 60).ok
    long = check_flight(windows, 3 * 3600)
    assert not long.ok
    assert "longer than every window" in long.message
    inside = dawn.start_t_unix_ns + 5 * 60 * _NS
    assert check_flight(windows, 20 * 60, inside).ok
    late = dawn.end_t_unix_ns - 5 * 60 * _NS
    res = check_flight(windows, 20 * 60, late)
    assert not res.ok
    assert "15 min after" in res.message
    noon = _utc_ns("2010-06-21T19:00Z")
    res = check_flight(windows, 20 * 60, noon)
    assert not res.ok
    assert "outside every sun window; next: dusk" in res.message
