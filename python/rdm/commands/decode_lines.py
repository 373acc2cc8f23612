"""Column-wise output lines of ``rdm decode`` for a batch of Leptrino force samples.

:func:`force_run_lines` writes a :class:`rdm.protocol.leptrino_capture.ForceRun` as the text
(or JSON) lines :func:`rdm.commands.decode.format_record` (or the JSON form) gives each of its
records, without a Python call per record: every line is a row of a byte matrix holding the
fixed text, the payload's hex digits and each integer's decimal digits right-aligned in a
field of its widest width; the padding (NUL bytes, never part of the text) is then dropped.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import numpy.typing as npt

_HEX = np.frombuffer(bytes(range(256)).hex().encode(), np.uint8).reshape(256, 2)
_PAD = 0

#: (fixed text before each field, field) of one line; fields: "offset", "hex", "raw0".."raw5",
#: "temperature", "status", "result", "term_no".
_TEXT: tuple[tuple[str, str], ...] = (
    ("@", "offset"),
    (' force_data {"payload":"', "hex"),
    ('","raw":[', "raw0"),
    (",", "raw1"),
    (",", "raw2"),
    (",", "raw3"),
    (",", "raw4"),
    (",", "raw5"),
    ('],"temperature":', "temperature"),
    (',"status":', "status"),
    (',"result":', "result"),
    (',"term_no":', "term_no"),
)
_TEXT_END = "}\n"
_JSON: tuple[tuple[str, str], ...] = (
    ('{"offset": ', "offset"),
    (', "kind": "force_data", "ok": true, "error": null, "payload": "', "hex"),
    ('", "raw": [', "raw0"),
    (", ", "raw1"),
    (", ", "raw2"),
    (", ", "raw3"),
    (", ", "raw4"),
    (", ", "raw5"),
    ('], "temperature": ', "temperature"),
    (', "status": ', "status"),
    (', "result": ', "result"),
    (', "term_no": ', "term_no"),
)
_JSON_END = "}\n"


def decimal_digits(values: npt.ArrayLike) -> npt.NDArray[np.uint8]:
    """``str(v)`` of each integer of ``values`` (any shape) as ASCII bytes along a new last
    axis, right-aligned and NUL-padded on the left to the widest value's width."""
    v = np.asarray(values, dtype=np.int64)
    mag = np.abs(v).astype(np.uint64)
    width = len(str(int(mag.max()))) + 1 if mag.size else 1  # digits and a sign
    out = np.full((*v.shape, width), _PAD, np.uint8)
    left = mag.copy()
    first = np.full(v.shape, width - 1)  # column of each value's leading digit
    for k in range(width - 1):
        col = width - 1 - k
        shown = (left > 0) | (k == 0)
        out[..., col] = np.where(shown, (left % 10).astype(np.uint8) + ord("0"), _PAD)
        first = np.where(shown, col, first)
        left //= 10
    neg = np.nonzero(v < 0)
    out[(*neg, first[neg] - 1)] = ord("-")  # the sign just before the leading digit
    return out


@functools.cache
def _int16_table() -> npt.NDArray[np.uint8]:
    """Row ``v + 32768`` is ``str(v)`` for every int16 ``v`` (6 bytes, NUL-padded)."""
    return decimal_digits(np.arange(-32768, 32768))


def _fixed(text: str, n: int) -> npt.NDArray[np.uint8]:
    row = np.frombuffer(text.encode("ascii"), np.uint8)
    return np.broadcast_to(row, (n, len(row)))


def force_run_lines(run: Any, as_json: bool) -> str:
    """The lines of a ForceRun batch, each ending in a newline (``""`` for an empty one)."""
    n = len(run)
    if not n:
        return ""
    table = _int16_table()
    fields = {"offset": decimal_digits(run.offsets)}
    raw = run.raw.astype(np.int64) + 32768
    for k in range(6):
        fields[f"raw{k}"] = table[raw[:, k]]
    fields["temperature"] = table[run.temperature.astype(np.int64) + 32768]
    for name in ("status", "result", "term_no"):  # uint8: the last three columns suffice
        fields[name] = table[getattr(run, name).astype(np.int64) + 32768, -3:]
    fields["hex"] = _HEX[run.payloads].reshape(n, -1)
    layout, end = (_JSON, _JSON_END) if as_json else (_TEXT, _TEXT_END)
    parts: list[npt.NDArray[np.uint8]] = []
    for text, name in layout:
        parts.append(_fixed(text, n))
        parts.append(fields[name])
    parts.append(_fixed(end, n))
    return np.hstack(parts).tobytes().replace(b"\0", b"").decode("ascii")
