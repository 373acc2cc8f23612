"""The ground-link datagram: one JSON object per UDP datagram, bounded in size and depth.

A command datagram (ground station -> robot), UTF-8 JSON, at most :data:`MAX_DATAGRAM`
bytes and :data:`MAX_DEPTH` levels of nesting::

    {"v": 1, "src": "ctl-lab-4711", "seq": 1718000000123456789, "t": 1718000000.123,
     "cmd": "takeoff", "args": {"height": 1.0}, "hmac": "<64 hex digits>"}

* ``v``: format version, 1.
* ``src``: the sender's name (1-64 printable ASCII characters); sequence numbers are
  tracked per sender.
* ``seq``: integer in [0, 2**63), strictly increasing per sender.
* ``t``: the sender's Unix time [s] when it signed the datagram.
* ``cmd``: the command name (lower case letters and ``_``); ``args``: its arguments (an
  object; optional, default ``{}``).
* ``hmac``: HMAC-SHA256 (hex) of :func:`canonical` of every other field (``rdm.ground.auth``).

An acknowledgement datagram (robot -> the sender's address) carries ``v``, ``src`` (the
robot's name), ``to`` (the command's sender), ``ack`` (the command's ``seq``, or null when
the datagram could not be read), ``t``, ``outcome`` (``accepted``, ``rejected`` or
``pending``), ``reason`` and ``detail`` (null when accepted), ``cmd``, optionally
``result`` and ``duplicate``, and its own ``hmac`` over the rest.

Parsing never recurses deeper than :data:`MAX_DEPTH`: the nesting is measured on the raw
bytes (brackets outside strings) before ``json.loads`` sees them, so a datagram of 1000
``[`` is refused as ``too_deep`` instead of exhausting Python's recursion limit.
"""

from __future__ import annotations

import json
import math
import re
from enum import Enum
from typing import Any

import numpy as np

#: Format version carried in ``v``.
VERSION = 1
#: Largest datagram accepted [bytes]. ASSUMPTION: 8 KiB holds the largest command (a
#: ``joints`` vector, a ``mocap`` sample) many times over and stays below one UDP datagram
#: on any link; the robot never reads more than this per datagram.
MAX_DATAGRAM = 8192
#: Deepest nesting of objects and arrays accepted (a command is at most 3 deep:
#: message -> args -> a vector).
MAX_DEPTH = 8
#: ``seq`` is below this (an int64 on every other implementation).
SEQ_LIMIT = 2**63

_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_NOT_BRACKET = bytes(b for b in range(256) if b not in b"[]{}")
_SRC = re.compile(r"[\x21-\x7e]{1,64}")
_CMD = re.compile(r"[a-z_]{1,64}")
_FIELDS = frozenset({"v", "src", "seq", "t", "cmd", "args", "hmac"})


class Reason(str, Enum):
    """Why a datagram or command was refused (the ``reason`` of a rejection ack)."""

    TOO_LARGE = "too_large"  # longer than MAX_DATAGRAM bytes
    TOO_DEEP = "too_deep"  # nested deeper than MAX_DEPTH
    MALFORMED = "malformed"  # not UTF-8, not JSON, not an object, or a field breaks a rule
    UNSIGNED = "unsigned"  # no hmac field (a key is configured)
    BAD_SIGNATURE = "bad_signature"  # hmac does not match the key
    REPLAYED = "replayed"  # seq not above the sender's last one
    STALE = "stale"  # t outside the time window
    TOO_MANY_SENDERS = "too_many_senders"  # sender table full of live senders
    UNKNOWN_COMMAND = "unknown_command"  # cmd is not in the command table
    BAD_ARGS = "bad_args"  # an argument breaks its rule (detail names the field)
    UNSUPPORTED = "unsupported"  # the node has no method for the command
    REFUSED = "refused"  # the node's method returned False
    NODE_ERROR = "node_error"  # the node's method raised
    BUSY = "busy"  # a plan is already being made
    PLAN_FAILED = "plan_failed"  # the planner did not reach the target
    NOT_PERCHED = "not_perched"  # ee is planned only while perched


class Rejected(Exception):
    """A datagram or command refused for ``reason``; ``detail`` names the field and rule."""

    def __init__(self, reason: Reason, detail: str) -> None:
        super().__init__(f"{reason.value}: {detail}")
        self.reason = reason
        self.detail = detail


