"""Generated whole-message layouts: the one ROS1 encode/decode path of every message type.

Each type gets straight-line ``pack``/``read`` code generated from its ``.msg`` fields (no
field loop at run time). A type made only of fixed-size fields (primitive scalars, fixed
primitive arrays, ``time``/``duration``) is a :class:`FlatLayout`: one ``struct`` for the
whole message. Every other type is a :class:`VarLayout`: one ``struct`` per combination of
array counts and string/blob lengths (a cache of 64 per type), with variable arrays of
primitives and of flat scalar-only messages packed inline (``iter_unpack`` on the way back),
strings as ``I{n}s``, and nested messages by value, arrays of them and arrays of strings or
times as ``{n}s`` blobs made by the nested type's own layout.

``pack`` takes a message object with exactly typed times (:class:`RosTime` /
:class:`RosDuration`) and raises on anything else (any exception: the codec then normalises
the value and names the refused field); ``read`` raises :class:`DecodeError` naming the field
and the byte offset.
"""

from __future__ import annotations

import functools
import keyword
import operator
import struct
from collections.abc import Callable
from typing import Any

from rdm.protocol.rosserial.msgdef import Field, MsgSpec
from rdm.protocol.rosserial.wire import (
    DURATION,
    STRUCT_CODE,
    TIME,
    TIMES,
    U32,
    RosDuration,
    RosTime,
    cut,
    over_count,
    raw_string,
)

Part = tuple[str, str, int | None]  # (field name, kind: v value / a array / t time / d duration, n)
Reader = Callable[[bytes, int], tuple[Any, int]]


def _attr(var: str, name: str) -> str:
    """Source text reading field ``name`` of ``var`` (attribute syntax when it is legal)."""
    if name.isidentifier() and not keyword.iskeyword(name):
        return f"{var}.{name}"
    return f"_getattr({var}, {name!r})"


def _generate(src: str, env: dict[str, Any], name: str) -> Any:
    """Compile generated source ``src`` in ``env`` and return the function ``name``."""
    namespace = {"_getattr": getattr, "_TIMES": TIMES, **env}
    exec(compile(src, f"<rosserial layout {name}>", "exec"), namespace)  # from .msg names
    return namespace[name]


def _fixed_parts(fields: list[Field]) -> tuple[list[Part], str, list[int]] | None:
    """Parts, struct body and byte sizes of fixed-size fields, or None if one is not."""
    parts: list[Part] = []
    fmt = ""
    sizes: list[int] = []
    for f in fields:
        if f.base_type in ("time", "duration") and f.array_len is None:
            parts.append((f.name, "t" if f.base_type == "time" else "d", None))
            fmt += "II" if f.base_type == "time" else "ii"
            sizes.append(8)
        elif f.is_primitive and f.base_type in STRUCT_CODE:
            code = STRUCT_CODE[f.base_type]
            if f.array_len is None:
                parts.append((f.name, "v", None))
                fmt += code
                sizes.append(struct.calcsize("<" + code))
            elif f.array_len >= 0:
                parts.append((f.name, "a", f.array_len))
                fmt += f"{f.array_len}{code}"
                sizes.append(struct.calcsize(f"<{f.array_len}{code}"))
            else:
                return None
        else:
            return None
    return parts, fmt, sizes


def _pack_lines(parts: list[Part], first: int) -> tuple[list[str], str]:
    """Generated lines reading fixed parts into ``v<i>`` and refusing (ValueError) a fixed
    array of another length or a time that is not a RosTime/RosDuration, and the
    ``*``-argument text packing them."""
    lines, args = [], []
    for i, (name, kind, n) in enumerate(parts, first):
        lines.append(f"v{i} = {_attr('msg', name)}")
        if kind == "v":
            args.append(f"v{i}")
        else:
            check = f"len(v{i}) != {n}" if kind == "a" else f"not isinstance(v{i}, _TIMES)"
            lines.append(f"if {check}:\n        raise ValueError({name!r})")
            args.append(f"*v{i}")
    return lines, ", ".join(args)


def _unpack_exprs(parts: list[Part], first: int) -> list[str]:
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


def _short(full_name: str, run: list[tuple[str, int]], pos: int, end: int) -> Exception:
    """The DecodeError of the fixed run ``run`` ((field, size) pairs) read at ``pos`` from a
    buffer ending at ``end``: it names the first field that does not fit."""
    for name, size in run:
        if pos + size > end:
            return cut(f"{full_name}.{name}", size, pos, end)
        pos += size
    return cut(full_name, 0, pos, end)  # not reached: the run did not fit


