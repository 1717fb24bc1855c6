"""The station's audit trail: who changed which hole, when, from what to what.

``DIR/audit.jsonl``, one JSON object per line, appended and fsynced before the change is
acknowledged, never rewritten (the station only ever opens it to append)::

    {"t_unix_ns": 1764766800000000000, "operator": "Ana", "client": "192.168.1.23",
     "hole": 3, "mark_from": "new", "mark_to": "confirmed",
     "tier_from": "review", "tier_to": "confirmed"}

``operator`` is the name the operator typed once in that browser; ``client`` the address
the request came from. A line cut by a power loss is skipped when the trail is read back.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from holescan.errors import InputError
from holescan.ground.errors import GroundError

__all__ = ["AUDIT_FILE", "AuditEntry", "AuditError", "AuditTrail", "check_operator"]

_log = logging.getLogger(__name__)

AUDIT_FILE = "audit.jsonl"
_OPERATOR_MAX = 40


class AuditError(GroundError):
    """The audit trail cannot be written (the change it was for is not made)."""


def check_operator(name: object) -> str:
    """An operator's name as given with a mark: 1-40 printable characters, trimmed.

    >>> check_operator("  Ana B. ")
    'Ana B.'
    >>> check_operator("")
    Traceback (most recent call last):
    ...
    holescan.errors.InputError: an operator name (1-40 printable characters) is required
    """
    text = name.strip() if isinstance(name, str) else ""
    if not 1 <= len(text) <= _OPERATOR_MAX or not text.isprintable():
        raise InputError(f"an operator name (1-{_OPERATOR_MAX} printable characters) is required")
    return text


@dataclass(frozen=True)
class AuditEntry:
    """One change: Unix clock ns, who (name, address), which hole, mark and tier before/after."""

    t_unix_ns: int
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
