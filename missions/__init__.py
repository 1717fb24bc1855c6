"""MAVLink missions and plan files: survey planning, sun windows, waypoint files, upload.

* :func:`plan_survey` - lawnmower survey of an area polygon for the nadir Xtion.
* :func:`sun_windows` / :func:`sun_day` / :func:`check_flight` - dawn/dusk windows.
* :func:`write_waypoints` and the per-format writers/readers - QGC ``.plan``, QGC WPL 110,
  KML, GeoJSON, GPX, generic over :class:`Waypoint` records (survey paths and found holes).
* :func:`upload_mission` / :func:`download_mission` - MAVLink mission protocol client;
  :class:`MissionReceiver` / :class:`MissionServer` - the vehicle's side (one
  implementation: the simulated autopilot's and the hole server's).
* :func:`write_hole_file` - found holes as GPX, KML/KMZ (thumbnails), GeoJSON, .plan, WPL.
* :class:`HoleMissionServer` - serves found holes live as a mission (component 191) and
  announces them by STATUSTEXT.
* :class:`SigningKey` - MAVLink 2 signing of the links to and from the ground station.
"""

from holescan.missions._files import read_area, read_waypoints, write_waypoints
from holescan.missions._geofiles import (
    read_geojson,
    read_gpx,
    read_kml,
    write_geojson,
    write_gpx,
    write_kml,
)
from holescan.missions._holecards import (
    CARD_PAYLOAD,
    CardAssembler,
    CardSender,
    card_facts,
    make_card,
    read_card,
)
from holescan.missions._holefiles import (
    HOLE_FORMATS,
    HOLE_SUFFIXES,
    HOLE_TIERS,
    HoleFormat,
    HoleTier,
    hole_description,
    hole_mission,
    hole_points,
    hole_properties,
    rank_holes,
    write_hole_file,
)
from holescan.missions._holeserver import (
    HoleMissionServer,
    MissionServerError,
    hole_statustext,
    hole_waypoints,
    radio_budget,
)
from holescan.missions._link import MavConnection, mavlink, mavutil, open_link, parser
from holescan.missions._protocol import (
    MAV_MISSION_ACCEPTED,
    MissionError,
    MissionRejectedError,
    MissionTimeoutError,
    UploadReport,
    connect,
    download_mission,
    upload_mission,
    waypoint_from_mission_item,
)
from holescan.missions._qgcfiles import read_plan, read_wpl, write_plan, write_wpl
from holescan.missions._signing import SigningKey
from holescan.missions._sun import (
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
from holescan.missions._survey import (
    XTION,
    Camera,
    SurveyParams,
    SurveyPlan,
    frame_around,
    plan_survey,
)
from holescan.missions._vehicle import MissionReceiver, MissionServer
from holescan.missions._waypoint import (
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
from holescan.missions.errors import MissionsError

__all__ = [
    "CARD_PAYLOAD",
    "HOLE_FORMATS",
    "HOLE_SUFFIXES",
    "HOLE_TIERS",
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
    "CardAssembler",
    "CardSender",
    "FlightCheck",
    "HoleFormat",
    "HoleMissionServer",
    "HoleTier",
    "MavConnection",
    "MissionError",
    "MissionReceiver",
    "MissionRejectedError",
    "MissionServer",
    "MissionServerError",
    "MissionTimeoutError",
    "MissionsError",
    "SigningKey",
    "SunDay",
    "SunWindow",
    "SunWindowError",
    "SurveyParams",
    "SurveyPlan",
    "UploadReport",
    "Waypoint",
    "card_facts",
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
    "make_card",
    "mavlink",
    "mavutil",
    "open_link",
    "parser",
    "plan_survey",
    "radio_budget",
    "rank_holes",
    "read_area",
    "read_card",
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
    "waypoint_from_mission_item",
    "write_geojson",
    "write_gpx",
    "write_hole_file",
    "write_kml",
    "write_plan",
    "write_waypoints",
    "write_wpl",
]
