"""The flight: the capture daemon, its clocks, sensor set-up, detection worker and live map.

Subpackage :mod:`capture.openni` (the Xtion through OpenNI2, ``.oni`` recordings); errors in
:mod:`capture.errors`. The infrastructure the flight stands on has floors of its own: the
flight log in :mod:`holescan.flightlog`, the MAVLink link in :mod:`holescan.link`, the
output-path rule in :mod:`holescan.outputs`, the frame record in :mod:`holescan.detect`
and the hole pipeline in :mod:`holescan.geotag`.
"""

from holescan.capture._clock import ClockEstimate, ClockSync
from holescan.capture._daemon import Flight
from holescan.capture._diskbudget import (
    DiskBudget,
    DiskPolicy,
    disk_budget,
    expected_bytes_per_s,
    preflight_disk_budget,
)
from holescan.capture._flightrecords import FlightConfig, FlightCounters, FlightSummary
from holescan.capture._fly import FlyReport, fly, format_report
from holescan.capture._flyconfig import (
    FlyConfig,
    SensorSpec,
    check_table,
    load_fly_config,
    numbers,
    parse_fly_config,
)
from holescan.capture._livemap import LiveMap, LiveMapConfig, LiveMapStats
from holescan.capture._mavlink import DEFAULT_RATES_HZ, Telemetry, TelemetryStats
from holescan.capture._preflight import (
    ITEMS,
    PreflightError,
    PreflightLimits,
    preflight,
    require_go,
)
from holescan.capture._preflightitems import (
    CheckItem,
    CheckStatus,
    PreflightReport,
    disk_item,
)
from holescan.capture._sensorsetup import PacedReplay, SensorSetup, open_sensor
from holescan.capture._usb import UsbDeviceInfo, find_xtion, reset_xtion
from holescan.capture._worker import DetectionWorker, WorkerResult
from holescan.capture.errors import CaptureError, ClockUnavailable, DiskBudgetError, SensorError
from holescan.capture.openni import (
    OniInfo,
    OniSource,
    OniStreamInfo,
    OniWriter,
    OpenNI2Device,
    camera_from_fov,
    export_oni,
    openni2_library,
    scan_oni,
    write_oni,
)

__all__ = [
    "DEFAULT_RATES_HZ",
    "ITEMS",
    "CaptureError",
    "CheckItem",
    "CheckStatus",
    "ClockEstimate",
    "ClockSync",
    "ClockUnavailable",
    "DetectionWorker",
    "DiskBudget",
    "DiskBudgetError",
    "DiskPolicy",
    "Flight",
    "FlightConfig",
    "FlightCounters",
    "FlightSummary",
    "FlyConfig",
    "FlyReport",
    "LiveMap",
    "LiveMapConfig",
    "LiveMapStats",
    "OniInfo",
    "OniSource",
    "OniStreamInfo",
    "OniWriter",
    "OpenNI2Device",
    "PacedReplay",
    "PreflightError",
    "PreflightLimits",
    "PreflightReport",
    "SensorError",
    "SensorSetup",
    "SensorSpec",
    "Telemetry",
    "TelemetryStats",
    "UsbDeviceInfo",
    "WorkerResult",
    "camera_from_fov",
    "check_table",
    "disk_budget",
    "disk_item",
    "expected_bytes_per_s",
    "export_oni",
    "find_xtion",
    "fly",
    "format_report",
    "load_fly_config",
    "numbers",
    "open_sensor",
    "openni2_library",
    "parse_fly_config",
    "preflight",
    "preflight_disk_budget",
    "require_go",
    "reset_xtion",
    "scan_oni",
    "write_oni",
]
