"""ROS1 wire values and errors shared by the codec and its generated layouts: ``time`` and
``duration`` pairs, the struct codes of the primitive types, :class:`EncodeError` and
:class:`DecodeError`."""

from __future__ import annotations

import struct
from typing import NamedTuple


class RosTime(NamedTuple):
    """ROS1 ``time``: unsigned seconds and nanoseconds."""

    sec: int
    nsec: int

    def to_ns(self) -> int:
        return self.sec * 1_000_000_000 + self.nsec

    @classmethod
    def from_ns(cls, ns: int) -> RosTime:
        return cls(ns // 1_000_000_000, ns % 1_000_000_000)


class RosDuration(NamedTuple):
    """ROS1 ``duration``: signed seconds and nanoseconds."""

    sec: int
    nsec: int


class EncodeError(ValueError):
    """A value that cannot be serialized; the message names the type and field path."""


class DecodeError(ValueError):
    """Bytes that are not a valid serialization of the type (truncated, trailing, bad count);
    the message names the field and the byte offset."""


#: struct code of each ROS1 primitive that ``struct`` packs directly
STRUCT_CODE = {
    "bool": "?",
    "int8": "b",
    "byte": "b",
    "uint8": "B",
    "char": "B",
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
    "float32": "f",
    "float64": "d",
}
U32 = struct.Struct("<I")
TIME = struct.Struct("<II")
DURATION = struct.Struct("<ii")
TIMES = (RosTime, RosDuration)


def cut(where: str, n: int, pos: int, end: int) -> DecodeError:
    """The error of ``n`` bytes needed at ``pos`` with the buffer ending at ``end``."""
    return DecodeError(f"{where}: needs {n} bytes at offset {pos}, only {end - pos} left")


def over_count(where: str, count: int, pos: int) -> DecodeError:
    """The error of an array count larger than the bytes after it can hold."""
    return DecodeError(f"{where}: count {count} exceeds the remaining bytes at offset {pos}")


def raw_string(value: object) -> bytes:
    """The bytes of a ``string`` value (``str`` as UTF-8, non-UTF-8 kept by surrogateescape;
    ``bytes``/``bytearray`` as they are); TypeError for anything else."""
    if value.__class__ is str:
        return value.encode("utf-8", "surrogateescape")  # type: ignore[attr-defined]
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if isinstance(value, str):
        return value.encode("utf-8", "surrogateescape")
    raise TypeError(f"expected str or bytes, got {type(value).__name__}")
