"""ROS1 serialization compiled from parsed ``.msg`` specs, plus the generated message classes.

Wire rules (fact sheet sec. 1.4): little-endian; ``float64`` is a real 8-byte double; ``time`` and
``duration`` are two 32-bit words; ``string`` and variable arrays carry a uint32 count; fixed
arrays do not; nested messages are inlined. Each message type gets a dataclass whose fields are
the ``.msg`` fields (arrays as lists) and whose class attributes are the ``.msg`` constants.
"""

from __future__ import annotations

import dataclasses
import struct
from collections.abc import Callable
from typing import Any, NamedTuple

from rdm.protocol.rosserial.msgdef import Field, MsgSpec


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
    """Bytes that are not a valid serialization of the type (truncated, trailing, bad count)."""


_STRUCT_CODE = {
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
_U32 = struct.Struct("<I")
_TIME = struct.Struct("<II")
_DURATION = struct.Struct("<ii")

Encoder = Callable[[Any, bytearray], None]
Decoder = Callable[[bytes, int], tuple[Any, int]]


def _need(buf: bytes, pos: int, n: int, what: str) -> None:
    if pos + n > len(buf):
        raise DecodeError(f"{what}: needs {n} bytes at offset {pos}, only {len(buf) - pos} left")


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
        self._fields: list[tuple[str, Encoder, Decoder]] = []
        self.min_size = 0
        for f in spec.fields:
            enc, dec, size = self._compile_field(f)
            self._fields.append((f.name, enc, dec))
            self.min_size += size
        self._flat = _FlatLayout.of(spec)

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

    # -- compilation ----------------------------------------------------------------------
    def _compile_field(self, f: Field) -> tuple[Encoder, Decoder, int]:
        where = f"{self.full_name}.{f.name}"
        if f.is_primitive and f.base_type in _STRUCT_CODE:
            return _compile_struct_field(f, _STRUCT_CODE[f.base_type], where)
        elem_enc, elem_dec, elem_size = self._compile_element(f.base_type, where)
        if f.array_len is None:
            return elem_enc, elem_dec, elem_size
        if f.array_len >= 0:
            n = f.array_len

            def enc_fixed(value: Any, out: bytearray) -> None:
                if len(value) != n:
                    raise EncodeError(f"{where}: needs exactly {n} elements, got {len(value)}")
                for v in value:
                    elem_enc(v, out)

            def dec_fixed(buf: bytes, pos: int) -> tuple[Any, int]:
                items = []
                for _ in range(n):
                    item, pos = elem_dec(buf, pos)
                    items.append(item)
                return items, pos

            return enc_fixed, dec_fixed, n * elem_size
        guard = max(elem_size, 1)

        def enc_var(value: Any, out: bytearray) -> None:
            out += _U32.pack(len(value))
            for v in value:
                elem_enc(v, out)

        def dec_var(buf: bytes, pos: int) -> tuple[Any, int]:
            _need(buf, pos, 4, where)
            (count,) = _U32.unpack_from(buf, pos)
            pos += 4
            if count * guard > len(buf) - pos:
                raise DecodeError(f"{where}: count {count} exceeds the remaining bytes")
            items = []
            for _ in range(count):
                item, pos = elem_dec(buf, pos)
                items.append(item)
            return items, pos

        return enc_var, dec_var, 4

    def _compile_element(self, base: str, where: str) -> tuple[Encoder, Decoder, int]:
        if base == "string":
            return _enc_string(where), _dec_string(where), 4
        if base in ("time", "duration"):
            return _compile_time(base, where)
        nested = self._resolve(base)

        def enc_nested(value: Any, out: bytearray) -> None:
            nested.encode_into(value, out)

        return enc_nested, nested.decode_from, nested.min_size

    # -- public API ------------------------------------------------------------------------
    def encode_into(self, msg: Any, out: bytearray) -> None:
        """Append the serialization of ``msg`` (an instance or any object with the fields)."""
        flat = self._flat
        if flat is not None and not isinstance(msg, dict):
            packed = flat.pack(msg)
            if packed is not None:
                out += packed
                return
        for name, enc, _ in self._fields:
            try:
                value = msg[name] if isinstance(msg, dict) else getattr(msg, name)
            except (KeyError, AttributeError) as exc:
                raise EncodeError(f"{self.full_name}: missing field {name!r}") from exc
            enc(value, out)

    def encode(self, msg: Any) -> bytes:
        """Serialize ``msg`` to ROS1 bytes."""
        out = bytearray()
        self.encode_into(msg, out)
        return bytes(out)

    def decode_from(self, buf: bytes, pos: int) -> tuple[Any, int]:
        """Decode one message starting at ``pos``; returns it and the position after it."""
        flat = self._flat
        if flat is not None and len(buf) - pos >= flat.size:
            return self.cls(*flat.unpack(buf, pos)), pos + flat.size
        values = {}
        for name, _, dec in self._fields:
            values[name], pos = dec(buf, pos)
        return self.cls(**values), pos

    def decode(self, data: bytes) -> Any:
        """Decode exactly one message; trailing bytes are an error."""
        buf = bytes(data)
        msg, pos = self.decode_from(buf, 0)
        if pos != len(buf):
            raise DecodeError(f"{self.full_name}: {len(buf) - pos} trailing bytes")
        return msg

    def new(self, **fields: Any) -> Any:
        """A message instance with defaults for the fields not given."""
        return self.cls(**fields)


class _FlatLayout:
    """One ``struct`` for a message made only of fixed-size fields (primitive scalars, fixed
    primitive arrays, ``time``/``duration``): a single pack/unpack instead of one per field.
    Same bytes and values as the per-field path, which still handles every error case
    (:meth:`pack` returns None for anything it does not take, the caller falls back)."""

    def __init__(self, parts: list[tuple[str, str, int | None]], fmt: str) -> None:
        self.parts = parts  # (field name, kind: "v" value / "a" array / "t" time / "d", n)
        self.struct = struct.Struct(fmt)
        self.size = self.struct.size
        self.scalars_only = all(kind == "v" for _, kind, _ in parts)
        steps, i = [], 0  # (kind, first index in the flat tuple, array length)
        for _, kind, n in parts:
            steps.append((kind, i, n))
            i += n if kind == "a" else (1 if kind == "v" else 2)
        self.steps = tuple(steps)

    @classmethod
    def of(cls, spec: MsgSpec) -> _FlatLayout | None:
        parts: list[tuple[str, str, int | None]] = []
        fmt = "<"
        for f in spec.fields:
            if f.base_type in ("time", "duration") and f.array_len is None:
                parts.append((f.name, "t" if f.base_type == "time" else "d", None))
                fmt += "II" if f.base_type == "time" else "ii"
            elif f.is_primitive and f.base_type in _STRUCT_CODE:
                code = _STRUCT_CODE[f.base_type]
                if f.array_len is None:
                    parts.append((f.name, "v", None))
                    fmt += code
                elif f.array_len >= 0:
                    parts.append((f.name, "a", f.array_len))
                    fmt += f"{f.array_len}{code}"
                else:
                    return None
            else:
                return None
        return cls(parts, fmt) if parts else None

    def unpack(self, buf: bytes, pos: int) -> tuple[Any, ...] | list[Any]:
        """The field values in field order (the message class takes them positionally)."""
        flat = self.struct.unpack_from(buf, pos)
        if self.scalars_only:
            return flat
        values: list[Any] = []
        for kind, i, n in self.steps:
            if kind == "v":
                values.append(flat[i])
            elif kind == "a":
                values.append(list(flat[i : i + n]))
            else:
                values.append((RosTime if kind == "t" else RosDuration)(flat[i], flat[i + 1]))
        return values

    def pack(self, msg: Any) -> bytes | None:
        try:
            args: list[Any] = []
            for name, kind, n in self.parts:
                value = getattr(msg, name)
                if kind == "v":
                    args.append(value)
                elif kind == "a":
                    if len(value) != n:
                        return None
                    args.extend(value)
                elif isinstance(value, (RosTime, RosDuration)):
                    args.extend(value)
                else:
                    return None
            return self.struct.pack(*args)
        except Exception:  # the per-field path raises the precise error
            return None


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


def _compile_struct_field(f: Field, code: str, where: str) -> tuple[Encoder, Decoder, int]:
    one = struct.Struct("<" + code)
    size = one.size
    if f.array_len is None:

        def enc(value: Any, out: bytearray) -> None:
            try:
                out += one.pack(value)
            except struct.error as exc:
                raise EncodeError(f"{where}: {value!r} does not fit {f.base_type}: {exc}") from exc

        def dec(buf: bytes, pos: int) -> tuple[Any, int]:
            _need(buf, pos, size, where)
            return one.unpack_from(buf, pos)[0], pos + size

        return enc, dec, size
    if f.array_len >= 0:
        n = f.array_len
        many = struct.Struct(f"<{n}{code}")

        def enc_fixed(value: Any, out: bytearray) -> None:
            if len(value) != n:
                raise EncodeError(f"{where}: needs exactly {n} elements, got {len(value)}")
            try:
                out += many.pack(*value)
            except struct.error as exc:
                raise EncodeError(f"{where}: element does not fit {f.base_type}: {exc}") from exc

        def dec_fixed(buf: bytes, pos: int) -> tuple[Any, int]:
            _need(buf, pos, many.size, where)
            return list(many.unpack_from(buf, pos)), pos + many.size

        return enc_fixed, dec_fixed, many.size

    def enc_var(value: Any, out: bytearray) -> None:
        try:
            out += _U32.pack(len(value)) + struct.pack(f"<{len(value)}{code}", *value)
        except struct.error as exc:
            raise EncodeError(f"{where}: element does not fit {f.base_type}: {exc}") from exc

    def dec_var(buf: bytes, pos: int) -> tuple[Any, int]:
        _need(buf, pos, 4, where)
        (count,) = _U32.unpack_from(buf, pos)
        pos += 4
        _need(buf, pos, count * size, where)
        return list(struct.unpack_from(f"<{count}{code}", buf, pos)), pos + count * size

    return enc_var, dec_var, 4


def _enc_string(where: str) -> Encoder:
    def enc(value: Any, out: bytearray) -> None:
        if isinstance(value, str):
            raw = value.encode("utf-8", "surrogateescape")
        elif isinstance(value, (bytes, bytearray)):
            raw = bytes(value)
        else:
            raise EncodeError(f"{where}: expected str or bytes, got {type(value).__name__}")
        out += _U32.pack(len(raw)) + raw

    return enc


def _dec_string(where: str) -> Decoder:
    def dec(buf: bytes, pos: int) -> tuple[Any, int]:
        _need(buf, pos, 4, where)
        (n,) = _U32.unpack_from(buf, pos)
        pos += 4
        _need(buf, pos, n, where)
        # surrogateescape keeps non-UTF-8 bytes so that decode -> encode is exact
        return buf[pos : pos + n].decode("utf-8", "surrogateescape"), pos + n

    return dec


def _compile_time(base: str, where: str) -> tuple[Encoder, Decoder, int]:
    st, kind = (_TIME, RosTime) if base == "time" else (_DURATION, RosDuration)

    def enc(value: Any, out: bytearray) -> None:
        try:
            if isinstance(value, dict):
                sec, nsec = value["sec"], value["nsec"]
            elif hasattr(value, "sec"):
                sec, nsec = value.sec, value.nsec
            else:
                sec, nsec = value
            out += st.pack(sec, nsec)
        except (struct.error, TypeError, ValueError, KeyError) as exc:
            raise EncodeError(f"{where}: bad {base} value {value!r}: {exc}") from exc

    def dec(buf: bytes, pos: int) -> tuple[Any, int]:
        _need(buf, pos, 8, where)
        return kind(*st.unpack_from(buf, pos)), pos + 8

    return enc, dec, 8


def message_to_dict(msg: Any) -> Any:
    """Plain JSON-able form of a decoded message (times as ``{"sec", "nsec"}``)."""
    if isinstance(msg, (RosTime, RosDuration)):
        return {"sec": msg.sec, "nsec": msg.nsec}
    if dataclasses.is_dataclass(msg) and not isinstance(msg, type):
        return {f.name: message_to_dict(getattr(msg, f.name)) for f in dataclasses.fields(msg)}
    if isinstance(msg, list):
        return [message_to_dict(v) for v in msg]
    return msg
