"""rosserial v2, both ends: the PC's server session fed the bytes a device sends, and the
device's client session (the Spinal mirror) fed the bytes a PC sends.

Each input is a byte stream, read in pieces (:func:`base.chunks`) with the clock advancing
per piece. Checks beyond "no crash":

* every frame the session's parser accepts is checked in the input itself with the fact
  sheet's acceptance rule (:func:`base.rosserial_frame_ok`) and rebuilt byte for byte by
  the harness's own encoder (:func:`base.rosserial_frame`): no bad-checksum frame is ever
  accepted, and the framing is canonical;
* every payload accepted on a topic re-encodes with that topic's codec to the same bytes
  (bool fields, which read any non-zero byte as true, and float NaN patterns excepted:
  then the re-encoded bytes must decode to the same message);
* the rejected-frame events equal the parser's bad-frame counter;
* everything the session writes back is a sequence of valid frames.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from functools import cache
from pathlib import Path
from typing import Any

from fuzz_targets.base import (
    BadFrameAccepted,
    NotCanonical,
    Target,
    WrongCount,
    chunks,
    rosserial_frame,
    rosserial_frame_ok,
    same_value,
)
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import DecodeError, MessageCodec
from rdm.protocol.rosserial.events import FrameRejected
from rdm.protocol.rosserial.registry import spinal_msgs_dir, spinal_registry
from rdm.protocol.rosserial.server import ServerSession

GOLDEN = spinal_msgs_dir() / "golden_frames.json"


@cache
def _golden() -> dict[str, Any]:
    return json.loads(Path(GOLDEN).read_text())


@cache
def _layout() -> dict[str, Any]:
    return json.loads((spinal_msgs_dir() / "layout_stm32H7_v2.json").read_text())


def _has_bool(codec: MessageCodec) -> bool:
    registry = spinal_registry()
    for f in codec.spec.fields:
        if f.base_type == "bool":
            return True
        if registry.has_msg(f.base_type) and _has_bool(registry.msg(f.base_type)):
            return True
    return False


def _has_nan(value: Any) -> bool:
    if isinstance(value, float):
        return value != value
    if isinstance(value, (list, tuple)):
        return any(_has_nan(v) for v in value)
    return any(_has_nan(getattr(value, f)) for f in getattr(value, "__dataclass_fields__", ()))


def check_payload(codec: MessageCodec, payload: bytes, where: str) -> None:
    """``payload`` decodes with ``codec`` (else nothing to check) and re-encodes to itself."""
    try:
        msg = codec.decode(payload)
    except DecodeError:
        return
    again = codec.encode(msg)
    if again == payload:
        return
    if not (_has_bool(codec) or _has_nan(msg)) or not same_value(codec.decode(again), msg):
        raise NotCanonical(f"{where}: {codec.full_name} payload {payload.hex()} re-encodes as "
                           f"{again.hex()}")  # fmt: skip


def check_output(out: bytes, who: str) -> None:
    """``out`` is whole valid frames back to back."""
    pos = 0
    while pos < len(out):
        n = out[pos + 2] + 256 * out[pos + 3] if pos + 4 <= len(out) else -8
        frame = out[pos : pos + n + 8]
        if not rosserial_frame_ok(frame):
            raise BadFrameAccepted(f"{who} wrote a bad frame at {pos}: {frame[:16].hex()}")
        pos += n + 8


def _spy(session: Any) -> list[tuple[int, bytes, int]]:
    """Record every good frame the session's parser hands the session."""
    parser = session.parser
    feed = parser._feed
    accepted: list[tuple[int, bytes, int]] = []

    def spy(data: bytes, now: float, raw: bool) -> list[Any]:
        items = feed(data, now, raw)
        for item in items:
            if item.__class__ is tuple:
                accepted.append(item)
            elif hasattr(item, "topic_id") and hasattr(item, "payload"):
                accepted.append((item.topic_id, item.payload, item.offset))
        return items

    parser._feed = spy
    return accepted


def _check_accepted(data: bytes, accepted: list[tuple[int, bytes, int]], codecs: Any) -> None:
    for topic_id, payload, offset in accepted:
        raw = data[offset : offset + len(payload) + 8]
        if not rosserial_frame_ok(raw):
            raise BadFrameAccepted(f"frame at {offset} accepted: {raw[:24].hex()}")
        if raw != rosserial_frame(topic_id, payload):
            raise NotCanonical(f"frame at {offset} is not topic {topic_id} + its payload")
        codec = codecs(topic_id)
        if codec is not None:
            check_payload(codec, payload, f"topic {topic_id} at {offset}")