def json_depth(data: bytes, limit: int = MAX_DEPTH) -> int:
    """Nesting depth of the JSON text ``data``, counted on the brackets outside strings
    (without recursion, in C-speed passes: a regex, ``bytes.translate``, a numpy cumulative
    sum); any depth above ``limit`` is reported as ``limit + 1``.

    For valid JSON this is the depth ``json.loads`` recurses to. For invalid text it is the
    depth ``json.loads`` reaches before failing: both read a string from a quote to the
    next unescaped quote, and an unterminated string's brackets are counted here.
    """
    brackets = _STRING.sub(b"", data).translate(None, _NOT_BRACKET)
    if not brackets:
        return 0
    codes = np.frombuffer(brackets, dtype=np.uint8)
    steps = np.where((codes == 0x5B) | (codes == 0x7B), 1, -1)
    return min(max(0, int(np.cumsum(steps).max())), limit + 1)


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text[:20]} is not finite")
    return value


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {key[:32]!r}")
        out[key] = value
    return out


def decode(data: bytes, max_size: int = MAX_DATAGRAM, max_depth: int = MAX_DEPTH) -> Any:
    """JSON value of ``data``; raises :class:`Rejected` (``too_large``, ``too_deep`` or
    ``malformed``) for anything else. NaN/Infinity, numbers that overflow to infinity and
    duplicate keys are malformed."""
    if len(data) > max_size:
        raise Rejected(Reason.TOO_LARGE, f"{len(data)} bytes, limit {max_size}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise Rejected(Reason.MALFORMED, f"not UTF-8 (byte {exc.start})") from None
    if json_depth(data, max_depth) > max_depth:
        raise Rejected(Reason.TOO_DEEP, f"nested deeper than {max_depth}")
    try:
        return json.loads(
            text,
            parse_constant=_no_constant,
            parse_float=_finite_float,
            object_pairs_hook=_unique_keys,
        )
    except RecursionError:  # not reachable after json_depth; kept as the last guard
        raise Rejected(Reason.TOO_DEEP, "recursion limit") from None
    except ValueError as exc:  # JSONDecodeError, int digit limit, our hooks
        raise Rejected(Reason.MALFORMED, f"not JSON: {str(exc)[:80]}") from None


def canonical(fields: dict[str, Any]) -> bytes:
    """The bytes an HMAC covers: ``fields`` without ``hmac``, keys sorted, no spaces,
    ASCII only (``json.dumps(sort_keys=True, separators=(",", ":"))``)."""
    body = {k: v for k, v in fields.items() if k != "hmac"}
    return json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def encode(fields: dict[str, Any]) -> bytes:
    """The datagram bytes of ``fields`` (canonical form, ``hmac`` included)."""
    return json.dumps(fields, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def as_finite(x: Any) -> float | None:
    """``x`` as a float if it is a number (not a bool) that a float holds finitely (a
    400-digit integer is not), else None."""
    if not _is_number(x):
        return None
    try:
        v = float(x)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None


def check_command(msg: Any) -> dict[str, Any]:
    """``msg`` if it is a well-formed command (module doc), else :class:`Rejected`
    (``malformed``) naming the field and its rule. ``hmac`` is checked by ``rdm.ground.auth``.
    """
    if not isinstance(msg, dict):
        raise Rejected(Reason.MALFORMED, f"not a JSON object but {type(msg).__name__}")
    extra = sorted(set(msg) - _FIELDS)
    if extra:
        raise Rejected(Reason.MALFORMED, f"unknown field {extra[0][:32]!r}")
    if msg.get("v") != VERSION or isinstance(msg.get("v"), bool):
        raise Rejected(Reason.MALFORMED, f"v: must be {VERSION}")
    src = msg.get("src")
    if not (isinstance(src, str) and _SRC.fullmatch(src)):
        raise Rejected(Reason.MALFORMED, "src: must be 1-64 printable ASCII characters")
    seq = msg.get("seq")
    if not (isinstance(seq, int) and not isinstance(seq, bool) and 0 <= seq < SEQ_LIMIT):
        raise Rejected(Reason.MALFORMED, "seq: must be an integer in [0, 2**63)")
    if as_finite(msg.get("t")) is None:
        raise Rejected(Reason.MALFORMED, "t: must be a finite number (Unix time, s)")
    cmd = msg.get("cmd")
    if not (isinstance(cmd, str) and _CMD.fullmatch(cmd)):
        raise Rejected(Reason.MALFORMED, "cmd: must be 1-64 of a-z and _")
    if not isinstance(msg.get("args", {}), dict):
        raise Rejected(Reason.MALFORMED, "args: must be an object")
    return msg


def json_safe(value: Any) -> Any:
    """``value`` as plain JSON data: non-finite floats become None, numpy arrays and
    scalars become lists and numbers, tuples lists, other objects their ``str``."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    tolist = getattr(value, "tolist", None)  # numpy arrays and scalars
    if callable(tolist):
        return json_safe(tolist())
    return str(value)
