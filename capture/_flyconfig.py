"""``holescan fly`` settings: a TOML file (and command-line overrides) -> a :class:`FlyConfig`.

The file (``deploy/fly.example.toml`` documents every key) has top-level keys for the
sensor and the links, and one table per part::

    sensor = "openni2"            # openni2 | oni:PATH | mcap:PATH | sim
    mavlink = "/dev/ttyAMA0"      # pymavlink connection string of the autopilot
    log_dir = "/var/lib/holescan/flights"
    [capture]  frame timeout, retry back-off, start-up sync, USB reset ...
    [detect]   detector mode, searcher ...
    [mount]    camera angles and offset on the vehicle
    [log]      MCAP compression, chunk and file sizes, image codecs
    [disk]     the disk budget before take-off, the image reserve, retention
    [holes]    announcing and serving holes
    [sim]      the simulated sortie (``sensor = "sim"``), checked by :mod:`sim`

Unknown keys and wrong types raise :class:`holescan.errors.InputError` naming the key (a
typo in a flight configuration must not pass silently); the ``[sim]`` table is kept as
written for :mod:`sim`, which checks it with :func:`check_table` when the sensor is ``sim``
(the flight side never imports the simulator). :func:`capture.open_sensor` turns the sensor
setting into a :class:`capture.SensorSetup`; :func:`capture.fly` runs the flight.

Why a table-driven check and not a schema library (pydantic, msgspec): the file is seven
small tables of scalars and short lists; ``_TABLES`` states each key's types and default in
one line, :func:`check_table` turns any mistake into one message naming ``table.key``, and
the typed :class:`FlyConfig` is built from the checked values. A schema library would add a
dependency on the companion computer for the same checks, with longer error messages.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import logging
import math
import time
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from holescan.capture._diskbudget import DiskPolicy
from holescan.capture._flightrecords import FlightConfig
from holescan.capture._livemap import LiveMapConfig
from holescan.capture._mavlink import DEFAULT_BAUD
from holescan.detect import DEFAULT, PAPER, SEARCHERS, DetectParams
from holescan.errors import InputError
from holescan.flightlog.options import LogOptions
from holescan.geotag import AnnounceGate, CameraMount, ErrorModel
from holescan.link import SigningKey
from holescan.utc import utc_datetime

__all__ = [
    "FlyConfig",
    "SensorSpec",
    "check_table",
    "load_fly_config",
    "numbers",
    "parse_fly_config",
]

_log = logging.getLogger(__name__)

SensorKind = Literal["openni2", "oni", "mcap", "sim"]


@dataclass(frozen=True)
class SensorSpec:
    """Where frames come from: ``openni2`` (the Xtion), ``oni:PATH``, ``mcap:PATH``, ``sim``."""

    kind: SensorKind
    path: Path | None = None

    @classmethod
    def parse(cls, text: str) -> SensorSpec:
        kind, sep, rest = text.partition(":")
        if kind in ("openni2", "sim") and not sep:
            return cls(kind)  # type: ignore[arg-type]
        if kind in ("oni", "mcap") and rest:
            return cls(kind, Path(rest))  # type: ignore[arg-type]
        raise InputError(f"sensor must be openni2, oni:PATH, mcap:PATH or sim; got {text!r}")

    def __str__(self) -> str:
        return self.kind if self.path is None else f"{self.kind}:{self.path}"


@dataclass(frozen=True)
class FlyConfig:
    """Everything ``holescan fly`` needs.

    sensor : where frames come from. mavlink : the autopilot link (None: fly without
    telemetry, every frame unposed; for ``sim``: the autopilot the simulated Xtion flies
    with, None = a simulated autopilot on a free loopback port). baud : serial rate.
    log_dir : folder of the flight logs. gcs : pymavlink connection towards the ground
    station for the hole mission server (None: the server shares the ``mavlink`` link and
    the autopilot routes to the ground station; no server without either). sysid : the
    vehicle's MAVLink system id (the hole server speaks as its component 191). signing :
    MAVLink 2 signing key of the hole server's link to the ground station, or, without
    ``gcs``, of the one link to the autopilot that the holes share (None: unsigned;
    fly.toml ``mavlink_key`` = 64 hex digits or ``mavlink_key_file`` = a file of the key or
    a passphrase, :class:`link.SigningKey`; never in ``record`` or a log).
    duration_s, max_frames : stop after this long / this many frames (None: until stopped).
    usb_reset : reset the Xtion on USB after a sensor failure (``openni2`` only).
    openni_uri : OpenNI2 device URI (None: the first Xtion).
    realtime : replay ``oni``/``mcap`` recordings at their recorded pace.
    flight : the daemon's settings (its ``log_prefix`` is set per flight by
    :meth:`flight_config`). hole_rel_alt_m, hole_clearance_m : served waypoints' altitude.
    hole_card_bytes_per_s : byte budget of the holes' pictures to the ground station.
    live_map : the on-board live map sent to the ground station with what the pictures
        leave of their budget (:class:`~capture._livemap.LiveMapConfig`; None: off).
    disk : the ``[disk]`` table: the budget before take-off
        (:class:`~capture._diskbudget.DiskPolicy`).
    sim_table : the ``[sim]`` table as written (checked by :mod:`sim`). record : the settings
    as flat ``table.key`` -> value
    (logged as the flight's ``holescan.config`` metadata).
    """

    sensor: SensorSpec
    log_dir: Path
    mavlink: str | None = None
    baud: int = DEFAULT_BAUD
    gcs: str | None = None
    sysid: int = 1
    signing: SigningKey | None = None
    duration_s: float | None = None
    max_frames: int | None = None
    usb_reset: bool = True
    openni_uri: str | None = None
    realtime: bool = True
    flight: FlightConfig = field(default_factory=lambda: FlightConfig(log_prefix=Path("flight")))
    hole_rel_alt_m: float = 10.0
    hole_clearance_m: float = 5.0
    hole_card_bytes_per_s: float = 1000.0
    live_map: LiveMapConfig | None = field(default_factory=LiveMapConfig)
    disk: DiskPolicy = field(default_factory=DiskPolicy)
    sim_table: Mapping[str, Any] = field(default_factory=dict)
    record: Mapping[str, Any] = field(default_factory=dict)

    def flight_config(self, t_unix_ns: int | None = None) -> FlightConfig:
        """The daemon's settings with a fresh log prefix ``LOG_DIR/flight-YYYYmmddTHHMMSSZ``.

        Creates ``log_dir``; adds ``-2``, ``-3``... when a log of that name exists.
        """
        try:
            self.log_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise InputError(f"cannot create the log folder {self.log_dir}: {err}") from err
        t = utc_datetime(t_unix_ns or time.time_ns())
        stem = f"flight-{t:%Y%m%dT%H%M%SZ}"
        name, k = stem, 1
        while any(self.log_dir.glob(f"{name}_*.mcap*")):
            k += 1
            name = f"{stem}-{k}"
        return dataclasses.replace(
            self.flight,
            log_prefix=self.log_dir / name,
            max_duration_s=self.duration_s,
            max_frames=self.max_frames,
            config_record=dict(self.record),
        )


# key -> (type(s), default) per table; None default = optional. A default the daemon, the log
# writer or this module's FlyConfig also has is taken from there: each default is written once.
_NUM = (int, float)
_RENAMED = {
    "announce_min_score": "the gate now takes a probability, announce_min_p_hole "
    "(docs/tiers.md, 'What is announced'; p_hole 0.5 is a best score of 0.37)",
}


def _default(cls: type[Any], name: str) -> Any:
    """The default of dataclass ``cls``'s field ``name`` (a list for a tuple, as TOML has)."""
    (f,) = (f for f in dataclasses.fields(cls) if f.name == name)
    value = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
    return list(value) if isinstance(value, tuple) else value


def _from(cls: type[Any], types: tuple[type, ...], name: str) -> tuple[tuple[type, ...], Any]:
    return (types, _default(cls, name))


_TOP: dict[str, tuple[tuple[type, ...], Any]] = {
    "sensor": ((str,), "openni2"),
    "mavlink": ((str,), None),
    "baud": _from(FlyConfig, (int,), "baud"),
    "log_dir": ((str,), None),
    "gcs": ((str,), None),
    "sysid": _from(FlyConfig, (int,), "sysid"),
    "mavlink_key": ((str,), None),
    "mavlink_key_file": ((str,), None),
    "duration_s": (_NUM, None),
    "max_frames": ((int,), None),
}
_TABLES: dict[str, dict[str, tuple[tuple[type, ...], Any]]] = {
    "capture": {
        "frame_timeout_s": _from(FlightConfig, _NUM, "frame_timeout_s"),
        "retry_backoff_s": _from(FlightConfig, (list,), "retry_backoff_s"),
        "startup_sync_s": _from(FlightConfig, _NUM, "startup_sync_s"),
        "pose_wait_s": _from(FlightConfig, _NUM, "pose_wait_s"),
        "health_period_s": _from(FlightConfig, _NUM, "health_period_s"),
        "usb_reset": _from(FlyConfig, (bool,), "usb_reset"),
        "openni_uri": ((str,), None),
        "realtime": _from(FlyConfig, (bool,), "realtime"),
    },
    "detect": {
        "mode": ((str,), "default"),
        "searcher": ((str,), "human"),
        "superpixels": ((int,), 9),
        "min_score": (_NUM, None),
        "max_range_m": (_NUM, None),
    },
    "mount": {
        "roll_deg": (_NUM, 0.0),
        "pitch_deg": (_NUM, -90.0),
        "yaw_deg": (_NUM, 0.0),
        "offset_m": ((list,), [0.0, 0.0, 0.0]),
        "attitude_sigma_deg": _from(FlightConfig, _NUM, "attitude_sigma_deg"),
    },
    "log": {
        "compression": _from(LogOptions, (str,), "compression"),
        "chunk_size": _from(LogOptions, (int,), "chunk_size"),
        "max_file_bytes": _from(LogOptions, (int,), "max_file_bytes"),
        "max_file_s": _from(LogOptions, _NUM, "max_file_s"),
        "sync_interval_s": _from(LogOptions, _NUM, "sync_interval_s"),
        "max_queued_frames": _from(LogOptions, (int,), "max_queued_frames"),
        "max_queued_messages": _from(LogOptions, (int,), "max_queued_messages"),
        "color": _from(LogOptions, (str,), "color"),
        "jpeg_quality": _from(LogOptions, (int,), "jpeg_quality"),
        "depth": _from(LogOptions, (str,), "depth"),
    },
    "disk": {
        "planned_flight_s": (_NUM, None),
        "expected_bytes_per_s": (_NUM, None),
        "when_short": _from(DiskPolicy, (str,), "when_short"),
        "image_reserve_bytes": _from(LogOptions, (int,), "image_reserve_bytes"),
        "remove_oldest_finished": _from(DiskPolicy, (bool,), "remove_oldest_finished"),
    },
    "holes": {
        "announce_min_p_hole": (_NUM, AnnounceGate.min_p_hole),
        "announce_min_sightings": ((int,), AnnounceGate.min_sightings),
        "announce_min_span_s": (_NUM, AnnounceGate.min_span_s),
        "review_min_p_hole": (_NUM, AnnounceGate.review_min_p_hole),
        "card_bytes_per_s": _from(FlyConfig, _NUM, "hole_card_bytes_per_s"),
        "rel_alt_m": _from(FlyConfig, _NUM, "hole_rel_alt_m"),
        "clearance_m": _from(FlyConfig, _NUM, "hole_clearance_m"),
    },
    "map": {
        "enabled": ((bool,), True),
        "cell_m": _from(LiveMapConfig, _NUM, "cell_m"),
        "pixel_stride": _from(LiveMapConfig, (int,), "pixel_stride"),
        "frame_every": _from(LiveMapConfig, (int,), "frame_every"),
        "budget_ms": _from(LiveMapConfig, _NUM, "budget_ms"),
        "radius_m": _from(LiveMapConfig, _NUM, "radius_m"),
    },
}


TableSpec = Mapping[str, tuple[tuple[type, ...], Any]]
"""key -> (accepted types, default) of one TOML table; a None default means optional."""


def check_table(table: str, doc: Mapping[str, Any], spec: TableSpec, where: str) -> dict[str, Any]:
    """Values of ``doc`` checked against ``spec`` with defaults filled in.

    Raises :class:`InputError` naming ``table.key`` for an unknown key or a wrong type.
    """
    out: dict[str, Any] = {}
    prefix = f"{table}." if table else ""
    for key, value in doc.items():
        if key not in spec:
            if not table and (key in _TABLES or key == "sim"):
                continue
            if key in _RENAMED:
                raise InputError(f"{where}: {prefix}{key} is gone: {_RENAMED[key]}")
            raise InputError(
                f"{where}: unknown setting {prefix}{key} (known: {', '.join(sorted(spec))})"
            )
        types, _ = spec[key]
        ok = isinstance(value, types) and not (bool not in types and isinstance(value, bool))
        if not ok:
            names = " or ".join(t.__name__ for t in types)
            raise InputError(f"{where}: {prefix}{key} must be {names}, got {value!r}")
        out[key] = value
    for key, (_, default) in spec.items():
        out.setdefault(key, default)
    return out


def numbers(where: str, key: str, value: list[Any], n: int | None = None) -> tuple[float, ...]:
    """A TOML list of numbers (``n`` of them when given) as floats, or :class:`InputError`."""
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value) or (
        n is not None and len(value) != n
    ):
        size = f"{n} " if n is not None else ""
        raise InputError(f"{where}: {key} must be a list of {size}numbers, got {value!r}")
    return tuple(float(v) for v in value)


