"""The station's audit trail: who changed which hole, when, from what to what.

``DIR/audit.jsonl``, one JSON object per line, appended and fsynced before the change is
acknowledged, never rewritten (the station only ever opens it to append)::

    {"t_unix_ns": 1764766800000000000, "pairing": "p1", "operator": "Ana",
     "client": "192.168.1.23", "hole": 3, "mark_from": "new", "mark_to": "confirmed",
     "tier_from": "review", "tier_to": "confirmed"}

``pairing`` is the id of the operator's pairing (:mod:`ground.station.pairing`) and
``operator`` the name the station's user gave that pairing, never a name typed in the page;
``client`` the address the request came from. A line cut by a power loss is skipped when
the trail is read back.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from holescan.ground.errors import GroundError

__all__ = ["AUDIT_FILE", "AuditEntry", "AuditError", "AuditTrail"]

_log = logging.getLogger(__name__)

AUDIT_FILE = "audit.jsonl"


class AuditError(GroundError):
    """The audit trail cannot be written (the change it was for is not made)."""


@dataclass(frozen=True)
class AuditEntry:
    """One change: Unix clock ns, who (pairing id, its operator, address), which hole, mark
    and tier before/after."""

    t_unix_ns: int
    pairing: str
    operator: str
    client: str
    hole: int
    mark_from: str
    mark_to: str
    tier_from: str
    tier_to: str


class AuditTrail:
    """Append-only ``DIR/audit.jsonl`` (see the module docstring)."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / AUDIT_FILE
        self._lock = threading.Lock()

    def append(self, entry: AuditEntry) -> None:
        """Write ``entry`` as one line, flushed and fsynced (raises :class:`AuditError` if
        it cannot: a change that cannot be audited is not made)."""
        line = json.dumps(asdict(entry), separators=(",", ":"), ensure_ascii=False) + "\n"
        with self._lock:
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
                try:
                    os.write(fd, line.encode("utf-8"))
                    os.fsync(fd)
                finally:
                    os.close(fd)
            except OSError as err:
                raise AuditError(f"cannot append to {self.path}: {err.strerror}") from err

    def read(self) -> list[dict[str, Any]]:
        """Every complete entry, oldest first (none when there is no trail yet)."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return []
        out = []
        for line in text.splitlines():
            try:
                d = json.loads(line)
            except json.JSONDecodeError:
                _log.warning("%s: a cut line skipped", self.path)
                continue
            if isinstance(d, dict):
                out.append(d)
        return out
