"""Operators' pairings: who may mark holes on the live page, each by a link of their own.

The station's user issues one pairing per operator (``holescan ground --pair NAME`` at
start, ``holescan pair -o DIR NAME`` while it runs): a pairing id (``p1``, ``p2``, ...), the
operator's name as the station's user gave it, and a random token (32 bytes) shown once in
the pairing link ``http://STATION/?token=TOKEN``. The operator opens the link once; the
page checks it with the station (``POST /pair``) before it keeps anything, and the station
answers with a cookie (``HttpOnly; SameSite=Strict``) that the page's later requests carry.
Every mark is written to the audit trail with the pairing id and its name: an operator is
who their pairing says, never a name typed in the page.

``DIR/.station-pairings.json`` (mode 0600) keeps each pairing with a SHA-256 hash of its
token, never the token itself: the file (or a backup of the folder) cannot pair a browser.
A restart keeps every browser paired; deleting a pairing from the file (or the file)
un-pairs its browsers. The station re-reads the file when it changes, so pairings issued by
``holescan pair`` while it runs work at once.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import logging
import os
import re
import secrets
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from holescan.errors import InputError

__all__ = ["PAIRINGS_FILE", "Pairing", "Pairings", "check_operator"]

_log = logging.getLogger(__name__)

PAIRINGS_FILE = ".station-pairings.json"
_OPERATOR_MAX = 40
_TOKEN = re.compile(r"[A-Za-z0-9_-]{20,100}")


def check_operator(name: object) -> str:
    """An operator's name for a pairing: 1-40 printable characters, trimmed.

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


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class Pairing:
    """One operator's pairing: its id (``p1``, ...), the operator's name, when issued."""

    id: str
    operator: str
    issued_unix_ns: int

    def __str__(self) -> str:
        return f"{self.operator} ({self.id})"


class Pairings:
    """The station's pairings in ``DIR/.station-pairings.json`` (see the module docstring).

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     ps = Pairings(Path(d))
    ...     p, token = ps.issue("Ana")
    ...     ps.check(token) == p, ps.check("x" * 43), ps.check(None), p.id
    (True, None, None, 'p1')
    """

    def __init__(self, folder: Path) -> None:
        self.path = folder / PAIRINGS_FILE
        self._lock = threading.Lock()
        self._stamp: tuple[int, int] | None = None
        self._by_digest: dict[str, Pairing] = {}
        self._load()

    def __repr__(self) -> str:  # never a token or a hash in a log line
        return f"Pairings({self.path}, {len(self._by_digest)} paired)"

    def _file_stamp(self) -> tuple[int, int] | None:
        try:
            st = self.path.stat()
        except FileNotFoundError:
            return None
        except OSError as err:
            raise InputError(f"cannot read {self.path}: {err.strerror}") from err
        return st.st_mtime_ns, st.st_size

    def _load(self) -> None:
        stamp = self._file_stamp()
        if stamp == self._stamp and (stamp is not None or not self._by_digest):
            return
        found: dict[str, Pairing] = {}
        if stamp is not None:
            try:
                doc = json.loads(self.path.read_text(encoding="utf-8"))
                for d in doc["pairings"]:
                    p = Pairing(str(d["id"]), str(d["operator"]), int(d["issued_unix_ns"]))
                    found[str(d["token_sha256"])] = p
            except (OSError, ValueError, KeyError, TypeError) as err:
                raise InputError(
                    f"{self.path} is not a pairings file ({err}): move it away to start over"
                ) from err
        self._by_digest, self._stamp = found, stamp

    def all(self) -> list[Pairing]:
        """Every pairing, oldest first."""
        with self._lock:
            self._load()
            return sorted(self._by_digest.values(), key=lambda p: int(p.id[1:]))

    def check(self, token: str | None) -> Pairing | None:
        """The pairing whose token this is (None: none, malformed or unknown)."""
        if not token or not _TOKEN.fullmatch(token):
            return None
        given = _digest(token)
        with self._lock:
            try:
                self._load()
            except InputError as err:  # keep the pairings already known
                _log.error("%s", err)
            for digest, p in self._by_digest.items():
                if hmac.compare_digest(digest, given):
                    return p
        return None

    def issue(self, operator: str) -> tuple[Pairing, str]:
        """A new pairing for ``operator``: (the pairing, its token, to be shown once)."""
        name = check_operator(operator)
        token = secrets.token_urlsafe(32)
        with self._lock:
            self._load()
            n = max((int(p.id[1:]) for p in self._by_digest.values()), default=0) + 1
            p = Pairing(f"p{n}", name, time.time_ns())
            rows = [
                {"id": q.id, "operator": q.operator, "issued_unix_ns": q.issued_unix_ns}
                | {"token_sha256": d}
                for d, q in {**self._by_digest, _digest(token): p}.items()
            ]
            self._write({"pairings": rows})
            self._by_digest[_digest(token)] = p
            self._stamp = self._file_stamp()
        return p, token

    def _write(self, doc: dict[str, object]) -> None:
        """The whole file anew: ``.part`` (0600), fsync, rename over the old one."""
        part = self.path.with_name(self.path.name + ".part")
        with contextlib.suppress(FileNotFoundError):
            part.unlink()
        try:
            fd = os.open(part, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(doc, f, indent=1)
                f.write("\n")
                f.flush()
                os.fsync(f.fileno())
            os.replace(part, self.path)
        except OSError as err:
            raise InputError(f"cannot write {self.path}: {err.strerror}") from err
