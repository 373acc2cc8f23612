"""Authentication of ground-link datagrams: the shared key file, HMAC-SHA256 signatures and
replay protection.

**Key file.** At least 32 random bytes, stored either raw or as hex (at least 64 hex digits,
surrounding whitespace ignored); ``rdm ctl keygen FILE`` writes 64 hex digits and a newline
with mode 0600. A key file that every user may read or write (``o+r`` or ``o+w``) is
refused: the key is the only thing between the network and the robot's motors.

**Signature.** ``hmac`` = hex HMAC-SHA256(key, :func:`rdm.ground.message.canonical` of the
datagram's other fields), compared in constant time (``hmac.compare_digest``).

**Replay protection.** A signed datagram is accepted only if its ``t`` lies within
``window_s`` of the robot's clock and its ``seq`` is above the last ``seq`` accepted from
the same ``src``. The same datagram again (same ``src``, ``seq`` and ``hmac``: a client's
retry) is a *duplicate*: it gets the first answer again and is never applied twice.
ASSUMPTION: the ground station's and the robot's clocks agree to well within the window
(both synchronised by NTP/chrony on the lab network); the window bounds how long a
captured datagram could be replayed to a robot that forgot its sender.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import stat
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rdm.ground.message import Reason, Rejected, canonical, check_command, decode

#: Shortest key [bytes] (HMAC-SHA256's block-size guidance: at least the hash's 32 bytes).
KEY_MIN_BYTES = 32
#: Largest key file read [bytes].
KEY_MAX_BYTES = 4096
#: Default time window [s] around the robot's clock for a datagram's ``t``.
WINDOW_S = 2.0
#: Senders remembered at once.
MAX_SENDERS = 64
_HEX = frozenset("0123456789abcdefABCDEF")


class KeyFileError(ValueError):
    """A key file that cannot be used; the message names the file and the rule."""


def load_key(path: str | Path) -> bytes:
    """The key in ``path`` (module doc); :class:`KeyFileError` names the file and the rule
    it breaks (missing, world-readable or -writable, too short, too long)."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise KeyFileError(f"key file {path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise KeyFileError(f"key file {path}: not a regular file")
    if st.st_mode & (stat.S_IROTH | stat.S_IWOTH):
        raise KeyFileError(
            f"key file {path}: mode {stat.S_IMODE(st.st_mode):04o} lets every user read or "
            f"write it; a key file must not be world-readable or -writable "
            f"(chmod 600 {path})"
        )
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise KeyFileError(f"key file {path}: {exc.strerror or exc}") from None
    if len(raw) > KEY_MAX_BYTES:
        raise KeyFileError(f"key file {path}: {len(raw)} bytes, more than {KEY_MAX_BYTES}")
    text = raw.strip()
    if text and all(chr(b) in _HEX for b in text):
        if len(text) < 2 * KEY_MIN_BYTES or len(text) % 2:
            raise KeyFileError(
                f"key file {path}: {len(text)} hex digits; a hex key needs an even number, "
                f"at least {2 * KEY_MIN_BYTES}"
            )
        return bytes.fromhex(text.decode())
    if len(raw) < KEY_MIN_BYTES:
        raise KeyFileError(
            f"key file {path}: {len(raw)} bytes; a key needs at least {KEY_MIN_BYTES} random "
            f"bytes (or {2 * KEY_MIN_BYTES} hex digits)"
        )
    return raw


def write_key(path: str | Path) -> None:
    """Write a new key file: 32 bytes from ``os.urandom`` as 64 hex digits and a newline,
    mode 0600. Refuses (``FileExistsError``) to overwrite an existing file."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        os.fchmod(fd, 0o600)  # whatever the umask
        os.write(fd, os.urandom(KEY_MIN_BYTES).hex().encode() + b"\n")
    finally:
        os.close(fd)


def signature(fields: dict[str, Any], key: bytes) -> str:
    """Hex HMAC-SHA256 of ``fields``' canonical bytes (``hmac`` excluded)."""
    return hmac.new(key, canonical(fields), hashlib.sha256).hexdigest()


def sign(fields: dict[str, Any], key: bytes | None) -> dict[str, Any]:
    """``fields`` with its ``hmac`` (a copy; unchanged without a key)."""
    out = {k: v for k, v in fields.items() if k != "hmac"}
    if key is not None:
        out["hmac"] = signature(out, key)
    return out


def signature_ok(fields: dict[str, Any], key: bytes) -> bool:
    """True if ``fields["hmac"]`` is the signature of the rest under ``key``."""
    given = fields.get("hmac")
    return isinstance(given, str) and hmac.compare_digest(
        given.encode("ascii", "replace"), signature(fields, key).encode()
    )


@dataclass
class Verdict:
    """What :meth:`Verifier.verify` decided about one datagram.

    ``kind``: ``accepted`` (apply ``message``), ``duplicate`` (answer with ``ack`` again,
    apply nothing) or ``rejected`` (``reason``, ``detail``). ``seq`` and ``src`` are the
    datagram's when it could be read that far (None otherwise)."""

    kind: str
    message: dict[str, Any] | None = None
    reason: Reason | None = None
    detail: str | None = None
    seq: int | None = None
    src: str | None = None
    ack: dict[str, Any] | None = None


@dataclass
class _Sender:
    seq: int
    mac: str
    accepted_at: float
    ack: dict[str, Any] | None = None


@dataclass
class Verifier:
    """Checks datagrams in order: size, depth, JSON, fields, signature, time window,
    sequence. ``key`` None accepts unsigned datagrams (``rdm onboard --insecure-control``);
    the time window and the sequence numbers are checked all the same.

    The sender table holds at most ``max_senders``; a new sender replaces the one heard
    from longest ago only if that was more than twice ``window_s`` ago (its old datagrams
    are stale by then, so forgetting it opens no replay); otherwise it is refused."""

    key: bytes | None
    window_s: float = WINDOW_S
    max_senders: int = MAX_SENDERS
    senders: OrderedDict[str, _Sender] = field(default_factory=OrderedDict)

    def verify(self, data: bytes, wall_now: float) -> Verdict:
        """The verdict on ``data`` received at Unix time ``wall_now``. An accepted datagram's
        ``seq`` becomes its sender's last; nothing else changes any state."""
        try:
            msg = check_command(decode(data))
        except Rejected as exc:
            return Verdict("rejected", reason=exc.reason, detail=exc.detail)
        src, seq = msg["src"], msg["seq"]
        mac = msg.get("hmac")

        def reject(reason: Reason, detail: str) -> Verdict:
            return Verdict("rejected", reason=reason, detail=detail, seq=seq, src=src)

        if self.key is not None:
            if mac is None:
                return reject(Reason.UNSIGNED, "no hmac field")
            if not signature_ok(msg, self.key):
                return reject(Reason.BAD_SIGNATURE, "hmac does not match the key")
        elif mac is not None and not isinstance(mac, str):
            return reject(Reason.MALFORMED, "hmac: must be a hex string")
        mac = mac or ""
        known = self.senders.get(src)
        if known is not None and seq == known.seq and mac == known.mac:  # macs are public
            if abs(msg["t"] - wall_now) > self.window_s:
                return reject(Reason.STALE, self._stale_detail(msg["t"], wall_now))
            return Verdict("duplicate", message=msg, seq=seq, src=src, ack=known.ack)
        if abs(msg["t"] - wall_now) > self.window_s:
            return reject(Reason.STALE, self._stale_detail(msg["t"], wall_now))
        if known is not None and seq <= known.seq:
            return reject(Reason.REPLAYED, f"seq {seq} not above {src}'s last {known.seq}")
        if known is None and not self._make_room(wall_now):
            return reject(Reason.TOO_MANY_SENDERS, f"{self.max_senders} senders active")
        self.senders[src] = _Sender(seq, mac, wall_now)
        self.senders.move_to_end(src)
        return Verdict("accepted", message=msg, seq=seq, src=src)

    def remember_ack(self, src: str, seq: int, ack: dict[str, Any]) -> None:
        """Keep ``ack`` as the answer to a duplicate of ``src``'s datagram ``seq``."""
        known = self.senders.get(src)
        if known is not None and known.seq == seq:
            known.ack = ack

    def _stale_detail(self, t: float, wall_now: float) -> str:
        return f"t is {t - wall_now:+.3f} s from the robot's clock (window +-{self.window_s} s)"

    def _make_room(self, wall_now: float) -> bool:
        if len(self.senders) < self.max_senders:
            return True
        oldest_src, oldest = next(iter(self.senders.items()))
        # Every datagram of that sender up to its last seq carries t <= accepted_at +
        # window_s, so after twice the window all of them are stale.
        if wall_now - oldest.accepted_at > 2.0 * self.window_s:
            del self.senders[oldest_src]
            return True
        return False
