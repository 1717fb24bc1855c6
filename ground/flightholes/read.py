"""The holes of a logged flight, read once.

:func:`read_flight_holes` reads one flight log (or its rotated files) front to back, once,
and keeps:

* the **final hole list**: the last ``/holes`` record (the daemon logs the whole list after
  every change and once more at the end), as :class:`geotag.Hole` records;
* each hole's **best view** (:attr:`geotag.Hole.best_frame_index` and ``best_box``) as a
  thumbnail (:class:`~ground.flightholes.views.BestViews`);
* the vehicle's **home** (the last MAVLink HOME_POSITION logged, decoded by capture's one
  MAVLink adapter, else the first logged position with its altitude less ``rel_alt_m``:
  where logging started) and the offset from the autopilot's boot clock to Unix time (from
  frames stamped on both clocks, else poses).

A file cut off by a crash is read up to its last complete chunk (a warning says so).
:func:`flight_log_files` and :func:`log_stem` name a flight's files.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.flightlog import (
    FlightLogError,
    LoggedDetections,
    LoggedFrame,
    LoggedHoles,
    LoggedMavlink,
    LoggedPose,
    TruncatedLogError,
    read_flight_log,
)
from holescan.geotag import AnnounceGate, Hole
from holescan.ground.flightholes.views import BestViews, HoleThumbnail
from holescan.link import home_from_home_position, mavlink, parser

__all__ = ["FlightHoles", "flight_log_files", "log_stem", "read_flight_holes"]

_log = logging.getLogger(__name__)

_PART = re.compile(r"^(?P<prefix>.*)_(?P<index>\d{4})\.mcap$")


@dataclasses.dataclass(frozen=True)
class FlightHoles:
    """What a flight log says about its holes.

    paths : the files read, in order. truncated : messages for the files cut off early.
    holes : every hole of the last ``/holes`` record, sorted by id (unfiltered).
    holes_t_unix_ns : when that record was logged (Unix clock); holes_records : how many
        ``/holes`` records the log has.
    home : (lat_deg, lon_deg, alt_m MSL) of the vehicle's home, or None; home_source says
        where it came from (``HOME_POSITION``, ``first logged position``).
    boot_to_unix_ns : add to an autopilot boot time to get Unix time, ns (None: unknown).
    thumbnails : hole id -> best view (holes whose best frame is not in the log have none).
    frames_read : RGB-D frames decoded (0 when thumbnails were not asked for).
    gate : the flight's :class:`geotag.AnnounceGate` (its thresholds as the last ``/holes``
        record gives them; the default gate for logs from before they were recorded, and
        then ``gate_recorded`` is False).
    tiers : hole id -> the tier the vehicle gave it in that record (logs from before:
        ``gate.tier`` of the hole).
    """

    paths: tuple[Path, ...]
    truncated: tuple[str, ...]
    holes: tuple[Hole, ...]
    holes_t_unix_ns: int
    holes_records: int
    home: tuple[float, float, float] | None
    home_source: str
    boot_to_unix_ns: int | None
    thumbnails: Mapping[int, HoleThumbnail]
    frames_read: int
    gate: AnnounceGate = dataclasses.field(default_factory=AnnounceGate)
    gate_recorded: bool = False
    tiers: Mapping[int, str] = dataclasses.field(default_factory=dict)


# ------------------------------------------------------------------------ file names


def flight_log_files(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
) -> tuple[Path, ...]:
    """The files of one flight, in order.

    Several paths are taken as given. One path ``PREFIX_0000.mcap`` (or any part) brings
    the parts that follow it (``PREFIX_0001.mcap``, ... until one is missing); a path
    ``PREFIX`` or ``PREFIX.mcap`` that does not exist stands for ``PREFIX_0000.mcap`` and
    its followers. Missing files are left for the reader to report.
    """
    if not isinstance(paths, str | os.PathLike):
        given = [Path(p) for p in paths]
        if len(given) != 1:
            if not given:
                raise FlightLogError("no flight log files given")
            return tuple(given)
        paths = given[0]
    p = Path(paths)
    if not p.exists():
        stem = p.with_suffix("") if p.suffix == ".mcap" else p
        first = stem.with_name(f"{stem.name}_0000.mcap")
        if not first.exists():
            return (p,)
        p = first
    match = _PART.match(p.name)
    if match is None:
        return (p,)
    out = [p]
    index = int(match["index"]) + 1
    while True:
        nxt = p.with_name(f"{match['prefix']}_{index:04d}.mcap")
        if not nxt.exists():
            return tuple(out)
        out.append(nxt)
        index += 1


def log_stem(path: Path) -> Path:
    """``/data/flight`` for ``/data/flight_0003.mcap`` or ``/data/flight.mcap``."""
    match = _PART.match(path.name)
    if match is not None:
        return path.with_name(match["prefix"])
    return path.with_suffix("") if path.suffix == ".mcap" else path


# ---------------------------------------------------------------------------- reading


def _home_position(packet: bytes) -> tuple[float, float, float] | None:
    mav = parser()
    try:
        msgs = mav.parse_buffer(packet) or []
    except mavlink.MAVError:
        return None
    for msg in msgs:
        if msg.get_type() == "HOME_POSITION":
            return home_from_home_position(msg)
    return None


def read_flight_holes(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    *,
    thumbnails: bool = True,
    thumb_height_px: int = 160,
    max_pending_frames: int = 90,
) -> FlightHoles:
    """Read a flight log once: final holes, best-view thumbnails, home, boot -> Unix offset.

    Parameters
    ----------
    paths : a log file, its rotated parts in order, or one part / prefix (see
        :func:`flight_log_files`).
    thumbnails : decode frames and make thumbnails (False reads much faster).
    thumb_height_px : thumbnail height, pixels.
    max_pending_frames : frames kept while waiting for their detections (memory: 1.5 MB
        each at 640x480; 90 = 3 s at 30 fps).

    Raises
    ------
    FlightLogError : a file is missing or not a flight log, or the log has no ``/holes``
        record.
    """
    if max_pending_frames < 1 or thumb_height_px < 8:
        raise InputError("max_pending_frames must be >= 1 and thumb_height_px >= 8")
    files = flight_log_files(paths)
    kinds: set[type[Any]] = {LoggedHoles, LoggedPose, LoggedMavlink}
    if thumbnails:
        kinds |= {LoggedFrame, LoggedDetections}
    views = BestViews(max_pending_frames)
    last: LoggedHoles | None = None
    holes: tuple[Hole, ...] = ()
    n_records = frames = 0
    home: tuple[float, float, float] | None = None
    first_pos: tuple[float, float, float] | None = None
    offset_frames: int | None = None
    offset_poses: int | None = None
    truncated = []
    for path in files:
        try:
            for rec in read_flight_log(path, kinds=kinds, strict=True):
                if isinstance(rec, LoggedFrame):
                    frames += 1
                    views.on_frame(rec)
                    if rec.t_boot_ns is not None:
                        offset_frames = rec.t_unix_ns - rec.t_boot_ns
                    if first_pos is None and rec.pose is not None:
                        p = rec.pose
                        first_pos = (p.lat_deg, p.lon_deg, p.alt_m - p.rel_alt_m)
                elif isinstance(rec, LoggedDetections):
                    views.on_detections(rec)
                elif isinstance(rec, LoggedHoles):
                    holes, last = rec.as_holes(), rec
                    n_records += 1
                    views.on_holes(holes)
                elif isinstance(rec, LoggedPose):
                    offset_poses = rec.t_unix_ns - rec.pose.t_boot_ns
                    if first_pos is None:
                        p = rec.pose
                        first_pos = (p.lat_deg, p.lon_deg, p.alt_m - p.rel_alt_m)
                elif (
                    isinstance(rec, LoggedMavlink)
                    and rec.msgid == mavlink.MAVLINK_MSG_ID_HOME_POSITION
                ):
                    home = _home_position(rec.packet) or home
        except TruncatedLogError as err:
            _log.warning("%s", err)
            truncated.append(str(err))
    if last is None:
        names = ", ".join(str(p) for p in files)
        cut = " (the log was cut off before one was written)" if truncated else ""
        raise FlightLogError(f"{names}: no /holes record{cut}: nothing to export")
    if home is not None:
        source = "HOME_POSITION"
    elif first_pos is not None:
        home, source = first_pos, "first logged position"
    else:
        source = "unknown"
    gate = last.announce_gate()
    tiers = last.tiers()
    if gate is None:
        _log.info(
            "%s: the log predates recorded tiers; tiers from the default gate %s",
            files[0],
            AnnounceGate().summary(),
        )
    use = gate or AnnounceGate()
    return FlightHoles(
        paths=files,
        truncated=tuple(truncated),
        holes=tuple(sorted(holes, key=lambda h: h.id)),
        holes_t_unix_ns=last.t_unix_ns,
        holes_records=n_records,
        home=home,
        home_source=source,
        boot_to_unix_ns=offset_frames if offset_frames is not None else offset_poses,
        thumbnails=views.thumbnails(holes, thumb_height_px) if thumbnails else {},
        frames_read=frames,
        gate=use,
        gate_recorded=gate is not None,
        tiers=tiers if tiers is not None else {h.id: use.tier(h) for h in holes},
    )
