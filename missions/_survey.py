"""Lawnmower survey over an area polygon for a nadir-looking Xtion (pure: records in, records out).

The plan is made in a local east-north (ENU) tangent plane around the area's centroid
(``pymap3d``), so a polygon across a UTM zone edge or the antimeridian is planned like any
other. Geometry with ``shapely``.

How the numbers are chosen (all in :class:`SurveyParams`):

* **altitude** above home (the rubble): the rubble's top and bottom (``altitude +- relief``)
  must both lie in the sensor's useful range (Xtion 0.8-3.5 m).
* **line spacing** = (1 - side overlap) x footprint width at that altitude, and never more
  than the footprint width on the rubble's top (``altitude - relief``), so peaks are not
  missed. The camera's wide axis (58 deg) looks across the track.
* **speed** bounded by consecutive-frame overlap at ``fps`` and by motion blur (pixels
  moved during one exposure, on the nearest rubble) and by the vehicle's limit.
* **turn margin**: each line runs on past the area (at least half a footprint, so slanted
  edges are covered, and at least the braking distance); no waypoint is further than that
  from the polygon.
* **heading**: by default the one (among the hull's edge directions and every 5 deg) that
  gives the shortest estimated flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from holescan.errors import InputError
from holescan.geotag import LocalFrame
from holescan.missions._checks import check_survey_numbers
from holescan.missions._sweep import (
    check_area,
    estimate_flight,
    heading_candidates,
    order_lines,
    polygon_enu,
    sweep_lines,
    validate_polygon,
)
from holescan.missions._waypoint import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_RETURN_TO_LAUNCH,
    MAV_CMD_NAV_TAKEOFF,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_MISSION,
    Area,
    Waypoint,
)

if TYPE_CHECKING:
    pass

__all__ = ["XTION", "Camera", "SurveyParams", "SurveyPlan", "frame_around", "plan_survey"]


@dataclass(frozen=True)
class Camera:
    """A nadir-looking depth camera: what the planner needs to know.

    hfov_deg, vfov_deg : field of view across the image width / height, degrees.
    fps : frame rate, Hz. min_range_m, max_range_m : useful depth range, metres.
    exposure_s : exposure time assumed for motion blur (the RGB camera at dusk is the
        slow one), seconds.
    """

    name: str = "Asus Xtion Pro"
    hfov_deg: float = 58.0
    vfov_deg: float = 45.0
    width_px: int = 640
    height_px: int = 480
    fps: float = 30.0
    min_range_m: float = 0.8
    max_range_m: float = 3.5
    exposure_s: float = 0.010

    def footprint_m(self, range_m: float) -> tuple[float, float]:
        """``(across, along)`` size of the view on a flat surface ``range_m`` below, metres.

        The image width (``hfov``) lies across the track, its height along it.
        """
        return (
            2.0 * range_m * math.tan(math.radians(self.hfov_deg) / 2.0),
            2.0 * range_m * math.tan(math.radians(self.vfov_deg) / 2.0),
        )

    @property
    def focal_along_px(self) -> float:
        """Focal length along the track (image rows), pixels."""
        return (self.height_px / 2.0) / math.tan(math.radians(self.vfov_deg) / 2.0)


XTION = Camera()


@dataclass(frozen=True)
class SurveyParams:
    """Everything that shapes a survey.

    altitude_m : flight height above home (the rubble), metres.
    relief_m : the rubble's surface lies within ``+- relief_m`` of home's level.
    side_overlap : fraction of the footprint width shared by neighbouring lines.
    frame_overlap : minimum fraction of the footprint length shared by consecutive frames.
    max_blur_px : largest image motion during one exposure, pixels.
    speed_m_s : ground speed; None = the largest the bounds allow (rounded down to 0.05).
    max_speed_m_s : the vehicle's own limit for this kind of flight.
    turn_margin_m : run-out past the area at each line end; None = automatic.
    heading_deg : direction of the lines, degrees clockwise from north; None = best.
    accel_m_s2, climb_m_s : for the flight-time estimate (stop at each waypoint; climb and
        descend vertically at home).
    home : (lat_deg, lon_deg) of take-off; None = the first waypoint.
    home_amsl_m : home's altitude above mean sea level (written as the planned home).
    max_extent_m : refuse larger areas (split them).
    """

    altitude_m: float = 2.5
    relief_m: float = 0.5
    side_overlap: float = 0.3
    frame_overlap: float = 0.8
    max_blur_px: float = 2.0
    speed_m_s: float | None = None
    max_speed_m_s: float = 2.0
    turn_margin_m: float | None = None
    heading_deg: float | None = None
    accel_m_s2: float = 1.0
    climb_m_s: float = 0.5
    home: tuple[float, float] | None = None
    home_amsl_m: float = 0.0
    max_extent_m: float = 2000.0
    camera: Camera = field(default=XTION)

    def __post_init__(self) -> None:
        check_survey_numbers(self)

    def altitude_band(self) -> tuple[float, float]:
        """Lowest and highest altitude that keep the rubble in the sensor's range, metres."""
        return (
            self.camera.min_range_m + self.relief_m,
            self.camera.max_range_m - self.relief_m,
        )

    def speed_limits(self) -> dict[str, float]:
        """Upper speed bounds, m/s: ``frame_overlap``, ``blur`` and ``vehicle``."""
        cam = self.camera
        nearest = self.altitude_m - self.relief_m
        along = cam.footprint_m(nearest)[1]
        return {
            "frame_overlap": (1.0 - self.frame_overlap) * along * cam.fps,
            "blur": self.max_blur_px * nearest / (cam.focal_along_px * cam.exposure_s),
            "vehicle": self.max_speed_m_s,
        }

    def check(self) -> None:
        """Raise :class:`InputError` saying what to change when the parameters cannot work."""
        lo, hi = self.altitude_band()
        cam = self.camera
        if not math.isfinite(self.altitude_m) or not lo <= self.altitude_m <= hi:
            if lo > hi:
                raise InputError(
                    f"rubble relief +-{self.relief_m:g} m does not fit the {cam.name}'s "
                    f"{cam.min_range_m:g}-{cam.max_range_m:g} m range at any altitude"
                )
            raise InputError(
                f"altitude {self.altitude_m:g} m puts the rubble (+-{self.relief_m:g} m) "
                f"outside the {cam.name}'s useful range {cam.min_range_m:g}-"
                f"{cam.max_range_m:g} m: choose {lo:.2f}-{hi:.2f} m"
            )
        if not 0.0 <= self.side_overlap <= 0.9:
            raise InputError(f"side overlap must be within 0..0.9, got {self.side_overlap}")
        if not 0.0 <= self.frame_overlap <= 0.99:
            raise InputError(f"frame overlap must be within 0..0.99, got {self.frame_overlap}")
        if self.relief_m < 0 or self.max_blur_px <= 0 or self.accel_m_s2 <= 0:
            raise InputError("relief must be >= 0, blur and acceleration > 0")
        if self.climb_m_s <= 0 or self.max_speed_m_s <= 0:
            raise InputError("climb rate and vehicle speed limit must be > 0")
        if self.speed_m_s is not None:
            limits = self.speed_limits()
            bound = min(limits.values())
            if not (math.isfinite(self.speed_m_s) and 0.0 < self.speed_m_s <= bound + 1e-9):
                which = min(limits, key=lambda k: limits[k])
                raise InputError(
                    f"speed {self.speed_m_s:g} m/s is outside 0..{bound:.2f} m/s "
                    f"(limited by {which.replace('_', ' ')} at {self.altitude_m:g} m)"
                )


