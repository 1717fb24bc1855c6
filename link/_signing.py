"""MAVLink 2 message signing: one secret key shared by the vehicle's hole server and the
ground station, so neither takes orders or holes from anyone without it.

pymavlink does the signing (``mavfile.setup_signing``: a SHA-256 signature of 6 bytes,
a 48-bit timestamp in 10 us units since 2015 and a link id on every packet). With a key
set, a link signs everything it sends and **drops every unsigned or wrongly signed
packet** it receives (pymavlink raises "Invalid signature"; read with robust parsing it is
a ``BAD_DATA`` message that nothing acts on), and a replayed packet (a timestamp not newer
than the last of its stream) too.

The key is 32 bytes, given as 64 hex digits or as a passphrase, which becomes the key the
way MAVProxy's ``signing key PASSPHRASE`` / ``signing setup PASSPHRASE`` make it (SHA-256
of the passphrase), so one passphrase serves MAVProxy, the vehicle and the ground station.
The key is never logged: :class:`SigningKey` shows only a fingerprint (4 bytes of a
SHA-256 of the key) to check that both ends hold the same one.

A peer's first signed packet is accepted when its timestamp is at most one minute behind
the receiver's own (pymavlink's rule): the companion computer's clock must be set (GPS,
NTP or chrony from the autopilot) before it flies with signing.
"""

from __future__ import annotations

import hashlib
import string
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from holescan.errors import InputError

__all__ = ["SigningKey"]

_KEY_BYTES = 32


@dataclass(frozen=True)
class SigningKey:
    """A MAVLink 2 signing key (32 bytes). ``repr``/``str`` never show it.

    >>> k = SigningKey.from_passphrase("rubble")
    >>> k == SigningKey.from_hex(k.key.hex()), "rubble" in repr(k), len(k.fingerprint)
    (True, False, 8)
    """

    key: bytes = field(repr=False)

    def __post_init__(self) -> None:
        if len(self.key) != _KEY_BYTES:
            raise InputError(f"a MAVLink signing key is {_KEY_BYTES} bytes, got {len(self.key)}")

    def __repr__(self) -> str:
        return f"SigningKey(fingerprint={self.fingerprint})"

    __str__ = __repr__

    @property
    def fingerprint(self) -> str:
        """8 hex digits of SHA-256(key): the same at both ends when the keys are."""
        return hashlib.sha256(b"holescan-fingerprint" + self.key).hexdigest()[:8]

    @classmethod
    def from_hex(cls, text: str) -> SigningKey:
        """The key as 64 hex digits."""
        text = text.strip()
        if len(text) != 2 * _KEY_BYTES or any(c not in string.hexdigits for c in text):
            raise InputError("a MAVLink signing key in hex is 64 hex digits (32 bytes)")
        return cls(bytes.fromhex(text))

    @classmethod
    def from_passphrase(cls, passphrase: str) -> SigningKey:
        """SHA-256 of an ASCII passphrase, as MAVProxy's ``signing key PASSPHRASE``."""
        if not passphrase or not passphrase.isascii() or any(c.isspace() for c in passphrase):
            raise InputError("a MAVLink signing passphrase is ASCII without spaces (MAVProxy's)")
        return cls(hashlib.sha256(passphrase.encode("ascii")).digest())

    @classmethod
    def from_text(cls, text: str) -> SigningKey:
        """64 hex digits as the key itself, anything else as a passphrase."""
        text = text.strip()
        if len(text) == 2 * _KEY_BYTES and all(c in string.hexdigits for c in text):
            return cls.from_hex(text)
        return cls.from_passphrase(text)

    @classmethod
    def from_file(cls, path: Path) -> SigningKey:
        """The key in a file: one line, 64 hex digits or a passphrase (:meth:`from_text`)."""
        try:
            text = path.read_text(encoding="ascii")
        except (OSError, UnicodeDecodeError) as err:
            raise InputError(f"cannot read the MAVLink signing key file {path}: {err}") from err
        lines = [line for line in text.splitlines() if line.strip()]
        if len(lines) != 1:
            raise InputError(f"{path}: a MAVLink signing key file holds one line")
        try:
            return cls.from_text(lines[0])
        except InputError as err:
            raise InputError(f"{path}: {err}") from err

    def apply(self, conn: Any) -> None:
        """Sign everything ``conn`` (a pymavlink ``mavfile``) sends; refuse every unsigned
        or badly signed packet it receives."""
        conn.setup_signing(self.key, sign_outgoing=True, allow_unsigned_callback=None)
