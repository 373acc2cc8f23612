"""Shared machinery of the Neuron frame dataclasses: range checks and struct-described payloads."""

from __future__ import annotations

import abc
import dataclasses
import struct
from typing import Any, ClassVar

from .errors import NeuronFrameError
from .ids import Direction, make_id

# Inclusive ranges of the little-endian struct codes used on this link.
_RANGES = {
    "B": (0, 0xFF),
    "b": (-0x80, 0x7F),
    "H": (0, 0xFFFF),
    "h": (-0x8000, 0x7FFF),
    "I": (0, 0xFFFF_FFFF),
    "i": (-0x8000_0000, 0x7FFF_FFFF),
}


def check_int(name: str, value: Any, low: int, high: int) -> None:
    """Raise ``NeuronFrameError("range")`` unless ``low <= value <= high`` (bools rejected)."""
    if not isinstance(value, int) or isinstance(value, bool):
        raise NeuronFrameError("range", f"{name}={value!r} is not an integer")
    if not low <= value <= high:
        raise NeuronFrameError("range", f"{name}={value} not in {low}..{high}")


def check_bool(name: str, value: Any) -> None:
    if not isinstance(value, bool):
        raise NeuronFrameError("range", f"{name}={value!r} is not a bool")


def check_dlc(kind: str, data: bytes, allowed: tuple[int, ...]) -> None:
    if len(data) not in allowed:
        raise NeuronFrameError(
            "dlc", f"{kind}: DLC {len(data)} not in {', '.join(map(str, allowed))}"
        )


class NeuronFrame(abc.ABC):
    """Base of every Neuron frame dataclass: ``can_id``, ``encode()``, ``as_dict()``."""

    KIND: ClassVar[str]
    DIRECTION: ClassVar[Direction]
    DEVICE: ClassVar[int]

    @property
    def can_id(self) -> int:
        """The 11-bit standard CAN identifier of this frame."""
        return make_id(self.DEVICE, self._message_id(), self._slave_field())

    def _message_id(self) -> int:
        return self.MESSAGE  # type: ignore[attr-defined]

    def _slave_field(self) -> int:
        return self.slave  # type: ignore[attr-defined]

    @abc.abstractmethod
    def encode(self) -> bytes:
        """The frame payload (length = DLC)."""

    def as_dict(self) -> dict[str, Any]:
        """Plain fields (json-friendly), plus ``kind``."""
        out: dict[str, Any] = {"kind": self.KIND}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            out[f.name] = list(value) if isinstance(value, tuple) else value
        return out


class StructFrame(NeuronFrame):
    """A frame whose payload is ``PREFIX + struct.pack("<" + CODES, *fields after slave)``.

    Code ``?`` is a bool carried as one byte 0/1 (other byte values are rejected on decode).
    """

    CODES: ClassVar[str] = ""
    PREFIX: ClassVar[bytes] = b""
    #: Extra inclusive ranges narrower than the struct code, e.g. servo ``index`` 0..3.
    LIMITS: ClassVar[dict[str, tuple[int, int]]] = {}

    @classmethod
    def _payload_fields(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls) if f.name != "slave"]  # type: ignore[arg-type]

    @classmethod
    def dlc(cls) -> int:
        return len(cls.PREFIX) + struct.calcsize("<" + cls.CODES.replace("?", "B"))

    def __post_init__(self) -> None:
        self._check_slave()
        for name, code in zip(self._payload_fields(), self.CODES, strict=True):
            value = getattr(self, name)
            if code == "?":
                check_bool(name, value)
            else:
                low, high = self.LIMITS.get(name, _RANGES[code])
                check_int(name, value, low, high)

    def _check_slave(self) -> None:
        from .ids import check_slave

        check_slave(self.slave)  # type: ignore[attr-defined]

    def encode(self) -> bytes:
        values = [int(getattr(self, n)) for n in self._payload_fields()]
        return self.PREFIX + struct.pack("<" + self.CODES.replace("?", "B"), *values)

    @classmethod
    def decode_payload(cls, slave: int, data: bytes) -> StructFrame:
        """Inverse of :meth:`encode` with DLC, prefix and range checks."""
        check_dlc(cls.KIND, data, (cls.dlc(),))
        if not data.startswith(cls.PREFIX):
            raise NeuronFrameError(
                "range", f"{cls.KIND}: payload does not start with {cls.PREFIX!r}"
            )
        raw = struct.unpack("<" + cls.CODES.replace("?", "B"), data[len(cls.PREFIX) :])
        kwargs: dict[str, Any] = {"slave": slave} if "slave" in cls.__dataclass_fields__ else {}  # type: ignore[attr-defined]
        for name, code, value in zip(cls._payload_fields(), cls.CODES, raw, strict=True):
            if code == "?":
                if value > 1:
                    raise NeuronFrameError("range", f"{cls.KIND}: flag {name}={value} not 0/1")
                value = bool(value)
            kwargs[name] = value
        return cls(**kwargs)
