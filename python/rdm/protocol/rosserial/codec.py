"""ROS1 serialization compiled from parsed ``.msg`` specs, plus the generated message classes.

Wire rules (fact sheet sec. 1.4): little-endian; ``float64`` is a real 8-byte double; ``time`` and
``duration`` are two 32-bit words; ``string`` and variable arrays carry a uint32 count; fixed
arrays do not; nested messages are inlined. Each message type gets a dataclass whose fields are
the ``.msg`` fields (arrays as lists) and whose class attributes are the ``.msg`` constants.

One serializer (docs/rosserial.md "One implementation per job"): the generated layout of each
type (:mod:`rdm.protocol.rosserial.layout`) packs and reads every message. A value its
``pack`` refuses goes through :meth:`MessageCodec.normalise` (dict input, times given as
pairs, dicts or objects with ``sec``/``nsec``) and is packed again by the same layout; a value
still refused is named by :meth:`MessageCodec.check` (the rule the field breaks), which packs
nothing. Checked against rosbags' ROS1 serializer.
"""

from __future__ import annotations

import dataclasses
import struct
from collections.abc import Callable
from typing import Any

from rdm.protocol.rosserial.layout import FlatLayout, VarLayout, layout_of
from rdm.protocol.rosserial.msgdef import Field, MsgSpec
from rdm.protocol.rosserial.wire import (
    DURATION,
    STRUCT_CODE,
    TIME,
    DecodeError,
    EncodeError,
    RosDuration,
    RosTime,
)

__all__ = [
    "DecodeError",
    "EncodeError",
    "MessageCodec",
    "RosDuration",
    "RosTime",
    "message_to_dict",
]


class MessageCodec:
    """Serializer/deserializer and message class for one ``.msg`` spec.

    Built by :class:`~rdm.protocol.rosserial.registry.TypeRegistry`; ``resolve`` returns the
    codec of a nested type so nested messages share one compiled codec per type.
    """

    def __init__(self, spec: MsgSpec, resolve: Callable[[str], MessageCodec]) -> None:
        self.spec = spec
        self.full_name = spec.full_name
        self._resolve = resolve
        self.cls = self._make_class()
        #: the generated layout: the one pack/read path of this type
        self.layout: FlatLayout | VarLayout = layout_of(spec, resolve).bind(self.cls)
        #: payload size of a message made only of fixed-size fields (``decode`` accepts exactly
        #: the payloads of this length), None otherwise
        self.fixed_size: int | None = (
            self.layout.size if isinstance(self.layout, FlatLayout) else None
        )
        self.min_size = self.layout.min_size
        self._pack = self.layout.pack
        self._read = self.layout.read
        self._unpack = self.layout.unpack if isinstance(self.layout, FlatLayout) else None

    # -- message class ------------------------------------------------------------------
    def _default_factory(self, f: Field) -> Callable[[], Any]:
        if f.array_len == -1:
            return list
        if f.is_primitive:
            scalar = _scalar_default(f.base_type)
            if f.array_len is None:
                return lambda: scalar
            n = f.array_len
            return lambda: [scalar] * n
        nested = self._resolve(f.base_type)
        if f.array_len is None:
            return nested.cls
        n = f.array_len
        return lambda: [nested.cls() for _ in range(n)]

    def _make_class(self) -> type:
        specs = [
            (f.name, Any, dataclasses.field(default_factory=self._default_factory(f)))
            for f in self.spec.fields
        ]
        cls = dataclasses.make_dataclass(self.spec.short_name, specs)
        cls.__module__ = "rdm.protocol.rosserial.types"
        cls.__qualname__ = self.spec.full_name.replace("/", ".")
        cls._type = self.spec.full_name
        for c in self.spec.constants:
            setattr(cls, c.name, c.value)
        return cls

    # -- public API ------------------------------------------------------------------------
    def encode(self, msg: Any) -> bytes:
        """Serialize ``msg`` (an instance, any object with the fields, or a dict; times also
        as ``(sec, nsec)`` pairs or ``{"sec", "nsec"}`` dicts) to ROS1 bytes; EncodeError
        naming the field and the rule it breaks."""
        try:
            return self._pack(msg)
        except Exception:  # normalise, pack again, or name the refused field
            return self._encode_refused(msg)

    def encode_into(self, msg: Any, out: bytearray) -> None:
        """Append the serialization of ``msg`` (as :meth:`encode`) to ``out``."""
        out += self.encode(msg)

    def _encode_refused(self, msg: Any) -> bytes:
        norm = self.normalise(msg)
        try:
            return self._pack(norm)
        except Exception as exc:
            self.check(norm)
            raise EncodeError(f"{self.full_name}: {exc}") from exc

    def normalise(self, msg: Any) -> Any:
        """``msg`` as an instance of :attr:`cls` that the layout's ``pack`` takes when its
        values fit: fields read from a dict or any object, times made :class:`RosTime` /
        :class:`RosDuration`, nested messages normalised. EncodeError for a missing field, a
        time that is not a pair, or an array of messages or times that is not a sequence."""
        values = {}
        for f in self.spec.fields:
            try:
                value = msg[f.name] if isinstance(msg, dict) else getattr(msg, f.name)
            except (KeyError, AttributeError, TypeError) as exc:
                raise EncodeError(f"{self.full_name}: missing field {f.name!r}") from exc
            values[f.name] = self._normal_value(f, value)
        return self.cls(**values)

    def _normal_value(self, f: Field, value: Any) -> Any:
        base = f.base_type
        where = f"{self.full_name}.{f.name}"
        if base in ("time", "duration"):
            one: Callable[[Any], Any] = lambda v: _time_value(base, where, v)  # noqa: E731
        elif not f.is_primitive:
            one = self._resolve(base).normalise
        else:
            return value
        if f.array_len is None:
            return one(value)
        return [one(v) for v in _sequence(where, value)]

    def check(self, msg: Any) -> None:
        """Raise the EncodeError of the first field of normalised ``msg`` that breaks a rule
        of its type (array length, range of its struct code, string type, time range);
        return None if every field fits."""
        for f in self.spec.fields:
            where = f"{self.full_name}.{f.name}"
            value = getattr(msg, f.name)
            if f.array_len is None:
                self._check_one(f.base_type, where, value, True)
                continue
            items = _sequence(where, value, strict=f.base_type not in STRUCT_CODE)
            if 0 <= f.array_len != len(items):
                n = f.array_len
                raise EncodeError(f"{where}: needs exactly {n} elements, got {len(items)}")
            for v in items:
                self._check_one(f.base_type, where, v, False)

    def _check_one(self, base: str, where: str, value: Any, scalar: bool) -> None:
        if base in STRUCT_CODE:
            try:
                struct.pack("<" + STRUCT_CODE[base], value)
            except Exception as exc:
                what = f"{value!r}" if scalar else "element"
                raise EncodeError(f"{where}: {what} does not fit {base}: {exc}") from exc
        elif base == "string":
            if not isinstance(value, (str, bytes, bytearray)):
                raise EncodeError(f"{where}: expected str or bytes, got {type(value).__name__}")
        elif base in ("time", "duration"):
            try:
                (TIME if base == "time" else DURATION).pack(*value)
            except (struct.error, TypeError) as exc:
                raise EncodeError(f"{where}: bad {base} value {value!r}: {exc}") from exc
        else:
            self._resolve(base).check(value)

    def decode_from(self, buf: bytes, pos: int) -> tuple[Any, int]:
        """Decode one message starting at ``pos``; returns it and the position after it."""
        return self._read(buf, pos)

    def decode(self, data: bytes) -> Any:
        """Decode exactly one message; trailing bytes are an error."""
        size = self.fixed_size
        if size is not None and len(data) == size:
            return self.cls(*self._unpack(data, 0))  # type: ignore[misc]  # the common case
        buf = bytes(data)
        msg, pos = self._read(buf, 0)
        if pos != len(buf):
            raise DecodeError(f"{self.full_name}: {len(buf) - pos} trailing bytes at offset {pos}")
        return msg

    def new(self, **fields: Any) -> Any:
        """A message instance with defaults for the fields not given."""
        return self.cls(**fields)

    def field_tree(self) -> tuple[Any, ...]:
        """``(name, base type, array length, nested tree)`` of every field, nested types
        expanded: two codecs with equal trees decode a payload to the same values."""
        return tuple(
            (
                f.name,
                f.base_type,
                f.array_len,
                None if f.is_primitive else self._resolve(f.base_type).field_tree(),
            )
            for f in self.spec.fields
        )


