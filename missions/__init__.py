"""MAVLink missions and plan files: survey planning, sun windows, waypoint files, upload.

* :func:`plan_survey` - lawnmower survey of an area polygon for the nadir Xtion.
* :func:`sun_windows` / :func:`sun_day` / :func:`check_flight` - dawn/dusk windows.
* :func:`write_waypoints` and the per-format writers/readers - QGC ``.plan``, QGC WPL 110,
  KML, GeoJSON, GPX, generic over :class:`Waypoint` records (survey paths and found holes).
* :func:`upload_mission` / :func:`download_mission` - MAVLink mission protocol client;
  :class:`MissionReceiver` / :class:`MissionServer` - the vehicle's side.
* :func:`write_hole_file` - found holes as GPX, KML/KMZ (thumbnails), GeoJSON, .plan, WPL.
* :class:`HoleMissionServer` - serves found holes live as a mission (component 191) and
  announces them by STATUSTEXT.
"""

from missions._files import read_area, read_waypoints, write_waypoints
from missions._geofiles import read_geojson, read_gpx, read_kml, write_geojson, write_gpx, write_kml
from missions._holefiles import (
    HOLE_FORMATS,
    HOLE_SUFFIXES,
    HoleFormat,
    hole_description,
    hole_mission,
    hole_points,
    hole_properties,
    rank_holes,
    write_hole_file,
)
from missions._holeserver import (
    HoleMissionServer,
    HoleWaypoint,
    MissionServerError,
    hole_statustext,
    hole_waypoints,
)
from missions._link import mavlink, mavutil, open_link, parser
from missions._protocol import (
    MAV_MISSION_ACCEPTED,
    MissionError,
    MissionReceiver,
    MissionRejectedError,
    MissionServer,
    MissionTimeoutError,
    UploadReport,
    connect,
    download_mission,
    upload_mission,
)
from missions._qgcfiles import read_plan, read_wpl, write_plan, write_wpl
from missions._sun import (
    SUNRISE_ELEVATION_DEG,
    FlightCheck,
    SunDay,
    SunWindow,
    SunWindowError,
    check_flight,
    local_solar_day,
    solar_elevation_deg,
    sun_day,
    sun_windows,
    sunrise_sunset,
)
from missions._survey import XTION, Camera, SurveyParams, SurveyPlan, frame_around, plan_survey
from missions._waypoint import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_RETURN_TO_LAUNCH,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    MAV_FRAME_MISSION,
    Area,
    Waypoint,
)

__all__ = [
    "HOLE_FORMATS",
    "HOLE_SUFFIXES",
    "MAV_CMD_DO_CHANGE_SPEED",
    "MAV_CMD_NAV_LAND",
    "MAV_CMD_NAV_RETURN_TO_LAUNCH",
    "MAV_CMD_NAV_TAKEOFF",
    "MAV_CMD_NAV_WAYPOINT",
    "MAV_FRAME_GLOBAL",
    "MAV_FRAME_GLOBAL_RELATIVE_ALT",
    "MAV_FRAME_MISSION",
    "MAV_MISSION_ACCEPTED",
    "SUNRISE_ELEVATION_DEG",
    "XTION",
    "Area",
    "Camera",
    "FlightCheck",
    "HoleFormat",
    "HoleMissionServer",
    "HoleWaypoint",
    "MissionError",
    "MissionReceiver",
    "MissionRejectedError",
    "MissionServer",
    "MissionServerError",
    "MissionTimeoutError",
    "SunDay",
    "SunWindow",
    "SunWindowError",
    "SurveyParams",
    "SurveyPlan",
    "UploadReport",
    "Waypoint",
    "check_flight",
    "connect",
    "download_mission",
    "frame_around",
    "hole_description",
    "hole_mission",
    "hole_points",
    "hole_properties",
    "hole_statustext",
    "hole_waypoints",
    "local_solar_day",
    "mavlink",
    "mavutil",
    "open_link",
    "parser",
    "plan_survey",
    "rank_holes",
    "read_area",
    "read_geojson",
    "read_gpx",
    "read_kml",
    "read_plan",
    "read_waypoints",
    "read_wpl",
    "solar_elevation_deg",
    "sun_day",
    "sun_windows",
    "sunrise_sunset",
    "upload_mission",
    "write_geojson",
    "write_gpx",
    "write_hole_file",
    "write_kml",
    "write_plan",
    "write_waypoints",
    "write_wpl",
]
