"""What a Python fuzz target is, the findings it raises, and the independent oracles the
targets share.

A target is a function ``check(data: bytes) -> None`` that feeds ``data`` to one parser
the way the stack feeds it bytes from outside, and raises a :class:`Finding` when the
parser breaks a rule beyond "no crash, no hang" (a bad-checksum frame accepted, a frame
that does not re-encode to its bytes, a NaN where the format has none, an error that
escapes the parser's documented error type). Any other exception escaping ``check`` is a
crash of the parser.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any


class Finding(AssertionError):
    """A rule broken by the parser; ``kind`` is the class counted in the campaign table."""

    kind = "finding"


class BadFrameAccepted(Finding):
    """A frame (or datagram) whose checksum, BCC or signature is wrong was delivered."""

    kind = "bad_frame_accepted"


class NotCanonical(Finding):
    """An accepted frame re-encodes to other bytes than those it was decoded from."""

    kind = "not_canonical"


class NonFinite(Finding):
    """A decoder returned NaN or infinity where the format cannot carry one."""

    kind = "non_finite"


class WrongCount(Finding):
    """A counter disagrees with the events the parser returned."""

    kind = "wrong_count"


@dataclass(frozen=True)
class Target:
    """One fuzz target.

    ``seeds``: inputs built from the ``firmware_protocol/`` golden vectors (the corpus is
    seeded from them). ``generate``: optional structure-aware inputs (a random source in,
    one input out) mixed into the mutation engine. ``isolated``: the parser is native code
    that can take the process down (a stack overflow), so engines run it in a child
    process per batch.
    """

    name: str
    check: Callable[[bytes], None]
    seeds: Callable[[], Iterable[bytes]]
    generate: Callable[[random.Random], bytes] | None = None
    isolated: bool = False
    about: str = ""
    notes: tuple[str, ...] = field(default=())


def rosserial_frame_ok(raw: bytes) -> bool:
    """The rosserial v2 acceptance rule (fact sheet sec. 1.2) from the bytes alone:
    ``FF FE``, ``len_lo + len_hi + len_chk == 255 (mod 256)``, a frame of ``len + 8``
    bytes, ``topic_lo + topic_hi + sum(payload) + msg_chk == 255 (mod 256)``."""
    if len(raw) < 8 or raw[0] != 0xFF or raw[1] != 0xFE:
        return False
    n = raw[2] + 256 * raw[3]
    return (
        (raw[2] + raw[3] + raw[4]) % 256 == 255 and len(raw) == n + 8 and sum(raw[5:]) % 256 == 255
    )


def rosserial_frame(topic_id: int, payload: bytes) -> bytes:
    """A rosserial v2 frame written from the fact sheet's formula (the harness's own
    encoder, for the re-encoding check)."""
    n = len(payload)
    head = bytes([0xFF, 0xFE, n & 0xFF, n >> 8, 255 - ((n & 0xFF) + (n >> 8)) % 256])
    topic = bytes([topic_id & 0xFF, topic_id >> 8])
    return head + topic + payload + bytes([255 - (sum(topic) + sum(payload)) % 256])


def leptrino_frame(payload: bytes) -> bytes:
    """A Leptrino frame written from the framing notes (``firmware_protocol/leptrino/
    FRAMING.md``): DLE STX, payload with DLE doubled, DLE ETX, BCC = XOR(payload) ^ ETX."""
    bcc = 0x03
    for b in payload:
        bcc ^= b
    return b"\x10\x02" + payload.replace(b"\x10", b"\x10\x10") + b"\x10\x03" + bytes([bcc])


def all_finite(value: Any, path: str = "") -> None:
    """Raise :class:`NonFinite` naming the first NaN or infinity found in ``value``
    (nested dicts, lists, tuples, dataclass-like objects with ``__dict__``)."""
    if isinstance(value, bool) or value is None or isinstance(value, (int, str, bytes)):
        return
    if isinstance(value, float):
        if not math.isfinite(value):
            raise NonFinite(f"{path or 'value'} = {value!r}")
        return
    if isinstance(value, dict):
        for k, v in value.items():
            all_finite(v, f"{path}.{k}")
        return
    if isinstance(value, (list, tuple)):
        for k, v in enumerate(value):
            all_finite(v, f"{path}[{k}]")
        return
    fields = getattr(value, "__dict__", None)
    if isinstance(fields, dict):
        all_finite(fields, path)


def same_value(a: Any, b: Any) -> bool:
    """Equality where NaN equals NaN (the values decoded from one float32 NaN pattern)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b, strict=True))
    if hasattr(a, "__dataclass_fields__") and type(a) is type(b):
        return all(same_value(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    return a == b


def chunks(data: bytes) -> list[bytes]:
    """``data`` cut into reads of 1 to 61 bytes (the size a function of the input's
    length, so one input always reads the same way and different inputs read differently),
    as a serial port hands bytes over in pieces."""
    step = 1 + len(data) % 61
    return [data[k : k + step] for k in range(0, len(data), step)] or [b""]
