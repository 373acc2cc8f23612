"""Random rosserial messages of any registered type, for the codec tests: every field filled
with an edge or random value of its ROS type."""

from __future__ import annotations

import math
import random
import struct
from collections.abc import Callable
from typing import Any

from rdm.protocol.rosserial.codec import RosDuration, RosTime

#: The value range of each ROS integer type.
INT_RANGE = {
    "int8": (-128, 127),
    "byte": (-128, 127),
    "uint8": (0, 255),
    "char": (0, 255),
    "int16": (-32768, 32767),
    "uint16": (0, 65535),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}


def random_value(base: str, rng: random.Random, reg: Any, array_len: Callable) -> Any:
    """A value of ROS type ``base`` (a nested message through ``reg``'s codecs)."""
    if base == "bool":
        return rng.random() < 0.5
    if base in INT_RANGE:
        lo, hi = INT_RANGE[base]
        return rng.choice([lo, hi, 0, rng.randint(lo, hi)])
    if base == "float32":
        return struct.unpack("<f", struct.pack("<f", rng.uniform(-1e6, 1e6)))[0]
    if base == "float64":
        return rng.choice([0.0, -0.0, 1e-300, rng.uniform(-1e9, 1e9), math.inf])
    if base == "string":
        return "".join(rng.choice("abc xyz") for _ in range(rng.randint(0, 5)))
    if base == "time":
        return RosTime(rng.randint(0, 2**32 - 1), rng.randint(0, 999_999_999))
    if base == "duration":
        return RosDuration(rng.randint(-(2**31), 2**31 - 1), rng.randint(0, 999_999_999))
    return random_message(reg.msg(base), rng, reg, array_len)


def random_message(codec: Any, rng: random.Random, reg: Any, array_len: Callable) -> Any:
    """A message of ``codec``'s type; ``array_len(rng)`` sizes each variable-length array."""
    values = {}
    for f in codec.spec.fields:
        if f.array_len is None:
            values[f.name] = random_value(f.base_type, rng, reg, array_len)
        else:
            n = f.array_len if f.array_len >= 0 else array_len(rng)
            values[f.name] = [random_value(f.base_type, rng, reg, array_len) for _ in range(n)]
    return codec.cls(**values)