class FlatLayout:
    """One ``struct`` for a message made only of fixed-size fields: ``pack`` is a single
    ``struct.pack``, ``unpack`` a single ``unpack_from`` (the field values in order)."""

    def __init__(self, full_name: str, parts: list[Part], fmt: str, sizes: list[int]) -> None:
        self.parts = tuple(parts)
        self.struct = struct.Struct("<" + fmt)
        self.size = self.min_size = self.struct.size
        run = [(p[0], s) for p, s in zip(parts, sizes, strict=True)]
        self.short = functools.partial(_short, full_name, run)
        lines, args = _pack_lines(parts, 0)
        body = "\n    ".join(lines)
        self.pack: Callable[[Any], bytes] = _generate(
            f"def pack(msg):\n    {body}\n    return _pack({args})\n",
            {"_pack": self.struct.pack},
            "pack",
        )
        self.unpack: Callable[[bytes, int], tuple[Any, ...]]
        if all(kind == "v" for _, kind, _ in parts):
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
        self.read: Reader = lambda buf, pos: (None, pos)  # bound in bind()

    @property
    def scalars_only(self) -> bool:
        """Whether every field is a primitive scalar (``unpack`` gives the field values)."""
        return all(kind == "v" for _, kind, _ in self.parts)

    def bind(self, cls: type) -> FlatLayout:
        """Make ``read(buf, pos) -> (message of cls, next pos)``."""
        size, unpack, short = self.size, self.unpack, self.short

        def read(buf: bytes, pos: int) -> tuple[Any, int]:
            if len(buf) - pos < size:
                raise short(pos, len(buf))
            return cls(*unpack(buf, pos)), pos + size

        self.read = read
        return self

    def signature(self) -> tuple[Any, ...]:
        """The wire layout as plain data: ``(("fixed", parts, struct body),)``."""
        return (("fixed", self.parts, self.struct.format[1:]),)


def _element(base: str, where: str, resolve: Callable[[str], Any]) -> tuple[Any, Reader, int]:
    """Bytes packer, reader and minimum size of one array element (string, time, message)."""
    if base == "string":

        def enc_str(value: Any) -> bytes:
            raw = raw_string(value)
            return U32.pack(len(raw)) + raw

        return enc_str, functools.partial(_read_string, where), 4
    if base in ("time", "duration"):
        st, kind = (TIME, RosTime) if base == "time" else (DURATION, RosDuration)

        def enc_time(value: Any) -> bytes:
            if not isinstance(value, TIMES):
                raise ValueError(where)
            return st.pack(*value)

        def read_time(buf: bytes, pos: int) -> tuple[Any, int]:
            if len(buf) - pos < 8:
                raise cut(where, 8, pos, len(buf))
            return kind(*st.unpack_from(buf, pos)), pos + 8

        return enc_time, read_time, 8
    nested = resolve(base).layout
    return nested.pack, nested.read, nested.min_size


def _read_string(where: str, buf: bytes, pos: int) -> tuple[str, int]:
    end = len(buf)
    if end - pos < 4:
        raise cut(where, 4, pos, end)
    (n,) = U32.unpack_from(buf, pos)
    pos += 4
    if n > end - pos:
        raise cut(where, n, pos, end)
    # surrogateescape keeps non-UTF-8 bytes so that decode -> encode is exact
    return str(buf[pos : pos + n], "utf-8", "surrogateescape"), pos + n


def _blob(f: Field, where: str, resolve: Callable[[str], Any]) -> tuple[Any, Reader, int]:
    """Packer to bytes, reader and minimum size of a field packed as a blob: a nested message
    by value, or an array of strings, times or nested messages."""
    enc, read, size = _element(f.base_type, where, resolve)
    if f.array_len is None:
        return enc, read, size
    n = f.array_len
    if n >= 0:

        def enc_fixed(value: Any) -> bytes:
            if len(value) != n:
                raise ValueError(where)
            return b"".join([enc(v) for v in value])

        def read_fixed(buf: bytes, pos: int) -> tuple[Any, int]:
            items = []
            for _ in range(n):
                item, pos = read(buf, pos)
                items.append(item)
            return items, pos

        return enc_fixed, read_fixed, n * size
    guard = max(size, 1)

    def enc_var(value: Any) -> bytes:
        return U32.pack(len(value)) + b"".join([enc(v) for v in value])

    def read_var(buf: bytes, pos: int) -> tuple[Any, int]:
        end = len(buf)
        if end - pos < 4:
            raise cut(where, 4, pos, end)
        (count,) = U32.unpack_from(buf, pos)
        pos += 4
        if count * guard > end - pos:
            raise over_count(where, count, pos)
        items = []
        for _ in range(count):
            item, pos = read(buf, pos)
            items.append(item)
        return items, pos

    return enc_var, read_var, 4


