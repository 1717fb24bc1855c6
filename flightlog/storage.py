"""The flight logs in a folder: which are finished, the rate they were written at, and the
retention rule that removes the oldest finished ones to make room.

A flight's log is the set of files ``PREFIX_0000.mcap``, ``PREFIX_0001.mcap``, ... that
one :class:`~flightlog.writer.FlightLogWriter` wrote. It is *finished* when every
file of the set ends with an intact footer (closed cleanly) and no ``PREFIX_*.part`` file
sits beside it. An unfinished log (cut off by a crash or power loss; ``holescan log
recover`` repairs it) and any ``.part`` file are never removed; neither is a log the
caller names as current.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
from collections.abc import Collection
from pathlib import Path
from typing import Final

from holescan.flightlog.diskspace import DiskSpace
from holescan.flightlog.errors import FlightLogError
from holescan.flightlog.format import read_footer
from holescan.flightlog.layout import read_log_layout

__all__ = ["FlightLogSet", "flight_logs", "measured_rate", "remove_oldest_finished"]

_log = logging.getLogger(__name__)

_FILE: Final = re.compile(r"(?P<prefix>.+)_(?P<index>\d{4})\.mcap")
#: A log shorter than this says little about the rate a flight writes at.
MIN_MEASURED_S: Final = 10.0


@dataclasses.dataclass(frozen=True)
class FlightLogSet:
    """One flight's log files in a folder.

    prefix : the files' common path prefix (``FOLDER/flight-20261206T101500Z``).
    files : in index order. bytes : their total size. newest_mtime_ns : the last change
    of any of them. finished : every file closed cleanly and no ``.part`` beside them.
    """

    prefix: Path
    files: tuple[Path, ...]
    bytes: int
    newest_mtime_ns: int
    finished: bool


def _closed_cleanly(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            return read_footer(f, os.fstat(f.fileno()).st_size) is not None
    except OSError:
        return False


def flight_logs(folder: str | os.PathLike[str]) -> list[FlightLogSet]:
    """The flight logs in ``folder`` (not its subfolders), oldest first (by last change)."""
    root = Path(folder)
    groups: dict[str, list[Path]] = {}
    parts: set[str] = set()
    try:
        entries = list(root.iterdir())
    except FileNotFoundError:
        return []
    except OSError as err:
        raise FlightLogError(f"cannot list the log folder {root}: {err}") from err
    for path in entries:
        if path.name.endswith(".part"):
            m = _FILE.fullmatch(path.name.removesuffix(".part"))
            parts.add(m.group("prefix") if m else path.name)
            continue
        m = _FILE.fullmatch(path.name)
        if m is not None and path.is_file():
            groups.setdefault(m.group("prefix"), []).append(path)
    out = []
    for prefix, files in groups.items():
        files.sort()
        stats = [f.stat() for f in files]
        finished = prefix not in parts and all(_closed_cleanly(f) for f in files)
        out.append(
            FlightLogSet(
                prefix=root / prefix,
                files=tuple(files),
                bytes=sum(s.st_size for s in stats),
                newest_mtime_ns=max(s.st_mtime_ns for s in stats),
                finished=finished,
            )
        )
    out.sort(key=lambda s: (s.newest_mtime_ns, s.prefix.name))
    return out


def measured_rate(
    folder: str | os.PathLike[str],
    config: dict[str, str] | None = None,
    *,
    min_span_s: float = MIN_MEASURED_S,
) -> tuple[float, FlightLogSet] | None:
    """Bytes per second the newest finished flight log in ``folder`` was written at.

    config : ``holescan.config`` entries the log must have been written with (e.g. its
    ``log.color``, ``log.depth``, ``log.jpeg_quality`` as logged: JSON text), so a log of
    other image settings is not taken as the rate of this one. Logs shorter than
    ``min_span_s`` or unreadable are passed over. None when no log qualifies.
    """
    for log_set in reversed(flight_logs(folder)):
        if not log_set.finished:
            continue
        try:
            layouts = [read_log_layout(f) for f in log_set.files]
        except FlightLogError:
            continue
        logged = layouts[0].metadata.get("holescan.config", {})
        if config and any(logged.get(k) != v for k, v in config.items()):
            continue
        starts = [c.start_time_ns for lay in layouts for c in lay.chunks]
        ends = [c.end_time_ns for lay in layouts for c in lay.chunks]
        if not starts:
            continue
        span_s = (max(ends) - min(starts)) / 1e9
        if span_s >= min_span_s:
            return log_set.bytes / span_s, log_set
    return None


def remove_oldest_finished(
    folder: str | os.PathLike[str],
    need_free_bytes: int,
    disk: DiskSpace,
    *,
    keep: Collection[str | os.PathLike[str]] = (),
) -> list[FlightLogSet]:
    """Remove the oldest finished flight logs in ``folder`` until ``disk`` says it has
    ``need_free_bytes`` free or none is left to remove; return what was removed.

    keep : prefixes of logs never to remove (the current flight's). Unfinished logs and
    ``.part`` files are never removed.
    """
    protected = {Path(p).resolve() for p in keep}
    removed: list[FlightLogSet] = []
    for log_set in flight_logs(folder):
        if disk.free_bytes(folder) >= need_free_bytes:
            break
        if not log_set.finished or log_set.prefix.resolve() in protected:
            continue
        for path in log_set.files:
            try:
                path.unlink()
            except FileNotFoundError:
                pass
            except OSError as err:
                raise FlightLogError(f"cannot remove the old log {path}: {err}") from err
        _log.warning(
            "removed the finished flight log %s (%d files, %.1f MB) to make room",
            log_set.prefix,
            len(log_set.files),
            log_set.bytes / 1e6,
        )
        removed.append(log_set)
    return removed