def frame_around(area: Area) -> LocalFrame:
    """A local frame at the centre of the area's vertices' hull (found in a first frame at its
    first vertex; the hull's centroid is defined even for an invalid polygon)."""
    from shapely.geometry import MultiPoint

    first = LocalFrame(*area.outer[0])
    lat, lon = zip(*area.outer, strict=True)
    e, n = first.to_en(lat, lon)
    c = MultiPoint(np.column_stack([e, n])).convex_hull.centroid
    if c.is_empty:
        return first
    lat0, lon0 = first.to_geodetic(c.x, c.y)
    return LocalFrame(float(lat0), float(lon0))


@dataclass(frozen=True)
class SurveyPlan:
    """A planned survey: lines, speeds, the estimates, and the mission items to fly it.

    lines : per line, its (start, end) waypoints in flight order.
    heading_deg : direction of the lines, clockwise from north (0..180).
    line_spacing_m, footprint_m (across, along at the flight altitude), turn_margin_m.
    speed_m_s : commanded ground speed; speed_limits_m_s : the bounds it respects.
    distance_m : home -> lines -> home, horizontal; duration_s : estimated flight time
        (climb, transit, lines, a stop at each waypoint, descent).
    area_m2 : the polygon's area.
    """

    area: Area
    params: SurveyParams
    origin_deg: tuple[float, float]
    heading_deg: float
    line_spacing_m: float
    footprint_m: tuple[float, float]
    turn_margin_m: float
    speed_m_s: float
    speed_limits_m_s: dict[str, float]
    home: Waypoint
    lines: tuple[tuple[Waypoint, Waypoint], ...]
    distance_m: float
    duration_s: float
    area_m2: float

    @property
    def path(self) -> tuple[Waypoint, ...]:
        """The line start/end waypoints in flight order."""
        return tuple(w for line in self.lines for w in line)

    def mission_items(self) -> list[Waypoint]:
        """Items to upload after home: take-off, set speed, the lines, return to launch."""
        alt = self.params.altitude_m
        takeoff = Waypoint(
            self.home.lat_deg,
            self.home.lon_deg,
            alt,
            name="takeoff",
            command=MAV_CMD_NAV_TAKEOFF,
            params=(0.0, 0.0, 0.0, float("nan")),
        )
        speed = Waypoint(
            0.0,
            0.0,
            0.0,
            name=f"speed {self.speed_m_s:.2f} m/s",
            command=MAV_CMD_DO_CHANGE_SPEED,
            frame=MAV_FRAME_MISSION,
            params=(1.0, self.speed_m_s, -1.0, 0.0),
        )
        rtl = Waypoint(
            0.0, 0.0, 0.0, name="rtl", command=MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=MAV_FRAME_MISSION
        )
        return [takeoff, speed, *self.path, rtl]

    def summary(self) -> str:
        """A few lines for a ground crew."""
        lim = self.speed_limits_m_s
        across, along = self.footprint_m
        p = self.params
        return "\n".join(
            [
                f"survey: {len(self.lines)} lines at heading {self.heading_deg:.0f} deg, "
                f"spacing {self.line_spacing_m:.2f} m; footprint {across:.2f} x {along:.2f} m "
                f"at {p.altitude_m:g} m (side overlap {p.side_overlap:.0%})",
                f"speed {self.speed_m_s:.2f} m/s (limits: blur {lim['blur']:.2f}, frame "
                f"overlap {lim['frame_overlap']:.2f}, vehicle {lim['vehicle']:.2f} m/s); "
                f"turn margin {self.turn_margin_m:.2f} m",
                f"area {self.area_m2:.0f} m2; distance {self.distance_m:.0f} m; "
                f"estimated flight {self.duration_s / 60:.1f} min",
            ]
        )