class VarLayout:
    """Generated ``pack``/``read`` of a message with variable-size fields mixed with fixed
    ones: one ``struct`` per combination of array counts and string/blob lengths. Segments:
    ``fixed`` runs of fixed-size fields, ``prim`` variable arrays of primitives, ``nested``
    variable arrays of flat scalar-only messages (their fields inline), ``string`` and
    ``blob`` (``{n}s`` bytes of a nested message, or of an array of strings, times or
    non-flat messages, made by :func:`_blob`)."""

    _CACHE_MAX = 64  # distinct count/length combinations kept per type

    def __init__(self, full_name: str, segments: list[tuple[Any, ...]]) -> None:
        self.full_name = full_name
        self._segments = segments
        self._structs: dict[tuple[int, ...], struct.Struct] = {}
        env: dict[str, Any] = {
            "_structs": self._structs,
            "_make": self._make,
            "_u32": U32.unpack_from,
            "_unpack_from": struct.unpack_from,
            "_raw": raw_string,
            "_cut": cut,
            "_over": over_count,
            "RosTime": RosTime,
            "RosDuration": RosDuration,
        }
        pack_lines: list[str] = []
        read_lines: list[str] = ["end = len(buf)"]
        args: list[str] = []
        counts: list[str] = []
        values: list[str] = []
        self.min_size = 0
        for k, seg in enumerate(segments):
            kind = seg[0]
            if kind == "fixed":
                parts, fmt, sizes = seg[1], seg[2], seg[3]
                lines, text = _pack_lines(parts, 100 * k)
                pack_lines += lines
                args.append(text)
                st = struct.Struct("<" + fmt)
                self.min_size += st.size
                env[f"_fixed{k}"] = st.unpack_from
                env[f"_short{k}"] = functools.partial(
                    _short, full_name, [(p[0], s) for p, s in zip(parts, sizes, strict=True)]
                )
                read_lines += [
                    f"if end - pos < {st.size}:\n        raise _short{k}(pos, end)",
                    f"v = _fixed{k}(buf, pos)",
                    f"pos += {st.size}",
                ]
                for j, expr in enumerate(_unpack_exprs(parts, 0)):
                    read_lines.append(f"f{k}_{j} = {expr}")
                    values.append(f"f{k}_{j}")
                continue
            name = seg[1]
            where = f"{full_name}.{name}"
            values.append(f"f{k}")
            counts.append(f"n{k}")
            self.min_size += 4 if kind != "blob" else seg[4]
            if kind == "string":
                pack_lines += [f"r{k} = _raw({_attr('msg', name)})", f"n{k} = len(r{k})"]
                args.append(f"n{k}, r{k}")
                env[f"_str{k}"] = functools.partial(_read_string, where)
                read_lines.append(f"f{k}, pos = _str{k}(buf, pos)")
                continue
            if kind == "blob":
                env[f"_enc{k}"], env[f"_read{k}"] = seg[2], seg[3]
                pack_lines += [f"r{k} = _enc{k}({_attr('msg', name)})", f"n{k} = len(r{k})"]
                args.append(f"r{k}")
                read_lines.append(f"f{k}, pos = _read{k}(buf, pos)")
                continue
            size = seg[3]
            pack_lines += [f"a{k} = {_attr('msg', name)}", f"n{k} = len(a{k})"]
            read_lines += [
                f"if end - pos < 4:\n        raise _cut({where!r}, 4, pos, end)",
                f"n{k} = _u32(buf, pos)[0]",
                "pos += 4",
                f"if n{k} * {size} > end - pos:\n        raise _over({where!r}, n{k}, pos)",
            ]
            if kind == "prim":
                args.append(f"n{k}, *a{k}")
                read_lines += [
                    f"f{k} = list(_unpack_from('<%d{seg[2]}' % n{k}, buf, pos))",
                    f"pos += n{k} * {size}",
                ]
            else:  # array of flat scalar-only messages
                nested = seg[2]
                names = [f.name for f in nested.spec.fields]
                env[f"_get{k}"] = operator.attrgetter(*names)
                env[f"_iter{k}"] = nested.layout.struct.iter_unpack
                env[f"_cls{k}"] = nested.cls
                grab = "append" if len(names) == 1 else "extend"
                pack_lines.append(f"e{k} = []\n    for e in a{k}:\n        e{k}.{grab}(_get{k}(e))")
                args.append(f"n{k}, *e{k}")
                read_lines += [
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
        self.pack: Callable[[Any], bytes] = _generate(f"def pack(msg):\n    {body}\n", env, "pack")
        body = "\n    ".join(read_lines)
        result = ", ".join(values)
        self._read_src = f"def read(buf, pos):\n    {body}\n    return _cls({result}), pos\n"
        self._env = env
        self.read: Reader = lambda buf, pos: (None, pos)  # bound in bind()

    def bind(self, cls: type) -> VarLayout:
        """Generate ``read(buf, pos) -> (message of cls, next pos)`` (cls is built after the
        layout)."""
        self._env["_cls"] = cls
        self.read = _generate(self._read_src, self._env, "read")
        return self

    def _make(self, counts: tuple[int, ...]) -> struct.Struct:
        fmt, it = "<", iter(counts)
        for seg in self._segments:
            kind = seg[0]
            if kind == "fixed":
                fmt += seg[2]
                continue
            n = next(it)
            if kind == "prim":
                fmt += f"I{n}{seg[2]}"
            elif kind == "nested":
                fmt += "I" + seg[4] * n
            elif kind == "string":
                fmt += f"I{n}s"
            else:
                fmt += f"{n}s"
        if len(self._structs) >= self._CACHE_MAX:
            self._structs.clear()
        st = self._structs[counts] = struct.Struct(fmt)
        return st

    def signature(self) -> tuple[Any, ...]:
        """The wire layout as plain data, one tuple per segment: ``("fixed", parts, struct
        body)``, ``("prim", field, code)``, ``("nested", field, element struct body, element
        field names)``, ``("string", field)``, ``("blob", field, type text)``."""
        out: list[tuple[Any, ...]] = []
        for seg in self._segments:
            kind = seg[0]
            if kind == "fixed":
                out.append(("fixed", tuple(seg[1]), seg[2]))
            elif kind == "prim":
                out.append(("prim", seg[1], seg[2]))
            elif kind == "nested":
                out.append(("nested", seg[1], seg[4], tuple(f.name for f in seg[2].spec.fields)))
            elif kind == "string":
                out.append(("string", seg[1]))
            else:
                out.append(("blob", seg[1], seg[5]))
        return tuple(out)


def layout_of(spec: MsgSpec, resolve: Callable[[str], Any]) -> FlatLayout | VarLayout:
    """The generated layout of ``spec`` (nested types through ``resolve``: their codecs)."""
    found = _fixed_parts(list(spec.fields))
    if found is not None:
        return FlatLayout(spec.full_name, *found)
    segments: list[tuple[Any, ...]] = []
    run: list[Field] = []
    for f in [*spec.fields, None]:
        if f is not None and _fixed_parts([f]) is not None:
            run.append(f)
            continue
        if run:
            parts, fmt, sizes = _fixed_parts(run)  # type: ignore[misc]
            segments.append(("fixed", parts, fmt, sizes))
            run = []
        if f is None:
            break
        where = f"{spec.full_name}.{f.name}"
        if f.base_type == "string" and f.array_len is None:
            segments.append(("string", f.name))
        elif f.array_len == -1 and f.base_type in STRUCT_CODE:
            code = STRUCT_CODE[f.base_type]
            segments.append(("prim", f.name, code, struct.calcsize("<" + code)))
        elif f.array_len == -1 and not f.is_primitive and _flat_scalars(resolve(f.base_type)):
            nested = resolve(f.base_type)
            body = nested.layout.struct.format[1:]
            segments.append(("nested", f.name, nested, nested.layout.size, body))
        else:
            enc, read, size = _blob(f, where, resolve)
            segments.append(("blob", f.name, enc, read, size, f.type_text))
    return VarLayout(spec.full_name, segments)


def _flat_scalars(codec: Any) -> bool:
    """Whether ``codec``'s layout is flat with primitive scalars only (inlined in arrays)."""
    layout = codec.layout
    return isinstance(layout, FlatLayout) and bool(layout.parts) and layout.scalars_only
