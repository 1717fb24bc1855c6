"""The disk budget before take-off: how long the card lasts at the log's rate, and whether
the planned flight fits.

:func:`disk_budget` is the pure arithmetic (a configuration and a free-space figure in, a
:class:`DiskBudget` out); :func:`preflight_disk_budget` reads the free space through a
:class:`~flightlog.diskspace.DiskSpace`, applies the optional retention rule
(removing the oldest *finished* flight logs when the configuration asks for it) and
refuses, or warns, as configured.

The rate is, in this order: ``[disk] expected_bytes_per_s`` when configured; else the
rate measured on the newest finished flight log in the log folder written with the same
image settings (:func:`flightlog.storage.measured_rate`); else the expected rate
of the image settings (:func:`expected_bytes_per_s`, measured with
``benchmarks/bench_log_writer.py``; docs/flight-log.md).
"""

from __future__ import annotations

import bisect
import dataclasses
import json
import logging
import math
from pathlib import Path
from typing import Final, Literal, Protocol

from holescan.capture._flightrecords import FlightConfig
from holescan.capture.errors import DiskBudgetError
from holescan.errors import InputError
from holescan.flightlog.diskspace import DiskSpace, SystemDiskSpace
from holescan.flightlog.options import LogOptions
from holescan.flightlog.storage import measured_rate, remove_oldest_finished

__all__ = [
    "DiskBudget",
    "DiskBudgetError",
    "DiskPolicy",
    "disk_budget",
    "expected_bytes_per_s",
    "preflight_disk_budget",
]

_log = logging.getLogger(__name__)

#: The Xtion's frame: 640 x 480 at 30 fps (other sizes scale by their pixel count).
_VGA_PIXELS: Final = 640 * 480
_FPS: Final = 30.0
#: Bytes of one VGA image as the log stores it, measured on simulated frames (the larger
#: of simulated and real: real Kinect-v1 depth is 73-92 KB with zstd, colour ~60 KB as JPEG
#: q90), benchmarks/bench_log_writer.py --codecs.
_JPEG_BYTES: Final = ((50, 18_000), (75, 30_000), (85, 47_200), (90, 69_100), (95, 117_200),
                      (100, 262_000))  # fmt: skip
_COLOR_BYTES: Final = {"png": 632_000, "raw": 921_600}
_DEPTH_BYTES: Final = {"zstd": 116_000, "png": 166_000, "raw": 614_400}
#: What chunk compression still takes off raw images (zstd: depth ~3.3x, colour ~1.1x).
_RAW_CHUNK_RATIO: Final = {
    "zstd": {"color": 1.1, "depth": 3.3},
    "lz4": {"color": 1.0, "depth": 2.0},
}
#: Everything but the images (frame info, poses, raw MAVLink, detections, holes, health),
#: 12.5 KB/s measured over a 60 s simulated sortie with its simulated autopilot, rounded up.
TELEMETRY_BYTES_PER_S: Final = 20_000.0


@dataclasses.dataclass(frozen=True)
class DiskPolicy:
    """The ``[disk]`` table of ``fly.toml``.

    planned_flight_s : the flight the budget is checked against (``duration_s`` /
        ``--duration`` takes precedence; None: only say how long the card lasts).
    expected_bytes_per_s : the log's rate to plan with (None: measured on the last finished
        log with the same image settings, else the expected rate of the settings).
    when_short : ``refuse`` (``fly`` exits with one line) or ``warn`` (it logs a warning
        and flies; the image reserve then keeps telemetry, detections and holes going).
    remove_oldest_finished : before the check, remove the oldest finished flight logs in
        the log folder until the planned flight fits (never an unfinished one).
    """

    planned_flight_s: float | None = None
    expected_bytes_per_s: float | None = None
    when_short: Literal["refuse", "warn"] = "refuse"
    remove_oldest_finished: bool = False

    def __post_init__(self) -> None:
        for name in ("planned_flight_s", "expected_bytes_per_s"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise InputError(f"disk.{name} must be a positive number, got {v!r}")
        if self.when_short not in ("refuse", "warn"):
            raise InputError(f"disk.when_short must be 'refuse' or 'warn', got {self.when_short!r}")


class PlannedFlight(Protocol):
    """What the budget reads of a flight's configuration (a :class:`capture.FlyConfig`)."""

    @property
    def log_dir(self) -> Path: ...
    @property
    def duration_s(self) -> float | None: ...
    @property
    def disk(self) -> DiskPolicy: ...
    @property
    def flight(self) -> FlightConfig: ...


@dataclasses.dataclass(frozen=True)
class DiskBudget:
    """How long the log's disk lasts.

    free_bytes : free now. reserve_bytes : kept free (frames stop being logged there).
    rate_bytes_per_s : the log's expected rate; rate_source : where that figure comes from.
    planned_s : the planned flight (None: none given).
    """

    free_bytes: int
    reserve_bytes: int
    rate_bytes_per_s: float
    rate_source: str
    planned_s: float | None

    @property
    def usable_bytes(self) -> int:
        return max(self.free_bytes - self.reserve_bytes, 0)

    @property
    def lasts_s(self) -> float:
        """Seconds of logging the disk holds before the image reserve."""
        return self.usable_bytes / self.rate_bytes_per_s

    @property
    def needed_bytes(self) -> int | None:
        """Bytes the planned flight needs (None: no plan)."""
        if self.planned_s is None:
            return None
        return math.ceil(self.planned_s * self.rate_bytes_per_s)

    @property
    def fits(self) -> bool | None:
        """The planned flight fits before the reserve (None: no plan)."""
        need = self.needed_bytes
        return None if need is None else need <= self.usable_bytes

    def describe(self) -> str:
        """One line for the operator."""
        text = (
            f"disk: {self.free_bytes / 1e9:.1f} GB free ({self.reserve_bytes / 1e9:.1f} GB "
            f"kept in reserve), log {self.rate_bytes_per_s / 1e6:.1f} MB/s "
            f"({self.rate_source}): lasts {_minutes(self.lasts_s)}"
        )
        if self.planned_s is not None:
            verdict = "fits" if self.fits else "does NOT fit"
            text += (
                f"; planned flight {_minutes(self.planned_s)} needs "
                f"{(self.needed_bytes or 0) / 1e9:.1f} GB: {verdict}"
            )
        return text


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.0f} min" if seconds < 5940 else f"{seconds / 3600:.1f} h"


