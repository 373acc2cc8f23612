"""ROS1 serialization compiled from parsed ``.msg`` specs, plus the generated message classes.

Wire rules (fact sheet sec. 1.4): little-endian; ``float64`` is a real 8-byte double; ``time`` and
``duration`` are two 32-bit words; ``string`` and variable arrays carry a uint32 count; fixed
arrays do not; nested messages are inlined. Each message type gets a dataclass whose fields are
the ``.msg`` fields (arrays as lists) and whose class attributes are the ``.msg`` constants.

Two forms serialize a message (docs/rosserial.md "One implementation per job"): the per-field
path (one compiled closure per field) is the only one for strings, nested messages with their
own variable arrays, dict and pair input, and the precise :class:`EncodeError` /
:class:`DecodeError` texts; the generated whole-message layouts (:class:`_FlatLayout`,
:class:`_VarLayout`) are the hot path of the types made of fixed-size fields and variable
arrays of primitives or flat messages, and hand anything they do not take to the per-field
path. Both are checked against rosbags' ROS1 serializer, not against each other.
"""

from __future__ import annotations

import dataclasses
import keyword
import operator
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
        self._var = None if self._flat is not None else _VarLayout.of(spec, resolve)
        if self._var is not None:
            self._var.bind(self.cls)
        #: payload size of a message made only of fixed-size fields (``decode`` accepts exactly
        #: the payloads of this length), None otherwise
        self.fixed_size: int | None = None if self._flat is None else self._flat.size
        # the whole-message fast encoder, None when only the per-field path applies
        self._pack = (
            self._flat.pack if self._flat else self._var.pack if self._var is not None else None
        )

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
        pack = self._pack
        if pack is not None and not isinstance(msg, dict):
            packed = pack(msg)
            if packed is not None:
                out += packed
                return
        self.encode_fields_into(msg, out)

    def encode_fields_into(self, msg: Any, out: bytearray) -> None:
        """The per-field (reference) path of :meth:`encode_into`; raises the precise error."""
        for name, enc, _ in self._fields:
            try:
                value = msg[name] if isinstance(msg, dict) else getattr(msg, name)
            except (KeyError, AttributeError) as exc:
                raise EncodeError(f"{self.full_name}: missing field {name!r}") from exc
            enc(value, out)

    def encode(self, msg: Any) -> bytes:
        """Serialize ``msg`` to ROS1 bytes."""
        pack = self._pack
        if pack is not None and not isinstance(msg, dict):
            packed = pack(msg)
            if packed is not None:
                return packed
        out = bytearray()
        self.encode_fields_into(msg, out)
        return bytes(out)

    def decode_from(self, buf: bytes, pos: int) -> tuple[Any, int]:
        """Decode one message starting at ``pos``; returns it and the position after it."""
        flat = self._flat
        if flat is not None and len(buf) - pos >= flat.size:
            return self.cls(*flat.unpack(buf, pos)), pos + flat.size
        var = self._var
        if var is not None:
            done = var.unpack(buf, pos)
            if done is not None:
                return done
        return self.decode_fields_from(buf, pos)

    def decode_fields_from(self, buf: bytes, pos: int) -> tuple[Any, int]:
        """The per-field (reference) path of :meth:`decode_from`; raises the precise error."""
        values = {}
        for name, _, dec in self._fields:
            values[name], pos = dec(buf, pos)
        return self.cls(**values), pos

    def decode(self, data: bytes) -> Any:
        """Decode exactly one message; trailing bytes are an error."""
        flat = self._flat
        if flat is not None and len(data) == flat.size:
            return self.cls(*flat.unpack(data, 0))  # the common case, without the calls below
        buf = bytes(data)
        msg, pos = self.decode_from(buf, 0)
        if pos != len(buf):
            raise DecodeError(f"{self.full_name}: {len(buf) - pos} trailing bytes")
        return msg

    def new(self, **fields: Any) -> Any:
        """A message instance with defaults for the fields not given."""
        return self.cls(**fields)


def _attr(var: str, name: str) -> str:
    """Source text reading field ``name`` of ``var`` (attribute syntax when it is legal)."""
    if name.isidentifier() and not keyword.iskeyword(name):
        return f"{var}.{name}"
    return f"_getattr({var}, {name!r})"


def _generate(src: str, env: dict[str, Any], name: str) -> Any:
    """Compile generated source ``src`` in ``env`` and return the function ``name``."""
    namespace = {"_getattr": getattr, "_TIMES": (RosTime, RosDuration), **env}
    exec(compile(src, f"<rosserial codec {name}>", "exec"), namespace)  # from .msg names
    return namespace[name]


def _fixed_parts(fields: list[Field]) -> tuple[list[tuple[str, str, int | None]], str] | None:
    """``(name, kind, n)`` parts and struct body of fixed-size fields, or None if one is not:
    kind ``v`` primitive scalar, ``a`` fixed primitive array, ``t``/``d`` time/duration."""
    parts: list[tuple[str, str, int | None]] = []
    fmt = ""
    for f in fields:
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
    return parts, fmt