def _positive(where: str, key: str, value: float | None) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise InputError(f"{where}: {key} must be a positive number, got {value!r}")


def parse_fly_config(
    doc: Mapping[str, Any],
    overrides: Mapping[str, Any] | None = None,
    *,
    where: str = "fly configuration",
) -> FlyConfig:
    """Build a :class:`FlyConfig` from a parsed TOML document and top-level overrides.

    ``overrides`` (e.g. from the command line: ``sensor``, ``mavlink``, ``log_dir``, ``gcs``,
    ``duration_s``, ``max_frames``) replace the file's top-level values when not None.
    """
    top = check_table("", doc, _TOP, where)
    for key, value in (overrides or {}).items():
        if key not in _TOP:
            raise InputError(f"unknown override {key!r}")
        if value is not None:
            top[key] = value
    tables: dict[str, dict[str, Any]] = {}
    for name, spec in _TABLES.items():
        sub = doc.get(name, {})
        if not isinstance(sub, Mapping):
            raise InputError(f"{where}: [{name}] must be a table")
        tables[name] = check_table(name, sub, spec, where)

    if top["log_dir"] is None:
        raise InputError(f"{where}: no log folder: give --log-dir DIR or log_dir in the file")
    sensor = SensorSpec.parse(str(top["sensor"]))
    _positive(where, "duration_s", top["duration_s"])
    if top["max_frames"] is not None and top["max_frames"] < 1:
        raise InputError(f"{where}: max_frames must be >= 1")
    if not 1 <= top["sysid"] <= 255:
        raise InputError(f"{where}: sysid must be 1..255, got {top['sysid']}")

    cap = tables["capture"]
    backoff = numbers(where, "capture.retry_backoff_s", cap["retry_backoff_s"])
    if not backoff or min(backoff) < 0:
        raise InputError(f"{where}: capture.retry_backoff_s needs >= 1 non-negative waits")
    for key in ("frame_timeout_s", "health_period_s"):
        _positive(where, f"capture.{key}", float(cap[key]))

    det = tables["detect"]
    if det["mode"] not in ("default", "paper"):
        raise InputError(f"{where}: detect.mode must be 'default' or 'paper', got {det['mode']!r}")
    if det["mode"] == "paper" and importlib.util.find_spec("numba") is None:
        raise InputError(
            f"{where}: detect.mode = 'paper' needs numba, which the flight install leaves out "
            "(pip install 'holescan[ground]'; the default mode does not need it)"
        )
    if det["searcher"] not in SEARCHERS:
        raise InputError(f"{where}: detect.searcher must be one of {sorted(SEARCHERS)}")
    params: DetectParams = (PAPER if det["mode"] == "paper" else DEFAULT).with_searcher(
        det["searcher"]
    )
    changes: dict[str, Any] = {"superpixels": det["superpixels"]}
    for key in ("min_score", "max_range_m"):
        if det[key] is not None:
            changes[key] = float(det[key])
    params = dataclasses.replace(params, **changes)

    mnt = tables["mount"]
    offset = numbers(where, "mount.offset_m", mnt["offset_m"], 3)
    mount = CameraMount.from_euler_deg(
        float(mnt["roll_deg"]),
        float(mnt["pitch_deg"]),
        float(mnt["yaw_deg"]),
        (offset[0], offset[1], offset[2]),
    )

    attitude_sigma_deg = float(mnt["attitude_sigma_deg"])
    try:
        ErrorModel(attitude_sigma_rad=math.radians(attitude_sigma_deg))
    except InputError as err:
        raise InputError(f"{where}: mount.{err}") from err

    lg, dk = tables["log"], tables["disk"]
    try:
        options = LogOptions(
            chunk_size=lg["chunk_size"],
            compression=lg["compression"],
            max_file_bytes=lg["max_file_bytes"],
            max_file_s=float(lg["max_file_s"]),
            sync_interval_s=float(lg["sync_interval_s"]),
            max_queued_frames=lg["max_queued_frames"],
            max_queued_messages=lg["max_queued_messages"],
            color=lg["color"],
            jpeg_quality=lg["jpeg_quality"],
            depth=lg["depth"],
            image_reserve_bytes=dk["image_reserve_bytes"],
        )
        disk = DiskPolicy(
            planned_flight_s=None
            if dk["planned_flight_s"] is None
            else float(dk["planned_flight_s"]),
            expected_bytes_per_s=(
                None if dk["expected_bytes_per_s"] is None else float(dk["expected_bytes_per_s"])
            ),
            when_short=dk["when_short"],
            remove_oldest_finished=dk["remove_oldest_finished"],
        )
    except InputError as err:
        raise InputError(f"{where}: {err}") from err

    holes = tables["holes"]
    try:
        AnnounceGate(
            float(holes["announce_min_p_hole"]),
            holes["announce_min_sightings"],
            float(holes["announce_min_span_s"]),
            float(holes["review_min_p_hole"]),
        )
    except InputError as err:
        raise InputError(f"{where}: [holes] {err}") from err
    if not float(holes["card_bytes_per_s"]) >= 100.0:
        raise InputError(f"{where}: holes.card_bytes_per_s must be >= 100")

    flight = FlightConfig(
        log_prefix=Path("flight"),
        params=params,
        mount=mount,
        attitude_sigma_deg=attitude_sigma_deg,
        log_options=options,
        frame_timeout_s=float(cap["frame_timeout_s"]),
        retry_backoff_s=backoff,
        announce_min_p_hole=float(holes["announce_min_p_hole"]),
        announce_min_sightings=holes["announce_min_sightings"],
        announce_min_span_s=float(holes["announce_min_span_s"]),
        review_min_p_hole=float(holes["review_min_p_hole"]),
        health_period_s=float(cap["health_period_s"]),
        pose_wait_s=float(cap["pose_wait_s"]),
        startup_sync_s=float(cap["startup_sync_s"]),
    )

    mp = tables["map"]
    live_map: LiveMapConfig | None = None
    if mp["enabled"]:
        try:
            live_map = LiveMapConfig(
                cell_m=float(mp["cell_m"]),
                pixel_stride=mp["pixel_stride"],
                frame_every=mp["frame_every"],
                budget_ms=float(mp["budget_ms"]),
                radius_m=float(mp["radius_m"]),
            )
        except InputError as err:
            raise InputError(f"{where}: [map] {err}") from err

    sim_table = doc.get("sim", {})
    if not isinstance(sim_table, Mapping):
        raise InputError(f"{where}: [sim] must be a table")

    signing = _signing_key(where, top)
    for key in ("mavlink_key", "mavlink_key_file"):  # the secret never reaches the log
        top[key] = None if top[key] is None else f"(set: {signing})"
    record: dict[str, Any] = {k: str(v) if isinstance(v, Path) else v for k, v in top.items()}
    for name, values in tables.items():
        record.update({f"{name}.{k}": v for k, v in values.items()})
    return FlyConfig(
        sensor=sensor,
        log_dir=Path(top["log_dir"]),
        mavlink=top["mavlink"],
        baud=top["baud"],
        gcs=top["gcs"],
        sysid=top["sysid"],
        signing=signing,
        duration_s=None if top["duration_s"] is None else float(top["duration_s"]),
        max_frames=top["max_frames"],
        usb_reset=cap["usb_reset"],
        openni_uri=cap["openni_uri"],
        realtime=cap["realtime"],
        flight=flight,
        hole_rel_alt_m=float(holes["rel_alt_m"]),
        hole_clearance_m=float(holes["clearance_m"]),
        hole_card_bytes_per_s=float(holes["card_bytes_per_s"]),
        live_map=live_map,
        disk=disk,
        sim_table=dict(sim_table),
        record=record,
    )


