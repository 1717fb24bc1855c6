"""``holescan ground``: the live ground station app beside the main ground station.

* :mod:`.app` - :class:`GroundStation` / :func:`run_ground`, the app composed;
* :mod:`.link` - :class:`VehicleLink`, the vehicle's MAVLink stream (holes, cards, the hole
  mission, the track);
* :mod:`.state` - :class:`StationState`, everything learnt, kept in ``DIR/station.json``
  (:mod:`.statefile`); :mod:`.records` - a hole, a vehicle's part in it, a track point;
  :mod:`.openings` - several vehicles' holes, one id per opening;
* :mod:`.files` - KML/GeoJSON/GPX always current; :mod:`.cot` - holes as TAK CoT;
  :mod:`.tak` - the link to TAK (mesh, TAK server over TCP/TLS); :mod:`.datapackage` -
  the TAK data package with the pictures;
* :mod:`.web` - the live page (``static/station.html``) and its state document;
  :mod:`.webapp` its routes (Starlette), :mod:`.webserver` its server (uvicorn),
  :mod:`.guard` the policy every request passes (Host, Origin, rate, headers),
  :mod:`.events` the bounded event stream, :mod:`.pairing` the operators' pairings,
  :mod:`.audit` the operators' marks in ``DIR/audit.jsonl``.
"""

from holescan.ground.station.app import GroundOptions, GroundStation, run_ground
from holescan.ground.station.audit import AuditTrail
from holescan.ground.station.cot import (
    COT_TYPE,
    TIERS,
    Tier,
    cot_uid,
    hole_cot,
    hole_tier,
    on_tak,
    point_age,
    withdraw_cot,
)
from holescan.ground.station.datapackage import (
    DATAPACKAGE_NAME,
    PACKAGE_STALE_S,
    ground_hole_of,
    package_holes,
    write_datapackage,
)
from holescan.ground.station.files import hole_summary, hole_waypoint, write_station_files
from holescan.ground.station.guard import Limits
from holescan.ground.station.link import VehicleLink
from holescan.ground.station.pairing import Pairing, Pairings
from holescan.ground.station.records import (
    MARKS,
    GroundHole,
    TrackPoint,
    parse_hole_statustext,
)
from holescan.ground.station.state import StationState
from holescan.ground.station.tak import (
    DEFAULT_COT_URL,
    CotError,
    CotPublisher,
    TakTls,
    tak_settings,
)
from holescan.ground.station.web import StationWeb, state_document

__all__ = [
    "COT_TYPE",
    "DATAPACKAGE_NAME",
    "DEFAULT_COT_URL",
    "MARKS",
    "PACKAGE_STALE_S",
    "TIERS",
    "AuditTrail",
    "CotError",
    "CotPublisher",
    "GroundHole",
    "GroundOptions",
    "GroundStation",
    "Limits",
    "Pairing",
    "Pairings",
    "StationState",
    "StationWeb",
    "TakTls",
    "Tier",
    "TrackPoint",
    "VehicleLink",
    "cot_uid",
    "ground_hole_of",
    "hole_cot",
    "hole_summary",
    "hole_tier",
    "hole_waypoint",
    "on_tak",
    "package_holes",
    "parse_hole_statustext",
    "point_age",
    "run_ground",
    "state_document",
    "tak_settings",
    "withdraw_cot",
    "write_datapackage",
    "write_station_files",
]
