"""The rosserial codec's single-struct path for fixed-layout messages (``_FlatLayout``) gives
the bytes, values and errors of the per-field path (docs/rosserial.md, "Native scan and
generated layouts"). The reference is a registry compiled with the flat path switched off."""

from __future__ import annotations

import random
from typing import Any

import pytest
from random_ros_messages import random_message

from rdm.protocol.rosserial import codec as rc
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.codec import RosDuration, RosTime
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_msgs_dir

FAST = spinal_registry()


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


def _message(codec, rng: random.Random, reg) -> Any:
    return random_message(codec, rng, reg, lambda r: r.randint(0, 3))


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
