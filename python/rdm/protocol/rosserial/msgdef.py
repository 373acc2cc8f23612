"""Parser for ROS1 ``.msg`` and ``.srv`` text (the single source of truth for Spinal payloads).

Only the subset genmsg accepts is handled: ``type name`` fields, ``type NAME=value`` constants,
``T[]`` and ``T[n]`` arrays, ``#`` comments. Types without a package are resolved in the
message's own package, except the builtins and ``Header`` (-> ``std_msgs/Header``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

#: ROS1 builtin scalar types (``byte``/``char`` are genmsg's deprecated aliases).
PRIMITIVES = frozenset(
    {
        "bool",
        "int8",
        "uint8",
        "byte",
        "char",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "float32",
        "float64",
        "string",
        "time",
        "duration",
    }
)

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_TYPE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*/)?[A-Za-z][A-Za-z0-9_]*(\[[0-9]*\])?$")


class MsgDefError(ValueError):
    """A ``.msg``/``.srv`` text that does not parse; the message names file and line."""


@dataclass(frozen=True)
class Field:
    """One field: ``base_type`` is a primitive or a full ``pkg/Type``; ``array_len`` is None
    for a scalar, -1 for a variable-length array, else the fixed length."""

    name: str
    base_type: str
    array_len: int | None
    type_text: str  # the type as written in the file (genmsg md5 text uses it verbatim)

    @property
    def is_primitive(self) -> bool:
        return self.base_type in PRIMITIVES


@dataclass(frozen=True)
class Constant:
    """A ``type NAME=value`` line; ``value_text`` is what genmsg hashes."""

    type: str
    name: str
    value_text: str
    value: int | float | str | bool


@dataclass(frozen=True)
class MsgSpec:
    """A parsed message: full name ``pkg/Type``, fields in wire order, constants in file order."""

    full_name: str
    fields: tuple[Field, ...]
    constants: tuple[Constant, ...]
    text: str

    @property
    def package(self) -> str:
        return self.full_name.split("/")[0]

    @property
    def short_name(self) -> str:
        return self.full_name.split("/")[1]


@dataclass(frozen=True)
class SrvSpec:
    """A parsed service: its request and response message specs (``pkg/TypeRequest`` ...)."""

    full_name: str
    request: MsgSpec
    response: MsgSpec


def _resolve(type_name: str, package: str) -> str:
    if type_name in PRIMITIVES:
        return type_name
    if type_name == "Header":
        return "std_msgs/Header"
    return type_name if "/" in type_name else f"{package}/{type_name}"


def _constant_value(type_name: str, text: str, where: str) -> int | float | str | bool:
    try:
        if type_name == "string":
            return text
        if type_name in ("float32", "float64"):
            return float(text)
        if type_name == "bool":
            return text.strip().lower() in ("1", "true")
        return int(text, 0)
    except ValueError as exc:
        raise MsgDefError(f"{where}: bad constant value {text!r} for {type_name}") from exc


def parse_msg(full_name: str, text: str) -> MsgSpec:
    """Parse ``.msg`` text for the message ``pkg/Type``."""
    package = full_name.split("/")[0]
    fields: list[Field] = []
    constants: list[Constant] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        where = f"{full_name} line {lineno}"
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        head = line.split(None, 1)
        if len(head) != 2:
            raise MsgDefError(f"{where}: expected 'type name' in {raw!r}")
        type_text, rest = head
        # string constants keep everything after '=' (genmsg does not strip their comments)
        if "=" in rest.split("#", 1)[0] or (type_text == "string" and "=" in rest):
            name, _, value = rest.partition("=")
            name = name.strip()
            value = value.strip() if type_text == "string" else value.split("#", 1)[0].strip()
            if type_text not in PRIMITIVES or type_text in ("time", "duration"):
                raise MsgDefError(f"{where}: constants must have a primitive type")
            if not _NAME.match(name):
                raise MsgDefError(f"{where}: bad constant name {name!r}")
            constants.append(
                Constant(type_text, name, value, _constant_value(type_text, value, where))
            )
            continue
        name = rest.split("#", 1)[0].strip()
        if not _TYPE.match(type_text) or not _NAME.match(name):
            raise MsgDefError(f"{where}: cannot parse field {raw!r}")
        base, array_len = type_text, None
        if type_text.endswith("]"):
            base, _, size = type_text[:-1].partition("[")
            array_len = int(size) if size else -1
        fields.append(Field(name, _resolve(base, package), array_len, type_text))
    return MsgSpec(full_name, tuple(fields), tuple(constants), text)


def parse_srv(full_name: str, text: str) -> SrvSpec:
    """Parse ``.srv`` text: request and response separated by a line of three dashes."""
    parts = re.split(r"^---[ \t]*$", text, maxsplit=1, flags=re.MULTILINE)
    if len(parts) != 2:
        raise MsgDefError(f"{full_name}: a .srv needs a '---' line between request and response")
    return SrvSpec(
        full_name,
        parse_msg(full_name + "Request", parts[0]),
        parse_msg(full_name + "Response", parts[1]),
    )
