"""Decode Neuron traffic from candump logs: ``.log`` (``candump -L`` / python-can canutils) and
``.asc`` (Vector ASCII, read with python-can's ``ASCReader``)."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .codec import DecodeResult, NeuronDecoder
from .ids import Direction

# "(1700000000.123456) can0 123#DEADBEEF" with an optional python-can " R"/" T" suffix.
_LOG_LINE = re.compile(
    r"^\((?P<ts>[0-9]+(?:\.[0-9]*)?)\)\s+(?P<ch>\S+)\s+(?P<id>[0-9A-Fa-f]{1,8})"
    r"#(?P<data>\S*)(?:\s+(?P<dir>[RTrt]))?$"
)


def _result_dict(line: int, res: DecodeResult, extra: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {
        "line": line,
        **extra,
        "id": res.can_id,
        "dlc": len(res.data),
        "data": res.data.hex(),
        "ok": res.ok,
        "error": None if res.error is None else str(res.error),
    }
    if res.frame is not None:
        fields = res.frame.as_dict()
        out["kind"] = fields.pop("kind")
        out["direction"] = res.frame.DIRECTION.value
        out["ambiguous"] = bool(res.alternatives)
        out["alternatives"] = [f.KIND for f in res.alternatives]
        for key, value in fields.items():
            out.setdefault(key, value)
    else:
        out["kind"] = None
    return out


def _error_dict(line: int, message: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"line": line, **(extra or {}), "kind": None, "ok": False, "error": message}


def _decode_log(path: Path, decoder: NeuronDecoder) -> Iterator[dict[str, Any]]:
    with open(path, encoding="utf-8", errors="replace") as fh:
        for number, raw in enumerate(fh, start=1):
            text = raw.strip()
            if not text:
                continue
            m = _LOG_LINE.match(text)
            if m is None:
                decoder.errors["syntax"] += 1
                yield _error_dict(number, f"syntax: not a candump -L line: {text[:80]!r}")
                continue
            id_text, payload = m["id"], m["data"]
            stamp = float(m["ts"])
            if not math.isfinite(stamp):  # digits past the double's range
                decoder.errors["syntax"] += 1
                yield _error_dict(number, f"syntax: timestamp {m['ts'][:24]}... out of range")
                continue
            extra = {"timestamp": stamp, "channel": m["ch"]}
            remote = payload[:1] in ("R", "r")
            if payload.startswith("#"):  # CAN FD "##<flags><data>"
                decoder.errors["fd"] += 1
                yield _error_dict(number, "fd: CAN FD frame on the Neuron link", extra)
                continue
            if remote or len(payload) % 2 or not re.fullmatch(r"[0-9A-Fa-f]*", payload):
                if not remote:
                    decoder.errors["syntax"] += 1
                    yield _error_dict(number, f"syntax: bad data field {payload!r}", extra)
                    continue
                payload = ""
            res = decoder.feed(
                int(id_text, 16), bytes.fromhex(payload), extended=len(id_text) > 3, remote=remote
            )
            yield _result_dict(number, res, extra)


def _decode_asc(path: Path, decoder: NeuronDecoder) -> Iterator[dict[str, Any]]:
    import can

    # ASCReader gives no line numbers; "line" is then the 1-based message ordinal.
    reader = can.ASCReader(str(path))
    number = 0
    try:
        for msg in reader:
            number += 1
            if not math.isfinite(msg.timestamp):  # digits past the double's range
                decoder.errors["syntax"] += 1
                yield _error_dict(number, "syntax: timestamp out of range")
                continue
            extra = {"timestamp": msg.timestamp, "channel": msg.channel}
            if msg.is_error_frame:
                decoder.errors["error_frame"] += 1
                yield _error_dict(number, "error_frame: CAN error frame", extra)
                continue
            if msg.is_fd:
                decoder.errors["fd"] += 1
                yield _error_dict(number, "fd: CAN FD frame on the Neuron link", extra)
                continue
            res = decoder.feed(
                msg.arbitration_id,
                bytes(msg.data),
                extended=msg.is_extended_id,
                remote=msg.is_remote_frame,
            )
            yield _result_dict(number, res, extra)
    except (ValueError, IndexError, KeyError) as exc:  # python-can parser gave up on a line
        decoder.errors["syntax"] += 1
        yield _error_dict(number + 1, f"syntax: ASC reader failed: {exc}")
    finally:
        reader.stop()


#: Log syntax by file suffix: ``candump -L`` lines or Vector ASCII.
SYNTAX_OF_SUFFIX = {".log": "log", ".candump": "log", ".asc": "asc"}


def decode_candump(
    path: str | os.PathLike[str],
    *,
    direction: Direction | None = None,
    decoder: NeuronDecoder | None = None,
    syntax: str | None = None,
) -> Iterator[dict[str, Any]]:
    """Yield one dict per frame line of a ``.log``/``.candump`` or ``.asc`` capture.

    ``syntax``: ``"log"`` (``candump -L`` lines) or ``"asc"`` (Vector ASCII); default from
    the suffix (:data:`SYNTAX_OF_SUFFIX`), a ValueError for any other suffix.

    Keys: ``line``, ``kind`` (None on error), ``ok``, ``error`` (message or None), ``timestamp``,
    ``channel``, ``id``, ``dlc``, ``data`` (hex), ``direction``, ``ambiguous``,
    ``alternatives`` and the decoded frame's fields. Pass a :class:`NeuronDecoder` to read its
    counters afterwards.
    """
    p = Path(path)
    dec = decoder if decoder is not None else NeuronDecoder(direction=direction)
    if direction is not None:
        dec.direction = direction
    if syntax is None:
        syntax = SYNTAX_OF_SUFFIX.get(p.suffix.lower())
        if syntax is None:
            raise ValueError(
                f"decode_candump: unsupported log suffix {p.suffix!r} "
                f"(use {', '.join(SYNTAX_OF_SUFFIX)} or give the syntax)"
            )
    if syntax == "log":
        yield from _decode_log(p, dec)
    elif syntax == "asc":
        yield from _decode_asc(p, dec)
    else:
        raise ValueError(f"decode_candump: syntax {syntax!r} must be 'log' or 'asc'")
