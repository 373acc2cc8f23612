"""Decode a raw UART byte capture of the Spinal link into one record per frame.

Topic ids are learned from the TopicInfo records in the capture (both directions may be mixed:
ids 100+ are PC -> Spinal, 150+ Spinal -> PC). Ids seen before, or without, a handshake fall
back to a slot layout (default: Spinal on stm32H7_v2, sec. 1.7). A TopicInfo whose md5 differs
from our ``.msg`` definition is reported as an error and frames on its id are not decoded.

Bytes skipped while re-scanning a rejected frame are not reported again (they belong to that
frame); a valid frame found inside it is. Each record is a dict with ``offset`` (byte offset of
the frame), ``kind``, ``ok``, ``error`` and, for frames, ``topic_id``, ``topic``, ``type`` and
``fields``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.codec import DecodeError, MessageCodec, message_to_dict
from rdm.protocol.rosserial.framing import BadFrame, Frame, FrameParser, SkippedBytes
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_msgs_dir, spinal_registry

_RESERVED_KIND = {
    C.TopicId.LOG: ("log", "rosserial_msgs/Log"),
    C.TopicId.TIME: ("time", "std_msgs/Time"),
}


class _TopicTable:
    """topic id -> (name, type, codec) from a layout and from TopicInfo records."""

    def __init__(self, registry: TypeRegistry, layout: dict[str, Any] | None) -> None:
        self.registry = registry
        self.ids: dict[int, tuple[str, str, MessageCodec] | None] = {}
        self.learned: set[int] = set()
        if layout:
            for row in layout["subscribers"]:
                self._set(row["id"], row["name"], row["type"], row["kind"] == "service_request")
            for row in layout["publishers"]:
                self._set(row["id"], row["name"], row["type"], False)

    def _set(self, topic_id: int, name: str, type_: str, is_request: bool) -> None:
        if self.registry.has_srv(type_):
            srv = self.registry.srv(type_)
            codec = srv.request if is_request else srv.response
        else:
            codec = self.registry.msg(type_)
        self.ids[topic_id] = (name, type_, codec)

    def learn(self, endpoint: int, info: Any) -> str | None:
        """Record a TopicInfo; returns an error text if it is refused."""
        reg, type_ = self.registry, info.message_type
        if endpoint in (C.Endpoint.PUBLISHER, C.Endpoint.SUBSCRIBER):
            expected = reg.md5(type_) if reg.has_msg(type_) else None
        else:
            srv = reg.srv(type_) if reg.has_srv(type_) else None
            is_req = endpoint == C.Endpoint.SERVICE_REQUEST
            expected = None if srv is None else (srv.request_md5 if is_req else srv.response_md5)
        if expected is None:
            self.ids[info.topic_id] = None
            return f"unknown type {type_!r}"
        if expected != info.md5sum:
            self.ids[info.topic_id] = None
            return f"md5 {info.md5sum} differs from our {type_} ({expected})"
        self._set(info.topic_id, info.topic_name, type_, endpoint == C.Endpoint.SERVICE_REQUEST)
        self.learned.add(info.topic_id)
        return None


def load_layout(path: str | Path | None = None) -> dict[str, Any]:
    """A slot layout file (default: ``layout_stm32H7_v2.json``)."""
    path = Path(path) if path else spinal_msgs_dir() / "layout_stm32H7_v2.json"
    return json.loads(path.read_text())


def decode_uart(
    data: bytes | Iterable[bytes],
    registry: TypeRegistry | None = None,
    layout: dict[str, Any] | None = None,
    max_payload: int = C.OUTPUT_SIZE - C.FRAME_OVERHEAD,
    *,
    raw: bool = False,
) -> Iterator[dict[str, Any]]:
    """Yield one record per frame, bad frame or run of skipped bytes, in stream order.

    ``data`` is the capture, whole or as an iterable of byte chunks (any chunking gives the
    same records: a run of skipped bytes cut by a chunk boundary is one record), so a file
    read piece by piece is decoded in memory bounded by the chunk size. With ``raw``, a
    decoded frame's record also carries its payload bytes as ``raw`` (the message's ROS1
    serialisation)."""
    registry = registry or spinal_registry()
    table = _TopicTable(registry, layout)
    topic_info = registry.msg("rosserial_msgs/TopicInfo")
    parser = FrameParser(max_payload)
    chunks = (data,) if isinstance(data, bytes | bytearray | memoryview) else data
    covered = 0  # end of the last rejected frame: bytes skipped inside it belong to it
    skip_start, skip_len = 0, 0  # a run of skipped bytes not yet reported (it may continue)
    for chunk in chunks:
        for item in parser.feed(bytes(chunk)):
            if isinstance(item, SkippedBytes):
                start = max(item.offset, covered)
                length = item.offset + len(item.data) - start
                if length <= 0:
                    continue
                if skip_len and skip_start + skip_len == start:
                    skip_len += length
                else:
                    if skip_len:
                        yield _skipped_record(skip_start, skip_len)
                    skip_start, skip_len = start, length
                continue
            if skip_len:
                yield _skipped_record(skip_start, skip_len)
                skip_len = 0
            if isinstance(item, BadFrame):
                covered = max(covered, item.offset + len(item.data))
                yield {
                    "offset": item.offset,
                    "kind": "bad_frame",
                    "ok": False,
                    "error": item.reason,
                    "bytes": item.data.hex(),
                }
            elif isinstance(item, Frame):
                rec = _frame_record(item, table, topic_info)
                if raw and rec["ok"]:
                    rec["raw"] = item.payload
                yield rec
    if skip_len:
        yield _skipped_record(skip_start, skip_len)
    # a frame cut off at the end of the capture
    if parser.in_frame:
        offset, rest = parser.pending
        yield {
            "offset": offset,
            "kind": "bad_frame",
            "ok": False,
            "error": "truncated",
            "bytes": rest.hex(),
        }


def _skipped_record(start: int, length: int) -> dict[str, Any]:
    return {
        "offset": start,
        "kind": "skipped",
        "ok": False,
        "error": f"{length} bytes outside any frame",
        "length": length,
    }


def _frame_record(frame: Frame, table: _TopicTable, topic_info: MessageCodec) -> dict[str, Any]:
    tid = frame.topic_id
    rec: dict[str, Any] = {"offset": frame.offset, "kind": "message", "ok": True, "error": None}
    rec["topic_id"] = tid
    codec: MessageCodec | None = None
    if tid in (0, 1, 2, 3) and frame.payload:
        rec.update(kind="topic_info", topic=C.Endpoint(tid).name.lower(), type=topic_info.full_name)
        codec = topic_info
    elif tid == C.TopicId.PUBLISHER:
        rec.update(kind="topic_request", topic=None, type=None, fields={})
        return rec
    elif tid == C.TopicId.TX_STOP:
        rec.update(kind="tx_stop", topic=None, type=None, fields={})
        return rec
    elif tid in _RESERVED_KIND:
        kind, type_ = _RESERVED_KIND[tid]
        codec = table.registry.msg(type_)
        rec.update(kind=kind, topic=kind, type=type_)
    else:
        entry = table.ids.get(tid, "missing")
        if entry == "missing" or entry is None:
            why = "refused (md5 or type)" if entry is None else "unknown topic id"
            rec.update(ok=False, error=why, topic=None, type=None, payload=frame.payload.hex())
            return rec
        name, type_, codec = entry
        rec.update(topic=name, type=codec.full_name)
    try:
        msg = codec.decode(frame.payload)
    except DecodeError as exc:
        rec.update(ok=False, error=f"payload does not decode: {exc}", payload=frame.payload.hex())
        return rec
    rec["fields"] = message_to_dict(msg)
    if rec["kind"] == "topic_info":
        error = table.learn(tid, msg)
        if error:
            rec.update(ok=False, error=error)
    return rec
