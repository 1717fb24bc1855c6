"""``holescan plan AREA``: plan a dawn/dusk lawnmower survey, write it, optionally upload it."""

from __future__ import annotations

import argparse
import datetime as dt
import logging
import time
from pathlib import Path

from holescan.errors import InputError
from holescan.missions import (
    SunWindowError,
    SurveyParams,
    check_flight,
    plan_survey,
    read_area,
    sun_day,
    upload_mission,
    write_waypoints,
)
from holescan.outputs import check_output, output_via_part

log = logging.getLogger("holescan.plan")


def _latlon(text: str) -> tuple[float, float]:
    try:
        lat, lon = (float(v) for v in text.replace(";", ",").split(","))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected LAT,LON, got {text!r}") from err
    return lat, lon  # range: checked by SurveyParams (one error line, never wrapped)


def _date(text: str) -> dt.date:
    try:
        return dt.date.fromisoformat(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected YYYY-MM-DD, got {text!r}") from err


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "plan",
        help="plan a dawn/dusk survey of an area; write .plan/WPL/KML/GeoJSON/GPX; upload",
        description="Lawnmower survey for the nadir Xtion over an area polygon (GeoJSON, KML, "
        "a text file of 'lat,lon' lines, or 'lat,lon;lat,lon;...'), with the sun windows.",
    )
    p.add_argument("area", help="area polygon: .geojson, .kml, text of lat,lon lines, or a string")
    p.add_argument("--altitude", type=float, default=2.5, help="metres above the rubble (2.5)")
    p.add_argument("--relief", type=float, default=0.5, help="rubble height variation +- m (0.5)")
    p.add_argument("--overlap", type=float, default=0.3, help="side overlap of lines (0.3)")
    p.add_argument("--speed", type=float, help="ground speed m/s (default: the largest allowed)")
    p.add_argument("--max-blur", type=float, default=2.0, help="motion blur limit, pixels (2)")
    p.add_argument("--margin", type=float, help="turn-around run-out past the area, m (auto)")
    p.add_argument("--heading", type=float, help="line direction, deg from north (auto)")
    p.add_argument("--home", type=_latlon, help="take-off LAT,LON (default: first waypoint)")
    p.add_argument("--home-amsl", type=float, default=0.0, help="home altitude AMSL, m")
    p.add_argument("--date", type=_date, help="flight date YYYY-MM-DD (local; default today)")
    p.add_argument("--takeoff", help="planned take-off time, ISO 8601 (default: now on upload)")
    p.add_argument("--tz", default="UTC", help="time zone for printed times, e.g. Europe/Rome")
    p.add_argument("--sun-min", type=float, default=-6.0, help="lowest sun elevation, deg (-6)")
    p.add_argument("--sun-max", type=float, default=6.0, help="highest sun elevation, deg (6)")
    p.add_argument("--out", type=Path, action="append",
                   help="output file, repeatable; type from the extension: .plan, .waypoints "
                   "(QGC WPL 110), .kml, .geojson, .gpx (default: survey.plan)")  # fmt: skip
    p.add_argument("--upload", metavar="LINK", help="upload over MAVLink, e.g. udpout:HOST:PORT")
    p.add_argument("--target-system", type=int, default=1, help="autopilot system id (1)")
    p.add_argument("--target-component", type=int, default=1, help="autopilot component (1)")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the autopilot")
    p.add_argument("--force", action="store_true", help="replace existing --out files")
    p.add_argument(
        "--outside-sun-window",
        action="store_true",
        help="upload even when the flight does not fit a sun window (infrared depth fails in sun)",
    )
    p.set_defaults(func=run)


def _zone(name: str) -> dt.tzinfo:
    if name.upper() == "UTC":
        return dt.UTC
    from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError) as err:
        raise InputError(f"unknown time zone {name!r} (use e.g. UTC or Europe/Rome)") from err


def _instant(text: str, tz: dt.tzinfo) -> int:
    try:
        t = dt.datetime.fromisoformat(text)
    except ValueError as err:
        raise InputError(
            f"--takeoff: expected ISO 8601 like 2024-06-21T19:30, got {text!r}"
        ) from err
    if t.tzinfo is None:
        t = t.replace(tzinfo=tz)
    return int(t.timestamp() * 1e9)


def _solar_date(t_unix_ns: int, lon_deg: float) -> dt.date:
    local_mean = t_unix_ns / 1e9 + lon_deg / 15.0 * 3600.0
    return dt.datetime.fromtimestamp(local_mean, tz=dt.UTC).date()


def run(args: argparse.Namespace) -> int:
    tz = _zone(args.tz)
    outs = args.out or [Path("survey.plan")]
    area_file = [args.area] if Path(args.area).is_file() else []
    for out in outs:  # before planning: an existing file only with --force, the area never
        check_output(out, inputs=area_file, force=args.force)
    area = read_area(args.area)
    params = SurveyParams(
        altitude_m=args.altitude,
        relief_m=args.relief,
        side_overlap=args.overlap,
        speed_m_s=args.speed,
        max_blur_px=args.max_blur,
        turn_margin_m=args.margin,
        heading_deg=args.heading,
        home=args.home,
        home_amsl_m=args.home_amsl,
    )
    plan = plan_survey(area, params)
    print(plan.summary())

    lat0, lon0 = plan.origin_deg
    takeoff_ns = _instant(args.takeoff, tz) if args.takeoff else None
    if args.date is not None:
        day = args.date
    else:
        day = _solar_date(takeoff_ns if takeoff_ns is not None else time.time_ns(), lon0)
    sun_kw = {"min_elev_deg": args.sun_min, "max_elev_deg": args.sun_max}
    sd = sun_day(lat0, lon0, day, **sun_kw)
    print(sd.describe(tz))
    fit = check_flight(sd.windows, plan.duration_s, takeoff_ns, tz)
    if fit.ok:
        print(f"sun: {fit.message}")
    else:
        log.warning("sun: %s", fit.message)

    items = plan.mission_items()
    for out in outs:
        with output_via_part(out, inputs=area_file, force=args.force) as tmp:
            write_waypoints(tmp, items, plan.home, name="holescan survey", area=area)
        print(f"wrote {out}")

    if args.upload:
        when = takeoff_ns if takeoff_ns is not None else time.time_ns()
        up_day = _solar_date(when, lon0)
        up_windows = sd.windows if up_day == day else sun_day(lat0, lon0, up_day, **sun_kw).windows
        now_fit = check_flight(up_windows, plan.duration_s, when, tz)
        if not now_fit.ok:
            if not args.outside_sun_window:
                raise SunWindowError(
                    f"not uploading: {now_fit.message}; --outside-sun-window uploads anyway"
                )
            log.warning(
                "uploading outside a sun window (--outside-sun-window): %s", now_fit.message
            )
        report = upload_mission(
            args.upload,
            items,
            plan.home,
            target_system=args.target_system,
            target_component=args.target_component,
            heartbeat_timeout_s=args.timeout,
        )
        print(
            f"uploaded {report.items} items to {args.upload} in {report.elapsed_s:.1f} s "
            f"({report.resends} resends)"
        )
    return 0
