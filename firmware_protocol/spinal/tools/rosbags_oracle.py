"""Independent reference for the Spinal wire format, built on ``rosbags`` (not on rdm).

Used by ``generate_vectors.py`` and by the tests: it registers every ``.msg``/``.srv`` of this
tree in a rosbags ROS1 typestore, converts plain JSON-like field dicts to rosbags messages,
serializes them with rosbags' ROS1 serializer, reports rosbags' md5 sums, and frames payloads
with a separate hand-written rosserial v2 formula.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

ROOT = Path(__file__).resolve().parents[1]
TIME = "builtin_interfaces/msg/Time"
DURATION = "builtin_interfaces/msg/Duration"
# rosbags gives empty messages this placeholder member (a ROS 2 rule); ROS1 sends no bytes
PLACEHOLDER = "structure_needs_at_least_one_member"

_DTYPES = {
    "bool": np.bool_,
    "int8": np.int8,
    "uint8": np.uint8,
    "byte": np.uint8,
    "char": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}


def rosbags_name(name: str) -> str:
    """``spinal/Imu`` -> ``spinal/msg/Imu``."""
    pkg, typ = name.split("/")
    return f"{pkg}/msg/{typ}"


def make_typestore(root: Path = ROOT):
    """A ROS1 typestore with every type of the tree (service halves as ``<Srv>Request`` ...)."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    types: dict[str, Any] = {}
    for path in sorted(root.glob("*/msg/*.msg")):
        name = f"{path.parts[-3]}/msg/{path.stem}"
        if name not in ts.types:
            types.update(get_types_from_msg(path.read_text(), name))
    for path in sorted(root.glob("*/srv/*.srv")):
        req, res = re.split(r"^---[ \t]*$", path.read_text(), maxsplit=1, flags=re.MULTILINE)
        base = f"{path.parts[-3]}/msg/{path.stem}"
        types.update(get_types_from_msg(req, base + "Request"))
        types.update(get_types_from_msg(res, base + "Response"))
    ts.register(types)
    return ts


def _convert(ts, node: tuple, value: Any) -> Any:
    kind, spec = node
    if kind == Nodetype.BASE:
        return value
    if kind == Nodetype.NAME:
        if spec == TIME:
            return ts.types[TIME](sec=value["sec"], nanosec=value["nsec"])
        if spec == DURATION:
            return ts.types[DURATION](sec=value["sec"], nanosec=value["nsec"])
        return to_rosbags(ts, spec, value)
    sub, _count = spec
    if sub[0] == Nodetype.BASE and sub[1][0] != "string":
        return np.array(value, dtype=_DTYPES[sub[1][0]])
    return [_convert(ts, sub, v) for v in value]


def to_rosbags(ts, typename: str, fields: dict[str, Any]) -> Any:
    """Plain dict (times as ``{"sec", "nsec"}``) -> rosbags message of ``pkg/msg/Type``."""
    _consts, defs = ts.fielddefs[typename]
    return ts.types[typename](
        **{
            name: 0 if name == PLACEHOLDER else _convert(ts, node, fields[name])
            for name, node in defs
        }
    )


def from_rosbags(ts, msg: Any) -> Any:
    """rosbags message -> plain dict in the same form as ``rdm`` ``message_to_dict``."""
    msgtype = getattr(msg, "__msgtype__", None)
    if msgtype in (TIME, DURATION):
        return {"sec": int(msg.sec), "nsec": int(msg.nanosec)}
    if msgtype is not None:
        _consts, defs = ts.fielddefs[msgtype]
        return {
            name: from_rosbags(ts, getattr(msg, name))
            for name, _node in defs
            if name != PLACEHOLDER
        }
    if isinstance(msg, np.ndarray):
        return [v.item() for v in msg]
    if isinstance(msg, list):
        return [from_rosbags(ts, v) for v in msg]
    if isinstance(msg, np.generic):
        return msg.item()
    return msg


def serialize(ts, typename: str, fields: dict[str, Any]) -> bytes:
    """rosbags' ROS1 serialization of a plain field dict."""
    return bytes(ts.serialize_ros1(to_rosbags(ts, typename, fields), typename))


def deserialize(ts, typename: str, data: bytes) -> Any:
    return from_rosbags(ts, ts.deserialize_ros1(data, typename))


def md5(ts, typename: str) -> str:
    return ts.generate_msgdef(typename)[1]


def frame(topic_id: int, payload: bytes) -> bytes:
    """rosserial v2 frame, written out independently of rdm's framing module."""
    n = len(payload)
    lo, hi = n % 256, n // 256
    t_lo, t_hi = topic_id % 256, topic_id // 256
    return (
        bytes([0xFF, 0xFE, lo, hi, (255 - (lo + hi) % 256) % 256, t_lo, t_hi])
        + payload
        + bytes([(255 - (t_lo + t_hi + sum(payload)) % 256) % 256])
    )


def random_fields(ts, typename: str, rng: np.random.Generator, max_len: int = 4) -> dict:
    """Random field values for ``typename`` (float32 values exactly representable)."""
    _consts, defs = ts.fielddefs[typename]
    return {name: _random(ts, node, rng, max_len) for name, node in defs if name != PLACEHOLDER}


def _random_base(base: str, rng: np.random.Generator) -> Any:
    if base == "bool":
        return bool(rng.integers(0, 2))
    if base == "string":
        return "".join(chr(int(c)) for c in rng.integers(32, 127, size=int(rng.integers(0, 12))))
    if base in ("float32", "float64"):
        v = float(rng.normal() * 10.0 ** int(rng.integers(-3, 4)))
        return float(np.float32(v)) if base == "float32" else v
    info = np.iinfo(_DTYPES[base])
    return int(rng.integers(info.min, info.max, endpoint=True))


def _random(ts, node: tuple, rng: np.random.Generator, max_len: int) -> Any:
    kind, spec = node
    if kind == Nodetype.BASE:
        return _random_base(spec[0], rng)
    if kind == Nodetype.NAME:
        if spec in (TIME, DURATION):
            return {"sec": int(rng.integers(0, 2**31 - 1)), "nsec": int(rng.integers(0, 10**9))}
        return random_fields(ts, spec, rng, max_len)
    sub, count = spec
    n = count if kind == Nodetype.ARRAY else int(rng.integers(0, max_len + 1))
    return [_random(ts, sub, rng, max_len) for _ in range(n)]
