"""The onboard control port's readers (``rdm.ground``): the datagram decoder
(``message.decode``) and the verifier every datagram goes through (``auth.Verifier``).

``ground_decode`` input: one datagram. Checks: ``decode`` returns a JSON value or raises
``Rejected`` (``too_large``, ``too_deep``, ``malformed``); a value holds no NaN or infinity,
is nested at most ``MAX_DEPTH`` deep (measured here on the value) and serialises back
with ``json.dumps(allow_nan=False)``.

``ground_verify`` input: datagrams separated by byte 0x1E, given in order to a verifier
with a key and to one without (``--insecure-control``), the robot's clock 10 ms later for
each. Checks, with the rules re-derived here (``rdm/ground/message.py`` module text):
an accepted datagram of the keyed verifier carries the HMAC-SHA256 of its canonical
fields computed here with ``hmac``; every accepted datagram has well-formed fields, a
``t`` inside the window and a ``seq`` above the last one accepted from its sender; a
duplicate repeats that last datagram's ``src``, ``seq`` and ``hmac``; every verdict is
``accepted``, ``duplicate`` or ``rejected`` with a reason.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import random
import re
from collections.abc import Iterable
from typing import Any

from fuzz_targets.base import BadFrameAccepted, Finding, Target, all_finite
from rdm.ground.auth import Verifier, sign
from rdm.ground.message import MAX_DEPTH, Reason, Rejected, decode

#: The key of the keyed verifier (32 bytes; a fuzzing key, used nowhere else).
KEY = bytes(range(32))
#: The robot's clock at the first datagram [Unix s].
T0 = 1_718_000_000.0
SEPARATOR = b"\x1e"
_SRC = re.compile(r"[\x21-\x7e]{1,64}")
_CMD = re.compile(r"[a-z_]{1,64}")


def _depth(value: Any) -> int:
    if isinstance(value, dict):
        return 1 + max((_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_depth(v) for v in value), default=0)
    return 0


def check_decode(data: bytes) -> None:
    """Decode one datagram."""
    try:
        value = decode(data)
    except Rejected as exc:
        if exc.reason not in (Reason.TOO_LARGE, Reason.TOO_DEEP, Reason.MALFORMED):
            raise Finding(f"decode refused with {exc.reason}") from None
        return
    all_finite(value, "datagram")
    if _depth(value) > MAX_DEPTH:
        raise Finding(f"value nested {_depth(value)} deep accepted")
    json.dumps(value, allow_nan=False)


def _signature(fields: dict[str, Any]) -> str:
    body = {k: v for k, v in fields.items() if k != "hmac"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hmac.new(KEY, text.encode(), hashlib.sha256).hexdigest()


def _well_formed(msg: dict[str, Any], now: float, window: float) -> str:
    """Why ``msg`` should not have been accepted ("" when it is fine)."""
    if set(msg) - {"v", "src", "seq", "t", "cmd", "args", "hmac"}:
        return "unknown field"
    if msg.get("v") != 1 or isinstance(msg.get("v"), bool):
        return "v"
    if not (isinstance(msg.get("src"), str) and _SRC.fullmatch(msg["src"])):
        return "src"
    seq = msg.get("seq")
    if not (isinstance(seq, int) and not isinstance(seq, bool) and 0 <= seq < 2**63):
        return "seq"
    t = msg.get("t")
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not abs(t - now) <= window:
        return "t outside the window"
    if not (isinstance(msg.get("cmd"), str) and _CMD.fullmatch(msg["cmd"])):
        return "cmd"
    if not isinstance(msg.get("args", {}), dict):
        return "args"
    return ""


def check_verify(data: bytes) -> None:
    """Verify every datagram of ``data`` with a keyed and an unkeyed verifier."""
    for key in (KEY, None):
        verifier = Verifier(key)
        last: dict[str, tuple[int, str]] = {}  # src -> (seq, hmac) last accepted
        for k, datagram in enumerate(data.split(SEPARATOR)):
            now = T0 + 0.01 * k
            verdict = verifier.verify(datagram, now)
            if verdict.kind == "rejected":
                if not isinstance(verdict.reason, Reason) or not verdict.detail:
                    raise Finding(f"rejection without a reason: {verdict}")
                continue
            msg = verdict.message
            if not isinstance(msg, dict):
                raise Finding(f"{verdict.kind} without a message")
            why = _well_formed(msg, now, verifier.window_s)
            if why:
                raise BadFrameAccepted(f"{verdict.kind} datagram {k} ({why}): {datagram[:120]!r}")
            if key is not None and msg.get("hmac") != _signature(msg):
                raise BadFrameAccepted(f"datagram {k} {verdict.kind} with a wrong hmac")
            src, seq, mac = msg["src"], msg["seq"], msg.get("hmac") or ""
            if verdict.kind == "duplicate":
                if last.get(src) != (seq, mac):
                    raise BadFrameAccepted(f"datagram {k}: duplicate of nothing accepted")
            elif verdict.kind == "accepted":
                if src in last and seq <= last[src][0]:
                    raise BadFrameAccepted(f"datagram {k}: seq {seq} replayed")
                last[src] = (seq, mac)
            else:
                raise Finding(f"verdict kind {verdict.kind!r}")


def _datagram(k: int, seq: int, cmd: str, args: dict[str, Any], key: bytes | None) -> bytes:
    fields = {"v": 1, "src": "fuzz-ground", "seq": seq, "t": T0 + 0.01 * k, "cmd": cmd}
    if args:
        fields["args"] = args
    return json.dumps(sign(fields, key), sort_keys=True, separators=(",", ":")).encode()


COMMANDS: list[tuple[str, dict[str, Any]]] = [
    ("takeoff", {"height": 1.0}),
    ("land", {}),
    ("goto", {"position": [1.0, 2.0, 1.5], "yaw": 0.5}),
    ("joints", {"q": [0.1] * 10}),
    ("gains", {"profile": "perch"}),
    ("mocap", {"position": [0.0, 0.0, 1.0], "velocity": [0.0, 0.0, 0.0], "yaw": 0.0}),
    ("pose", {"position": [0.0, 0.0, 1.0], "quaternion": [0.0, 0.0, 0.0, 1.0]}),
    ("status", {}),
    ("heartbeat", {}),
    ("ee", {"position": [0.5, 0.0, -0.3]}),
]


def decode_seeds() -> Iterable[bytes]:
    """Signed datagrams of every command, an ack-shaped object, edge cases."""
    for k, (cmd, args) in enumerate(COMMANDS):
        yield _datagram(0, k + 1, cmd, args, KEY)
    yield b'{"v":1,"a":[[[[[[[[1]]]]]]]]}'
    yield b'{"a":1,"a":2}'
    yield b'{"x":NaN,"y":1e999,"z":"\\ud800"}'


def verify_seeds() -> Iterable[bytes]:
    """Sequences: each command signed; a retry (duplicate), a replay, a stale one, a bad
    hmac, an unsigned one, a second sender."""
    for k, (cmd, args) in enumerate(COMMANDS):
        yield _datagram(0, k + 1, cmd, args, KEY)
    first = _datagram(0, 5, "takeoff", {"height": 1.0}, KEY)
    yield SEPARATOR.join([first, first, _datagram(2, 4, "land", {}, KEY),
                          _datagram(3, 6, "land", {}, KEY)])  # fmt: skip
    stale = json.loads(_datagram(0, 9, "land", {}, None))
    stale["t"] = T0 - 60.0
    yield json.dumps(sign(stale, KEY)).encode()
    bad = json.loads(first)
    bad["hmac"] = "0" * 64
    yield SEPARATOR.join([json.dumps(bad).encode(), _datagram(1, 7, "status", {}, None)])


def _value(rng: random.Random, depth: int = 0) -> Any:
    kind = rng.randrange(8 if depth < 3 else 5)
    if kind == 0:
        return rng.choice((0, 1, -1, 2**63, -(2**63), 10**308, 10**309, 10**400, -(10**400)))
    if kind == 1:
        return rng.choice((0.0, -0.0, 1e308, -1e308, 5e-324, 0.5, T0))
    if kind == 2:
        return rng.choice(("", "a", "ctl-lab", "x" * 65, "\u00e9", "\x7f", "\ud800"))
    if kind == 3:
        return rng.choice((True, False, None))
    if kind == 4:
        return rng.randrange(-(2**64), 2**64)
    if kind == 5:
        return [_value(rng, depth + 1) for _ in range(rng.randrange(4))]
    return {rng.choice(("height", "position", "q", "yaw", "x")): _value(rng, depth + 1)
            for _ in range(rng.randrange(3))}  # fmt: skip


def generate_verify(rng: random.Random) -> bytes:
    """Structure-aware sequences: well-formed datagrams with fields replaced by values of
    other types and extreme sizes (huge integers, floats at the double's limits), signed
    with the key most of the time so they reach the checks after the signature."""
    out = []
    for k in range(rng.randrange(1, 5)):
        cmd, args = rng.choice(COMMANDS)
        fields: dict[str, Any] = {"v": 1, "src": "fuzz-ground", "seq": rng.randrange(1, 50),
                                  "t": T0 + 0.01 * k, "cmd": cmd, "args": dict(args)}  # fmt: skip
        for _ in range(rng.randrange(3)):
            name = rng.choice(("v", "src", "seq", "t", "cmd", "args", "extra"))
            fields[name] = _value(rng) if name != "args" else {"height": _value(rng)}
        if rng.random() < 0.8:
            with contextlib.suppress(ValueError):  # a value json cannot write: unsigned
                fields = sign(fields, KEY)
        try:
            out.append(json.dumps(fields).encode("utf-8", "surrogatepass"))
        except ValueError:
            continue
    return SEPARATOR.join(out)


TARGETS = [
    Target("ground_decode", check_decode, decode_seeds,
           about="rdm.ground.message.decode (control-port datagrams)"),
    Target("ground_verify", check_verify, verify_seeds, generate_verify,
           about="rdm.ground.auth.Verifier.verify (keyed and --insecure-control)"),
]  # fmt: skip
