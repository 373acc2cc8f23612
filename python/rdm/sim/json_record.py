"""One JSON log record as text, the same characters ``json.dumps`` writes, but faster.

The run logger writes the plant's ground truth and the onboard status as JSON at 100 Hz;
``json.dumps`` (plus the ``_jsonable`` walk that turns NaN into null) cost ~170 us per
ground-truth record, most of it ``float.__repr__``. :func:`encode_record` writes the flat
records these are (str keys; float, int, bool, str, None, 1-D float arrays, lists of floats) with
the float arrays formatted in Rust (``rdm._rdm.json_float_list``: Python's repr digits and
layout). Anything else, it returns None and the caller takes the general path. The output is
byte-equal with ``json.dumps(_jsonable(values), separators=(",", ":"))`` (tests compare the
two on random bit patterns, signed zeros, NaN, infinities and subnormals).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from json.encoder import encode_basestring_ascii
from typing import Any

import numpy as np

from rdm._rdm import json_float_list, json_record

#: Keys json.dumps writes as they are (no escapes under ensure_ascii).
_PLAIN_KEY = re.compile(r"[A-Za-z0-9_ ./:+-]*")
_known_keys: dict[str, str] = {}
_FLOAT64 = np.dtype(np.float64)


def _key(k: Any) -> str | None:
    if type(k) is not str:
        return None
    text = _known_keys.get(k)
    if text is None:
        if _PLAIN_KEY.fullmatch(k) is None or len(_known_keys) > 4096:
            return None
        text = _known_keys[k] = f'"{k}":'
    return text


def _float(v: float) -> str:
    return float.__repr__(v) if math.isfinite(v) else "null"


def encode_record(values: Mapping[str, Any]) -> str | None:
    """``values`` as compact JSON text, or None when a value is outside the fast path.

    A dict goes to Rust in one call (``rdm._rdm.json_record``: plain keys; None, bool, float,
    int, str, 1-D float64 arrays, lists of floats); what it declines takes
    :func:`encode_record_plain` (the same text, tests/test_sampler_fast_paths.py)."""
    if type(values) is dict:
        text = json_record(values)
        if text is not None:
            return text
    return encode_record_plain(values)


def encode_record_plain(values: Mapping[str, Any]) -> str | None:
    """The Python form of :func:`encode_record` (the reference of the Rust path)."""
    parts = []
    for k, v in values.items():
        key = _key(k)
        if key is None:
            return None
        t = type(v)
        if t is float or t is np.float64:
            text = _float(v)
        elif t is bool or t is np.bool_:
            text = "true" if v else "false"
        elif t is int:
            text = int.__repr__(v)
        elif t is np.int64 or t is np.int32:
            text = int.__repr__(int(v))
        elif t is str:
            text = encode_basestring_ascii(v)
        elif v is None:
            text = "null"
        elif t is np.ndarray:
            if v.ndim != 1 or v.dtype != _FLOAT64:
                return None
            text = f"[{json_float_list(v)}]"
        elif t is list:
            if not all(type(x) is float for x in v):
                return None
            text = f"[{json_float_list(np.array(v, dtype=np.float64))}]"
        else:
            return None
        parts.append(key + text)
    return "{" + ",".join(parts) + "}"