def _pack_lines(parts: list[tuple[str, str, int | None]], first: int) -> tuple[list[str], str]:
    """Generated lines reading fixed parts into ``v<i>`` and checking them (return None on a
    value the single struct must not take), and the ``*``-argument text packing them."""
    lines, args = [], []
    for i, (name, kind, n) in enumerate(parts, first):
        lines.append(f"v{i} = {_attr('msg', name)}")
        if kind == "v":
            args.append(f"v{i}")
        else:
            check = f"len(v{i}) != {n}" if kind == "a" else f"not isinstance(v{i}, _TIMES)"
            lines.append(f"if {check}:\n        return None")
            args.append(f"*v{i}")
    return lines, ", ".join(args)


def _unpack_exprs(parts: list[tuple[str, str, int | None]], first: int) -> list[str]:
    """Generated expressions turning flat tuple ``v`` (from index ``first``) into field values."""
    exprs, i = [], first
    for _, kind, n in parts:
        if kind == "v":
            exprs.append(f"v[{i}]")
            i += 1
        elif kind == "a":
            assert n is not None
            items = ", ".join(f"v[{j}]" for j in range(i, i + n))
            exprs.append(f"[{items}]" if n <= 16 else f"list(v[{i}:{i + n}])")
            i += n
        else:
            exprs.append(f"{'RosTime' if kind == 't' else 'RosDuration'}(v[{i}], v[{i + 1}])")
            i += 2
    return exprs


class _FlatLayout:
    """One ``struct`` for a message made only of fixed-size fields (primitive scalars, fixed
    primitive arrays, ``time``/``duration``): a single pack/unpack instead of one per field.
    Same bytes and values as the per-field path, which still handles every error case
    (:meth:`pack` returns None for anything it does not take, the caller falls back).
    ``pack``/``unpack`` are generated per message type (straight-line code, no field loop)."""

    def __init__(self, parts: list[tuple[str, str, int | None]], fmt: str) -> None:
        self.parts = parts  # (field name, kind: "v" value / "a" array / "t" time / "d", n)
        self.struct = struct.Struct(fmt)
        self.size = self.struct.size
        self.scalars_only = all(kind == "v" for _, kind, _ in parts)
        lines, args = _pack_lines(parts, 0)
        body = "\n    ".join(lines)
        self.pack: Callable[[Any], bytes | None] = _generate(
            f"def pack(msg):\n  try:\n    {body}\n    return _pack({args})\n"
            "  except Exception:  # the per-field path raises the precise error\n    return None\n",
            {"_pack": self.struct.pack},
            "pack",
        )
        self.unpack: Callable[[bytes, int], tuple[Any, ...]]
        if self.scalars_only:
            self.unpack = self.struct.unpack_from  # the field values in field order
        else:
            exprs = ", ".join(_unpack_exprs(parts, 0))
            self.unpack = _generate(
                f"def unpack(buf, pos):\n    v = _unpack_from(buf, pos)\n    return ({exprs},)\n",
                {
                    "_unpack_from": self.struct.unpack_from,
                    "RosTime": RosTime,
                    "RosDuration": RosDuration,
                },
                "unpack",
            )

    @classmethod
    def of(cls, spec: MsgSpec) -> _FlatLayout | None:
        found = _fixed_parts(spec.fields)
        if found is None or not found[0]:
            return None
        return cls(found[0], "<" + found[1])