def _signing_key(where: str, top: Mapping[str, Any]) -> SigningKey | None:
    """The hole server's MAVLink signing key from ``mavlink_key`` or ``mavlink_key_file``."""
    text, path = top["mavlink_key"], top["mavlink_key_file"]
    if text is not None and path is not None:
        raise InputError(f"{where}: give mavlink_key or mavlink_key_file, not both")
    try:
        if text is not None:
            return SigningKey.from_hex(text)
        if path is not None:
            return SigningKey.from_file(Path(path))
    except InputError as err:
        raise InputError(f"{where}: {err}") from err
    return None


def load_fly_config(
    path: str | Path | None = None, overrides: Mapping[str, Any] | None = None
) -> FlyConfig:
    """Read a TOML configuration file (None: defaults only) and apply ``overrides``."""
    doc: dict[str, Any] = {}
    where = "fly configuration"
    if path is not None:
        where = str(path)
        try:
            with open(path, "rb") as f:
                doc = tomllib.load(f)
        except FileNotFoundError as err:
            raise InputError(f"configuration file not found: {path}") from err
        except OSError as err:
            raise InputError(f"cannot read {path}: {err.strerror}") from err
        except tomllib.TOMLDecodeError as err:
            raise InputError(f"{path}: not valid TOML ({err})") from err
    return parse_fly_config(doc, overrides, where=where)
