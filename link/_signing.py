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

**The signature is verified before its timestamp is believed.** pymavlink 2.4.50's
``MAVLink.check_signature`` stores a stream's timestamp *before* it compares the
signature: anyone on the network, without the key, can send one badly signed packet per
(link id, system, component) with the timestamp 2**48 - 1, and every later genuine packet
of that stream is refused as a replay until a restart. :meth:`SigningKey.apply` replaces
that check on the link's MAVLink object by :func:`verified_signature` (the C library's
order: signature first, then the replay window), so a forger's packet changes nothing.
``docs/trust-model.md`` says what this protects and what not.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import string
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from holescan.errors import InputError

__all__ = ["SigningKey", "guard_signing", "verified_signature"]

_KEY_BYTES = 32
_NEW_STREAM_BEHIND = 6000 * 1000  # 10 us units: a new stream at most 1 minute behind ours


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
        guard_signing(conn.mav)


def guard_signing(mav: Any) -> None:
    """Make ``mav`` (a pymavlink ``MAVLink`` object with a signing key set) check incoming
    signatures with :func:`verified_signature` instead of its own ``check_signature``."""
    mav.check_signature = functools.partial(verified_signature, mav)


def verified_signature(mav: Any, msgbuf: bytes, src_system: int, src_component: int) -> bool:
    """Whether a signed MAVLink 2 packet ``msgbuf`` (whole, signature included) is genuine
    and new; only then is its stream's timestamp recorded.

    The same rules as pymavlink's ``check_signature`` and the C library: the signature is
    the first 6 bytes of SHA-256(key + packet without the signature); a packet whose
    timestamp is not newer than the last one of its (link id, system, component) stream is
    a replay; a new stream's first timestamp may be at most one minute behind ours. But a
    badly signed packet never touches the state.
    """
    signing = mav.signing
    key = signing.secret_key
    if key is None or len(msgbuf) < 13:
        return False
    digest = hashlib.sha256(bytes(key) + bytes(msgbuf[:-6])).digest()[:6]
    if not hmac.compare_digest(digest, bytes(msgbuf[-6:])):
        return False
    timestamp = int.from_bytes(bytes(msgbuf[-12:-6]), "little")
    stream = (msgbuf[-13], src_system, src_component)
    last = signing.stream_timestamps.get(stream)
    if last is not None:
        if timestamp <= last:
            return False  # a replay
    elif timestamp + _NEW_STREAM_BEHIND < signing.timestamp:
        return False  # a new stream far in the past: an old recording replayed
    signing.stream_timestamps[stream] = timestamp
    signing.timestamp = max(signing.timestamp, timestamp)
    return True