class _VarLayout:
    """Generated whole-message pack/unpack for messages with variable-length arrays of
    primitives or of flat scalar-only nested messages (``spinal/ServoStates``, ``Pwms``,
    ``FourAxisCommand``, ...) mixed with fixed-size fields: one ``struct`` per array-length
    combination instead of a closure per field and element. Same bytes and values as the
    per-field path; anything it does not take (wrong types, out-of-range values, truncated
    input) makes it return None and the caller runs the per-field path, which raises the
    precise error."""

    _CACHE_MAX = 64  # distinct array-length combinations kept per type

    def __init__(self, full_name: str, segments: list[tuple[Any, ...]]) -> None:
        self.full_name = full_name
        self._segments = segments
        self._structs: dict[tuple[int, ...], struct.Struct] = {}
        env: dict[str, Any] = {
            "_structs": self._structs,
            "_make": self._make,
            "_u32": _U32.unpack_from,
            "RosTime": RosTime,
            "RosDuration": RosDuration,
        }
        pack_lines: list[str] = []
        unpack_lines: list[str] = ["end = len(buf)"]
        args: list[str] = []
        counts: list[str] = []
        values: list[str] = []
        for k, seg in enumerate(segments):
            if seg[0] == "fixed":
                parts, fmt = seg[1], seg[2]
                lines, text = _pack_lines(parts, 100 * k)
                pack_lines += lines
                args.append(text)
                st = struct.Struct("<" + fmt)
                env[f"_fixed{k}"] = st.unpack_from
                unpack_lines += [
                    f"if end - pos < {st.size}:\n        return None",
                    f"v = _fixed{k}(buf, pos)",
                    f"pos += {st.size}",
                ]
                for j, expr in enumerate(_unpack_exprs(parts, 0)):
                    unpack_lines.append(f"f{k}_{j} = {expr}")
                    values.append(f"f{k}_{j}")
                continue
            name, size = seg[1], seg[3]
            pack_lines += [f"a{k} = {_attr('msg', name)}", f"n{k} = len(a{k})"]
            counts.append(f"n{k}")
            unpack_lines += [
                "if end - pos < 4:\n        return None",
                f"n{k} = _u32(buf, pos)[0]",
                "pos += 4",
                f"if n{k} * {size} > end - pos:\n        return None",
            ]
            values.append(f"f{k}")
            if seg[0] == "prim":
                args.append(f"n{k}, *a{k}")
                unpack_lines += [
                    f"f{k} = list(_unpack_from('<%d{seg[2]}' % n{k}, buf, pos))",
                    f"pos += n{k} * {size}",
                ]
                env["_unpack_from"] = struct.unpack_from
            else:  # array of nested messages
                nested: MessageCodec = seg[2]
                names = [f.name for f in nested.spec.fields]
                env[f"_get{k}"] = operator.attrgetter(*names)
                env[f"_iter{k}"] = nested._flat.struct.iter_unpack  # type: ignore[union-attr]
                env[f"_cls{k}"] = nested.cls
                grab = "append" if len(names) == 1 else "extend"
                pack_lines.append(f"e{k} = []\n    for e in a{k}:\n        e{k}.{grab}(_get{k}(e))")
                args.append(f"n{k}, *e{k}")
                unpack_lines += [
                    f"stop = pos + n{k} * {size}",
                    f"f{k} = [_cls{k}(*t) for t in _iter{k}(buf[pos:stop])]",
                    "pos = stop",
                ]
        key = f"({', '.join(counts)},)"
        pack_lines += [
            f"st = _structs.get({key})",
            f"if st is None:\n        st = _make({key})",
            f"return st.pack({', '.join(a for a in args if a)})",
        ]
        body = "\n    ".join(pack_lines)
        self.pack: Callable[[Any], bytes | None] = _generate(
            f"def pack(msg):\n  try:\n    {body}\n"
            "  except Exception:  # the per-field path raises the precise error\n    return None\n",
            env,
            "pack",
        )
        body = "\n    ".join(unpack_lines)
        env["_cls"] = None  # bound in bind()
        self._unpack_src = (
            f"def unpack(buf, pos):\n    {body}\n    return _cls({', '.join(values)}), pos\n"
        )
        self._env = env
        self.unpack: Callable[[bytes, int], tuple[Any, int] | None] = lambda buf, pos: None

    def bind(self, cls: type) -> _VarLayout:
        """Generate the decoder for message class ``cls`` (built after the layout)."""
        self._env["_cls"] = cls
        self.unpack = _generate(self._unpack_src, self._env, "unpack")
        return self

    def _make(self, counts: tuple[int, ...]) -> struct.Struct:
        fmt, it = "<", iter(counts)
        for seg in self._segments:
            if seg[0] == "fixed":
                fmt += seg[2]
                continue
            n = next(it)
            fmt += "I" + (f"{n}{seg[2]}" if seg[0] == "prim" else seg[4] * n)
        if len(self._structs) >= self._CACHE_MAX:
            self._structs.clear()
        st = self._structs[counts] = struct.Struct(fmt)
        return st

    @classmethod
    def of(cls, spec: MsgSpec, resolve: Callable[[str], MessageCodec]) -> _VarLayout | None:
        segments: list[tuple[Any, ...]] = []
        run: list[Field] = []
        has_var = False
        for f in [*spec.fields, None]:
            if f is not None and f.array_len != -1:
                run.append(f)
                continue
            if run:
                found = _fixed_parts(run)
                if found is None:
                    return None
                segments.append(("fixed", found[0], found[1]))
                run = []
            if f is None:
                break
            has_var = True
            if f.is_primitive and f.base_type in _STRUCT_CODE:
                code = _STRUCT_CODE[f.base_type]
                segments.append(("prim", f.name, code, struct.calcsize("<" + code)))
                continue
            if f.is_primitive or f.base_type in ("time", "duration", "string"):
                return None
            nested = resolve(f.base_type)
            flat = nested._flat
            if flat is None or not flat.scalars_only:
                return None
            body = flat.struct.format[1:]
            segments.append(("nested", f.name, nested, flat.size, body))
        return cls(spec.full_name, segments) if has_var else None


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