def check_server(data: bytes) -> None:
    """The PC's session reading ``data`` from a device."""
    server = ServerSession()
    server.start(0.0)
    check_output(server.take_output(), "server")
    accepted = _spy(server)
    rejected = 0
    now = 0.0
    for piece in chunks(data):
        for event in server.feed(piece, now):
            rejected += isinstance(event, FrameRejected)
        check_output(server.take_output(), "server")
        now += 1e-4  # ASSUMPTION: 0.1 ms per read keeps a 4 KiB input inside the 1 s sync timer
    if rejected != server.parser.bad_frames:
        raise WrongCount(
            f"{rejected} FrameRejected events, parser counts {server.parser.bad_frames}"
        )
    registry = server.registry
    info = registry.msg("rosserial_msgs/TopicInfo")

    def codec_of(topic_id: int) -> MessageCodec | None:
        if topic_id in (0, 1, 2, 3):
            return info
        remote = server.inbound.get(topic_id)
        return None if remote is None else remote.codec

    _check_accepted(data, accepted, codec_of)


def check_client(data: bytes) -> None:
    """The device's session (Spinal, stm32H7_v2 layout) reading ``data`` from a PC."""
    client = ClientSession.from_layout(_layout())
    accepted = _spy(client)
    rejected = 0
    for now_ms, piece in enumerate(chunks(data)):  # one read per MCU millisecond
        for event in client.spin(piece, now_ms):
            rejected += isinstance(event, FrameRejected)
        check_output(client.take_output(), "client")
    if rejected != client.parser.bad_frames:
        raise WrongCount(
            f"{rejected} FrameRejected events, parser counts {client.parser.bad_frames}"
        )
    time_codec = client.registry.msg("std_msgs/Time")

    def codec_of(topic_id: int) -> MessageCodec | None:
        if topic_id == 10:
            return time_codec
        index = topic_id - 100
        return client.subscribers[index].codec if 0 <= index < len(client.subscribers) else None

    _check_accepted(data, accepted, codec_of)


def _frames(direction: str) -> list[bytes]:
    return [bytes.fromhex(v["hex"]) for v in _golden()["topics"] if v["direction"] == direction]


def server_seeds() -> Iterable[bytes]:
    """What a device sends: the TopicInfo records of a topic then frames on it (each
    topic of the layout), logs, corrupted frames, the whole handshake reply."""
    golden = _golden()
    reply = [bytes.fromhex(f["hex"]) for f in golden["handshake"]["client_reply"]]
    infos = {}
    for f in golden["handshake"]["client_reply"]:
        if f["topic_id"] in (0, 1, 2, 3):
            infos.setdefault(f["fields"]["topic_id"], []).append(bytes.fromhex(f["hex"]))
    device = [v for v in golden["topics"] if v["direction"] == "spinal_to_pc"]
    for v in device:
        yield b"".join(infos.get(v["topic_id"], [])) + bytes.fromhex(v["hex"])
    first = b"".join(infos.get(device[0]["topic_id"], [])) + bytes.fromhex(device[0]["hex"])
    for v in golden["reserved"]:
        yield reply[0] + bytes.fromhex(v["hex"])
    for v in golden["bad_frames"]:
        yield bytes.fromhex(v["hex"]) + first
    for v in golden["fact_sheet_examples"]:
        yield bytes.fromhex(v["hex"].replace(" ", ""))
    yield b"".join(reply)


def client_seeds() -> Iterable[bytes]:
    """What a PC sends: the topic request, time answers, its topics, corrupted frames."""
    golden = _golden()
    request = bytes.fromhex(golden["handshake"]["server_request"])
    host = _frames("pc_to_spinal")
    time_answer = [bytes.fromhex(v["hex"]) for v in golden["reserved"] if v["topic_id"] == 10]
    yield request
    yield request + b"".join(time_answer) + b"".join(host)
    for frame in host:
        yield request + frame
    for v in golden["reserved"]:
        yield request + bytes.fromhex(v["hex"])
    for v in golden["bad_frames"]:
        yield request + bytes.fromhex(v["hex"]) + host[0]


TARGETS = [
    Target(
        "rosserial_server",
        check_server,
        server_seeds,
        about="rdm.protocol.rosserial.server.ServerSession.feed (PC side, device bytes)",
    ),
    Target(
        "rosserial_client",
        check_client,
        client_seeds,
        about="rdm.protocol.rosserial.client.ClientSession.spin (device side, PC bytes)",
    ),
]
