"""The rosserial codec's single-struct path for fixed-layout messages (``_FlatLayout``) gives
the bytes, values and errors of the per-field path (docs/lockstep.md, "The onboard node's
40 Hz tick"). The reference is a registry compiled with the flat path switched off."""

from __future__ import annotations

import math
import random
import struct
from typing import Any

import pytest

from rdm.protocol.rosserial import codec as rc
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.codec import RosDuration, RosTime
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_msgs_dir

FAST = spinal_registry()
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


@pytest.fixture(scope="module")
def plain():
    """The same registry with every codec on the per-field path."""
    original = rc._FlatLayout.of
    rc._FlatLayout.of = classmethod(lambda cls, spec: None)  # type: ignore[method-assign]
    try:
        reg = TypeRegistry.from_directory(spinal_msgs_dir())  # not the cached one
        for name in reg.message_names:
            reg.msg(name)  # compile now, while the flat path is off
    finally:
        rc._FlatLayout.of = original  # type: ignore[method-assign]
    assert all(reg.msg(n)._flat is None for n in reg.message_names)
    return reg


def _value(base: str, rng: random.Random, reg) -> Any:
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
    return _message(reg.msg(base), rng, reg)


def _message(codec, rng: random.Random, reg) -> Any:
    values = {}
    for f in codec.spec.fields:
        if f.array_len is None:
            values[f.name] = _value(f.base_type, rng, reg)
        else:
            n = f.array_len if f.array_len >= 0 else rng.randint(0, 3)
            values[f.name] = [_value(f.base_type, rng, reg) for _ in range(n)]
    return codec.cls(**values)


def test_flat_layout_covers_the_hot_types():
    for name in ("spinal/Imu", "spinal/ServoState", "spinal/RollPitchYawTerm"):
        assert FAST.msg(name)._flat is not None, name
    assert FAST.msg("spinal/ServoStates")._flat is None  # variable array: per-field path


def test_same_bytes_and_values_as_the_per_field_path(plain):
    rng = random.Random(7)
    flat_types = 0
    for name in FAST.message_names:
        fast, ref = FAST.msg(name), plain.msg(name)
        flat_types += fast._flat is not None
        for _ in range(30):
            msg = _message(fast, rng, FAST)
            data = fast.encode(msg)
            assert data == ref.encode(msg), name
            got, want = fast.decode(data), ref.decode(data)
            assert rc.message_to_dict(got) == rc.message_to_dict(want), name
            assert type(got).__name__ == type(want).__name__
            assert fast.encode(got) == data
    assert flat_types >= 5


def _error(codec, call) -> tuple[type, str]:
    try:
        call(codec)
    except Exception as exc:  # the comparison is the point
        return type(exc), str(exc)
    return type(None), ""


@pytest.mark.parametrize(
    "field, value",
    [
        ("quaternion", [0.0, 0.0, 1.0]),  # wrong fixed length
        ("acc", [1e300, 0.0, 0.0]),  # float32 overflow
        ("stamp", (-1, 0)),  # plain tuple, negative seconds
        ("stamp", RosDuration(-1, 0)),
        ("gyro", "abc"),
    ],
)
def test_same_errors_as_the_per_field_path(plain, field, value):
    fast, ref = FAST.msg("spinal/Imu"), plain.msg("spinal/Imu")
    msg = fast.cls(**{field: value})
    assert _error(fast, lambda c: c.encode(msg)) == _error(ref, lambda c: c.encode(msg))


def test_same_decode_errors_and_dict_input(plain):
    fast, ref = FAST.msg("spinal/Imu"), plain.msg("spinal/Imu")
    data = fast.encode(fast.cls(stamp=RosTime(3, 4), quaternion=[0.0, 0.0, 0.0, 1.0]))
    for cut in (0, 1, 7, len(data) - 1):
        short = data[:cut]
        assert _error(fast, lambda c, b=short: c.decode(b)) == _error(
            ref, lambda c, b=short: c.decode(b)
        )
    assert _error(fast, lambda c: c.decode(data + b"\0"))[0] is rc.DecodeError
    as_dict = rc.message_to_dict(fast.decode(data))
    assert fast.encode(as_dict) == ref.encode(as_dict) == data
    term = FAST.msg("spinal/RollPitchYawTerm")
    assert _error(term, lambda c: c.encode(term.cls(roll_p=40000))) == _error(
        plain.msg("spinal/RollPitchYawTerm"),
        lambda c: c.encode(term.cls(roll_p=40000)),
    )
