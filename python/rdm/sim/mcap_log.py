"""MCAP signal log for Foxglove Studio and PlotJuggler.

Two kinds of channel, each with a registered schema (PlotJuggler looks the schema up by id):

* ``ros1msg`` / ``ros1`` for Spinal messages: the schema is the full ROS1 message definition
  (the ``.msg`` text from ``firmware_protocol/spinal`` plus every nested type after a
  ``====`` / ``MSG: pkg/Type`` separator, as ``gendeps --cat`` writes it), the payload the
  ROS1 serialisation by the rosserial registry's codec, and the channel carries the md5;
* ``jsonschema`` / ``json`` for everything else (plant ground truth, sensor values, node
  diagnostics): the schema is inferred from the first message (numbers, booleans, strings,
  arrays of numbers, nested objects); a field that is null in it is left open (``{}``: any
  value), since its type is not known yet, so every later record still meets the schema.

Log times are simulated time in ns. Chunks are small (64 KiB) so a crash loses little; call
:meth:`McapLogger.finish` in a ``finally`` (it writes the summary and footer). The file is
written by :class:`rdm.sim.mcap_writer.McapWriter` (a full chunk compressed and written on one
worker thread while the caller goes on; ``finish`` waits for it); a logger is used from one
thread.
"""

from __future__ import annotations

import inspect
import json
import math
import operator
import os
from collections.abc import Mapping
from typing import Any, BinaryIO

import numpy as np
from mcap.writer import CompressionType

from rdm.output_files import open_output
from rdm.protocol.rosserial.msgdef import MsgSpec
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry

from .mcap_writer import McapWriter

CHUNK_SIZE = 64 * 1024
#: Per dataclass type: (field names, attrgetter of them all, whether the values are the
#: instance ``__dict__``'s) for :meth:`McapLogger.log_truth`.
_FIELD_GETTERS: dict[type, tuple[tuple[str, ...], Any, bool]] = {}
_SEPARATOR = "=" * 80


def ros1_definition(registry: TypeRegistry, full_name: str) -> str:
    """The concatenated ROS1 definition of ``full_name`` (what ``gendeps --cat`` prints)."""
    parts = [registry.spec(full_name).text.rstrip("\n")]
    seen: set[str] = set()

    def visit(spec: MsgSpec) -> None:
        for f in spec.fields:
            if f.is_primitive or f.base_type in seen:
                continue
            seen.add(f.base_type)
            dep = registry.spec(f.base_type)
            parts.append(f"{_SEPARATOR}\nMSG: {f.base_type}\n{dep.text.rstrip(chr(10))}")
            visit(dep)

    visit(registry.spec(full_name))
    return "\n".join(parts) + "\n"


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        kind = value.dtype.kind
        # Finite floats, ints and bools come out of tolist() as the Python values the
        # element-wise walk would return: one call for the common arrays.
        if kind in "iub":
            return value.tolist()
        if kind == "f" and value.ndim == 1:
            values = value.tolist()
            if all(map(math.isfinite, values)):
                return values
            return [v if math.isfinite(v) else None for v in values]
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None  # JSON has no NaN/inf
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def _field_getter(cls: type) -> tuple[tuple[str, ...], Any, bool]:
    """(field names, attrgetter of them all, whether an instance's ``__dict__`` holds the
    values ``attrgetter`` reads: no field is a data descriptor of the class, instances have
    a ``__dict__``)."""
    keys = tuple(cls.__dataclass_fields__)  # type: ignore[attr-defined]
    direct = (
        cls.__dictoffset__ != 0
        and cls.__getattribute__ is object.__getattribute__  # type: ignore[comparison-overlap]
        and not any(
            hasattr(type(inspect.getattr_static(cls, k, None)), "__set__")
            or hasattr(type(inspect.getattr_static(cls, k, None)), "__delete__")
            for k in keys
        )
    )
    return keys, operator.attrgetter(*keys), direct


def _schema_of(value: Any) -> dict[str, Any]:
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, int):
        return {"type": "integer"}
    if value is None:  # no value yet: the field's type is not known from this record
        return {}
    if isinstance(value, float):
        return {"type": ["number", "null"]}
    if isinstance(value, str):
        return {"type": "string"}
    if isinstance(value, list):
        return {"type": "array", "items": _schema_of(value[0]) if value else {}}
    if isinstance(value, dict):
        return {
            "type": "object",
            "properties": {k: _schema_of(v) for k, v in value.items()},
        }
    raise TypeError(f"McapLogger: cannot log a {type(value).__name__} as JSON")