def _jpeg_bytes(quality: int) -> float:
    qs = [q for q, _ in _JPEG_BYTES]
    i = bisect.bisect_left(qs, quality)
    if i == 0:
        return float(_JPEG_BYTES[0][1])
    (q0, b0), (q1, b1) = _JPEG_BYTES[i - 1], _JPEG_BYTES[min(i, len(qs) - 1)]
    return b0 + (b1 - b0) * (quality - q0) / max(q1 - q0, 1)


def expected_bytes_per_s(
    options: LogOptions, *, fps: float = _FPS, pixels: int = _VGA_PIXELS
) -> float:
    """The log's expected rate, bytes/s, for these image settings at ``fps`` frames of
    ``pixels`` pixels (default: the Xtion, VGA at 30 fps), telemetry included.

    >>> round(expected_bytes_per_s(LogOptions()) / 1e6, 1)  # JPEG q90 + zstd depth
    5.6
    """
    ratio = _RAW_CHUNK_RATIO.get(options.compression, {"color": 1.0, "depth": 1.0})
    if options.color == "jpeg":
        color = _jpeg_bytes(options.jpeg_quality)
    else:
        color = _COLOR_BYTES[options.color] / (ratio["color"] if options.color == "raw" else 1)
    depth = _DEPTH_BYTES[options.depth] / (ratio["depth"] if options.depth == "raw" else 1)
    return fps * (color + depth) * pixels / _VGA_PIXELS + TELEMETRY_BYTES_PER_S


def _image_settings(options: LogOptions) -> dict[str, str]:
    """The ``holescan.config`` entries (as logged: JSON text) that set the image sizes."""
    values = {"log.color": json.dumps(options.color), "log.depth": json.dumps(options.depth)}
    if options.color == "jpeg":
        values["log.jpeg_quality"] = json.dumps(options.jpeg_quality)
    return values


def disk_budget(cfg: PlannedFlight, free_bytes: int, *, measure: bool = True) -> DiskBudget:
    """The disk budget of the flight ``cfg`` describes on a disk with ``free_bytes`` free.

    The planned flight is ``cfg.duration_s`` (``--duration``), else ``[disk]
    planned_flight_s``. measure : look in ``cfg.log_dir`` for a finished log to measure
    the rate on (see the module docstring).
    """
    if free_bytes < 0:
        raise InputError(f"free_bytes must be >= 0, got {free_bytes}")
    options, policy = cfg.flight.log_options, cfg.disk
    if policy.expected_bytes_per_s is not None:
        rate, source = policy.expected_bytes_per_s, "configured"
    else:
        found = measured_rate(cfg.log_dir, _image_settings(options)) if measure else None
        if found is not None:
            rate, log_set = found
            source = f"measured on {log_set.prefix.name}"
        else:
            rate = expected_bytes_per_s(options)
            source = f"expected for colour {options.color}, depth {options.depth}"
    plan = cfg.duration_s if cfg.duration_s is not None else policy.planned_flight_s
    return DiskBudget(int(free_bytes), options.image_reserve_bytes, rate, source, plan)


def preflight_disk_budget(cfg: PlannedFlight, disk: DiskSpace | None = None) -> DiskBudget:
    """The budget of the log folder's disk before take-off, said in the log.

    With ``[disk] remove_oldest_finished`` the oldest finished flight logs are removed
    first until the planned flight fits. Raises :class:`DiskBudgetError` when it still
    does not fit and ``[disk] when_short`` is ``refuse``; logs a warning when ``warn``.
    """
    disk = disk or SystemDiskSpace()
    log_dir = cfg.log_dir
    try:
        log_dir.mkdir(parents=True, exist_ok=True)
        free = disk.free_bytes(log_dir)
    except OSError as err:
        raise InputError(f"cannot read the free space of the log folder {log_dir}: {err}") from err
    budget = disk_budget(cfg, free)
    need = budget.needed_bytes
    retention = budget.fits is False and cfg.disk.remove_oldest_finished and need is not None
    if retention and remove_oldest_finished(log_dir, (need or 0) + budget.reserve_bytes, disk):
        budget = dataclasses.replace(budget, free_bytes=disk.free_bytes(log_dir))
    if budget.fits is False:
        if cfg.disk.when_short == "refuse":
            raise DiskBudgetError(
                f"{budget.describe()} (make room in {log_dir}, plan a shorter flight, or set "
                '[disk] when_short = "warn" or remove_oldest_finished = true)'
            )
        _log.warning("%s: frames stop being logged at the reserve", budget.describe())
    else:
        _log.info("%s", budget.describe())
    return budget