def plan_survey(area: Area, params: SurveyParams | None = None) -> SurveyPlan:
    """Plan a lawnmower survey over ``area``.

    Raises
    ------
    InputError
        Self-intersecting or empty polygon, altitude outside the sensor's range, speed
        above its bounds, an area too large: the message says what to change.
    """
    params = params if params is not None else SurveyParams()
    params.check()
    check_area(area)
    frame = frame_around(area)
    poly = polygon_enu(area, frame)
    validate_polygon(poly, frame, params.max_extent_m)

    cam = params.camera
    across, along = cam.footprint_m(params.altitude_m)
    across_top = cam.footprint_m(params.altitude_m - params.relief_m)[0]
    spacing = min((1.0 - params.side_overlap) * across, across_top)
    limits = params.speed_limits()
    bound = min(limits.values())
    speed = params.speed_m_s if params.speed_m_s is not None else math.floor(bound * 20) / 20
    if speed <= 0:
        speed = bound
    braking = speed * speed / (2.0 * params.accel_m_s2)
    auto_margin = max(1.0, across / 2.0, braking)
    if params.turn_margin_m is None:
        margin = auto_margin
    elif params.turn_margin_m + 1e-9 < max(across / 2.0, braking):
        raise InputError(
            f"turn margin {params.turn_margin_m:g} m is too short: at least "
            f"{max(across / 2.0, braking):.2f} m (half the footprint width, the braking "
            "distance) keeps slanted edges covered"
        )
    else:
        margin = params.turn_margin_m

    home_enu: tuple[float, float] | None = None
    if params.home is not None:
        he, hn = frame.to_en(params.home[0], params.home[1])
        home_enu = (float(he), float(hn))

    headings = (
        [params.heading_deg % 180.0] if params.heading_deg is not None else heading_candidates(poly)
    )
    # Inner chords of the arcs: every point of ``reach`` is within ``margin`` of the area.
    reach = poly.buffer(margin * (1.0 - 1e-6), quad_segs=16)
    best: tuple[float, float, list[tuple[float, float, float]]] | None = None
    for h in headings:
        lines = sweep_lines(poly, reach, h, across, spacing, margin)
        pairs = order_lines(lines, h, None)
        pts = [p for pair in pairs for p in pair]
        _, t = estimate_flight(
            pts,
            speed,
            altitude_m=params.altitude_m,
            climb_m_s=params.climb_m_s,
            accel_m_s2=params.accel_m_s2,
        )
        if best is None or t < best[0] - 1e-6:
            best = (t, h, lines)
    assert best is not None
    _, heading, lines = best
    pairs = order_lines(lines, heading, home_enu)
    flat = [p for pair in pairs for p in pair]
    if home_enu is None:
        home_enu = flat[0]
    dist, duration = estimate_flight(
        [home_enu, *flat, home_enu],
        speed,
        altitude_m=params.altitude_m,
        climb_m_s=params.climb_m_s,
        accel_m_s2=params.accel_m_s2,
    )

    e = np.array([p[0] for p in flat] + [home_enu[0]])
    n = np.array([p[1] for p in flat] + [home_enu[1]])
    lat, lon = frame.to_geodetic(e, n)
    home = Waypoint(
        float(lat[-1]), float(lon[-1]), params.home_amsl_m, name="home", frame=MAV_FRAME_GLOBAL
    )
    out_lines = []
    for k, ((sx, sy), (ex, ey)) in enumerate(pairs):
        yaw = math.degrees(math.atan2(ex - sx, ey - sy)) % 360.0
        ends = []
        for j, role in enumerate(("start", "end")):
            i = 2 * k + j
            ends.append(
                Waypoint(
                    float(lat[i]),
                    float(lon[i]),
                    params.altitude_m,
                    name=f"L{k + 1:02d} {role}",
                    description=f"survey line {k + 1} of {len(pairs)}, {role}",
                    properties={"line": k + 1, "end": role, "yaw_deg": round(yaw, 2)},
                    params=(0.0, 0.0, 0.0, round(yaw, 2)),
                )
            )
        out_lines.append((ends[0], ends[1]))
    return SurveyPlan(
        area=area,
        params=params,
        origin_deg=(frame.lat0_deg, frame.lon0_deg),
        heading_deg=heading,
        line_spacing_m=spacing,
        footprint_m=(across, along),
        turn_margin_m=margin,
        speed_m_s=speed,
        speed_limits_m_s=limits,
        home=home,
        lines=tuple(out_lines),
        distance_m=dist,
        duration_s=duration,
        area_m2=float(poly.area),
    )