class McapLogger:
    """Write signals to an MCAP file. Use as a context manager or call :meth:`finish`."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        registry: TypeRegistry | None = None,
        *,
        chunk_size: int = CHUNK_SIZE,
        compression: CompressionType = CompressionType.ZSTD,
    ) -> None:
        self.path = path
        self._file: BinaryIO = open_output(path, "wb")
        try:
            self._writer = McapWriter(self._file, chunk_size=chunk_size, compression=compression)
            self._writer.start(profile="ros1", library="rdm")
        except BaseException:
            self._file.close()
            raise
        self._registry = registry
        self._channels: dict[str, tuple[int, str]] = {}  # topic -> (channel id, kind)
        self._schemas: dict[tuple[str, str], int] = {}
        self._seq: dict[int, int] = {}
        self.messages = 0
        self._finished = False

    @property
    def registry(self) -> TypeRegistry:
        if self._registry is None:
            self._registry = spinal_registry()
        return self._registry

    # ------------------------------------------------------------------ channels
    def _schema(self, name: str, encoding: str, data: bytes) -> int:
        key = (name, encoding)
        sid = self._schemas.get(key)
        if sid is None:
            sid = self._writer.register_schema(name=name, encoding=encoding, data=data)
            self._schemas[key] = sid
        return sid

    def ros1_channel(self, topic: str, type_name: str) -> int:
        """Register (once) a ``ros1`` channel for Spinal type ``type_name`` (e.g. spinal/Imu)."""
        known = self._channels.get(topic)
        if known is not None:
            if known[1] != f"ros1:{type_name}":
                raise ValueError(f"McapLogger: topic {topic!r} already has type {known[1]}")
            return known[0]
        text = ros1_definition(self.registry, type_name)
        sid = self._schema(type_name, "ros1msg", text.encode())
        cid = self._writer.register_channel(
            topic=topic,
            message_encoding="ros1",
            schema_id=sid,
            metadata={"md5sum": self.registry.md5(type_name)},
        )
        self._channels[topic] = (cid, f"ros1:{type_name}")
        return cid

    def json_channel(self, topic: str, example: Mapping[str, Any], schema_name: str = "") -> int:
        """Register (once) a ``json`` channel whose schema is inferred from ``example``."""
        known = self._channels.get(topic)
        if known is not None:
            return known[0]
        schema = _schema_of(_jsonable(dict(example)))
        name = schema_name or topic.strip("/").replace("/", ".") or "root"
        sid = self._schema(name, "jsonschema", json.dumps(schema, sort_keys=True).encode())
        cid = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        self._channels[topic] = (cid, "json")
        return cid

    # ------------------------------------------------------------------ messages
    def _time_ns(self, t: float) -> int:
        if not math.isfinite(t) or t < 0:
            raise ValueError(f"McapLogger: time {t!r} must be finite and >= 0")
        return round(t * 1e9)

    def _add(self, cid: int, t: float, data: bytes) -> None:
        ns = self._time_ns(t)
        seq = self._seq.get(cid, 0)
        self._writer.add_message(cid, ns, seq, data)
        self._seq[cid] = seq + 1
        self.messages += 1

    def log_ros1(self, topic: str, type_name: str, t: float, message: Any) -> None:
        """Log a Spinal message (a registry dataclass instance, or its ROS1 bytes)."""
        cid = self.ros1_channel(topic, type_name)
        if isinstance(message, (bytes, bytearray, memoryview)):
            data = bytes(message)
        else:
            data = self.registry.msg(type_name).encode(message)
        self._add(cid, t, data)

    def log_json(self, topic: str, t: float, values: Mapping[str, Any]) -> None:
        """Log a dict of values (numpy arrays allowed; NaN/inf become null). On a known
        channel a flat record (the 100 Hz truth and status) is encoded in Rust straight into
        the chunk; the text is ``json.dumps``'s, which writes any other record."""
        known = self._channels.get(topic)
        if known is not None:
            cid = known[0]
            ns = self._time_ns(t)
            seq = self._seq.get(cid, 0)
            if self._writer.add_record(cid, ns, seq, values):
                self._seq[cid] = seq + 1
                self.messages += 1
                return
        doc = _jsonable(dict(values))
        cid = self.json_channel(topic, doc)
        self._add(cid, t, json.dumps(doc, separators=(",", ":")).encode())

    def log_truth(self, truth: Any, topic: str = "/plant/ground_truth") -> None:
        """Log a :class:`rdm.plant.GroundTruth` (every field) at its own time."""
        getter = _FIELD_GETTERS.get(type(truth))
        if getter is None:
            getter = _FIELD_GETTERS[type(truth)] = _field_getter(type(truth))
        keys, values, direct = getter
        if direct:
            known = self._channels.get(topic)
            if known is not None:
                # The fields straight from the instance dict into the chunk (one Rust call;
                # the same text as the dict below).
                cid = known[0]
                ns = self._time_ns(float(truth.time))
                seq = self._seq.get(cid, 0)
                if self._writer.add_fields(cid, ns, seq, truth.__dict__, keys):
                    self._seq[cid] = seq + 1
                    self.messages += 1
                    return
        # attrgetter: every field in one C call, in field order (as the dict comprehension).
        self.log_json(topic, float(truth.time), dict(zip(keys, values(truth), strict=True)))

    # ------------------------------------------------------------------ end
    def finish(self) -> None:
        """Write the summary and footer and close the file (idempotent)."""
        if self._finished:
            return
        self._finished = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> McapLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()