def _sequence(where: str, value: Any, strict: bool = True) -> list[Any]:
    """``value`` as a list of array elements; EncodeError if it is not a sequence (with
    ``strict``, a str, bytes or dict is not one either)."""
    text = isinstance(value, (str, bytes, bytearray, dict))
    if (strict and text) or not hasattr(value, "__len__"):
        raise EncodeError(f"{where}: expected a sequence, got {type(value).__name__}")
    return list(value)


def _time_value(base: str, where: str, value: Any) -> Any:
    """A ``time``/``duration`` given as a RosTime/RosDuration, a ``{"sec", "nsec"}`` dict,
    an object with ``sec``/``nsec`` or a pair, as the field's NamedTuple."""
    kind = RosTime if base == "time" else RosDuration
    try:
        if isinstance(value, dict):
            sec, nsec = value["sec"], value["nsec"]
        elif hasattr(value, "sec"):
            sec, nsec = value.sec, value.nsec
        else:
            sec, nsec = value
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise EncodeError(f"{where}: bad {base} value {value!r}: {exc}") from exc
    return kind(sec, nsec)


def _scalar_default(base: str) -> Any:
    if base == "bool":
        return False
    if base in ("float32", "float64"):
        return 0.0
    if base == "string":
        return ""
    if base == "time":
        return RosTime(0, 0)
    if base == "duration":
        return RosDuration(0, 0)
    return 0


def message_to_dict(msg: Any) -> Any:
    """Plain JSON-able form of a decoded message (times as ``{"sec", "nsec"}``)."""
    if isinstance(msg, (RosTime, RosDuration)):
        return {"sec": msg.sec, "nsec": msg.nsec}
    if dataclasses.is_dataclass(msg) and not isinstance(msg, type):
        return {f.name: message_to_dict(getattr(msg, f.name)) for f in dataclasses.fields(msg)}
    if isinstance(msg, list):
        return [message_to_dict(v) for v in msg]
    return msg
