"""The device (Spinal) side of rosserial as a sans-IO state machine.

Mirrors ``NodeHandle::spinOnce``/``publish``/``negotiateTopics`` of the rosserial client with the
JSK settings (fact sheet sec. 1.2, 1.3, 1.5): call :meth:`ClientSession.spin` with the received
bytes and the MCU millisecond tick; read what to send with :meth:`take_output`.

* topic request (id 0) -> time request, TopicInfo per publisher (buffer 1024) then per
  subscriber (buffer 512), configured;
* time request every 2.5 s while configured; 11 s without a time answer -> not configured;
* user topics (id >= 100) are not sent until configured; frames over 1024 bytes are dropped
  with a logged error; frames longer than the 512-byte input buffer are rejected;
* a frame must complete within 20 ms of its 0xFF; a wrong version byte while unconfigured
  triggers a time request; TX_STOP (id 11) drops the configuration;
* TX goes through a ring of 128 chunks of 64 bytes: a frame that does not fit is dropped.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.codec import DecodeError, MessageCodec, RosTime
from rdm.protocol.rosserial.events import (
    Configured,
    DroppedMessage,
    FrameRejected,
    ServiceHandled,
    SessionEvent,
    SyncLost,
    TimeSynced,
    message_received,
)
from rdm.protocol.rosserial.framing import (
    BadFrame,
    Frame,
    FrameParser,
    _new_frame,
    encode_frame,
)
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_msgs_dir, spinal_registry
from rdm.protocol.rosserial.services import DeviceServiceServer, ServiceHandler
from rdm.protocol.rosserial.timesync import ClientClock

_MASK = 0xFFFFFFFF  # MCU ticks are uint32
_FOREVER = 2**62  # an idle window without end (unconfigured: spin(b"") never acts)


class SlotError(ValueError):
    """No free publisher/subscriber slot, or a slot layout that does not fit."""


@dataclass
class ClientEndpoint:
    """One publisher or subscriber slot of the device."""

    topic_id: int
    name: str
    type: str  # message type, or the service type for service halves
    md5: str
    codec: MessageCodec
    endpoint: C.Endpoint
    service: DeviceServiceServer | None = None


class ClientSession:
    """Spinal-side rosserial node handle (``NodeHandleStm_<50, 50, 512, 1024>``)."""

    def __init__(
        self,
        registry: TypeRegistry | None = None,
        *,
        max_subscribers: int = C.MAX_SUBSCRIBERS,
        max_publishers: int = C.MAX_PUBLISHERS,
        input_size: int = C.INPUT_SIZE,
        output_size: int = C.OUTPUT_SIZE,
        frame_timeout_ms: int = C.SERIAL_MSG_TIMEOUT_MS,
        tx_chunks: int = C.TX_CHUNKS,
        tx_chunk_bytes: int = C.TX_CHUNK_BYTES,
        rescan: bool = True,
    ) -> None:
        self.registry = registry or spinal_registry()
        self.max_subscribers = max_subscribers
        self.max_publishers = max_publishers
        self.input_size = input_size
        self.output_size = output_size
        self.parser = FrameParser(input_size, frame_timeout_ms, rescan=rescan)
        self.publishers: list[ClientEndpoint] = []
        self.subscribers: list[ClientEndpoint] = []
        self.configured = False
        self.clock = ClientClock()
        self.counts: Counter[str] = Counter()
        self._last_sync_time = 0
        self._last_sync_receive_time = 0
        self._tx_chunks = tx_chunks
        self._tx_chunk_bytes = tx_chunk_bytes
        self._tx: list[bytes] = []  # frames waiting in the TX ring
        #: The frames :meth:`take_output` will return (the same list for the session's life;
        #: read it, never change it): empty means ``take_output()`` returns ``b""``.
        self.pending_frames = self._tx
        self._tx_used = 0  # chunks in use
        self._time = self.registry.msg("std_msgs/Time")
        self._topic_info = self.registry.msg("rosserial_msgs/TopicInfo")
        self._log = self.registry.msg("rosserial_msgs/Log")
        self._publisher_cache: dict[str, ClientEndpoint] = {}  # name -> first plain slot
        self._cached_slots = 0  # len(publishers) when the cache was filled
        #: ``f(items) -> n``: takes the leading run of good user frames it applies itself
        #: (the Spinal mirror's steady commands, :meth:`SpinalMirror._apply_command_run`);
        #: only before any other event of a spin, so that nothing changes order.
        self.command_run: Callable[[list], int] | None = None

    # -- slot set-up (advertise / subscribe / advertiseService) ---------------------------
    def _new_pub(self, name: str, type_: str, md5: str, codec: MessageCodec, ep: C.Endpoint):
        if len(self.publishers) >= self.max_publishers:
            raise SlotError(f"no free publisher slot for {name!r} (max {self.max_publishers})")
        topic_id = C.FIRST_USER_TOPIC_ID + self.max_subscribers + len(self.publishers)
        slot = ClientEndpoint(topic_id, name, type_, md5, codec, ep)
        self.publishers.append(slot)
        return slot

    def _new_sub(self, name: str, type_: str, md5: str, codec: MessageCodec, ep: C.Endpoint):
        if len(self.subscribers) >= self.max_subscribers:
            raise SlotError(f"no free subscriber slot for {name!r} (max {self.max_subscribers})")
        slot = ClientEndpoint(
            C.FIRST_USER_TOPIC_ID + len(self.subscribers), name, type_, md5, codec, ep
        )
        self.subscribers.append(slot)
        return slot

    def advertise(self, name: str, msg_type: str) -> int:
        """Add a publisher (device -> PC); returns its topic id (150 + slot)."""
        codec = self.registry.msg(msg_type)
        slot = self._new_pub(
            name, msg_type, self.registry.md5(msg_type), codec, C.Endpoint.PUBLISHER
        )
        return slot.topic_id

    def subscribe(self, name: str, msg_type: str) -> int:
        """Add a subscriber (PC -> device); returns its topic id (100 + slot)."""
        codec = self.registry.msg(msg_type)
        slot = self._new_sub(
            name, msg_type, self.registry.md5(msg_type), codec, C.Endpoint.SUBSCRIBER
        )
        return slot.topic_id

    def _bind_service(
        self, pub: ClientEndpoint, sub: ClientEndpoint, handler: ServiceHandler
    ) -> None:
        srv = self.registry.srv(pub.type)
        service = DeviceServiceServer(pub.name, srv, handler, sub.topic_id, pub.topic_id)
        pub.service = sub.service = service

    @classmethod
    def from_layout(
        cls,
        layout: dict[str, Any] | str | Path | None = None,
        handlers: dict[str, ServiceHandler] | None = None,
        registry: TypeRegistry | None = None,
    ) -> ClientSession:
        """A session with the slots of a layout file (default: Spinal on stm32H7_v2, sec. 1.7).

        Services without a handler in ``handlers`` answer with a default-constructed response.
        """
        if layout is None:
            layout = spinal_msgs_dir() / "layout_stm32H7_v2.json"
        if not isinstance(layout, dict):
            layout = json.loads(Path(layout).read_text())
        session = cls(
            registry,
            max_subscribers=layout.get("max_subscribers", C.MAX_SUBSCRIBERS),
            max_publishers=layout.get("max_publishers", C.MAX_PUBLISHERS),
            input_size=layout.get("input_size", C.INPUT_SIZE),
            output_size=layout.get("output_size", C.OUTPUT_SIZE),
        )
        handlers = handlers or {}
        reg = session.registry
        halves: dict[str, ClientEndpoint] = {}
        for row in sorted(layout["publishers"], key=lambda r: r["id"]):
            if row["id"] != session.next_publisher_id:
                raise SlotError(f"publisher {row['name']!r}: id {row['id']} is not the next slot")
            if row["kind"] == "service_response":
                srv = reg.srv(row["type"])
                ep = C.Endpoint.SERVICE_RESPONSE
                halves[row["name"]] = session._new_pub(
                    row["name"], row["type"], srv.response_md5, srv.response, ep
                )
            else:
                session.advertise(row["name"], row["type"])
        for row in sorted(layout["subscribers"], key=lambda r: r["id"]):
            if row["id"] != session.next_subscriber_id:
                raise SlotError(f"subscriber {row['name']!r}: id {row['id']} is not the next slot")
            if row["kind"] == "service_request":
                pub = halves.pop(row["name"], None)
                if pub is None:
                    raise SlotError(f"service {row['name']!r} has no response slot")
                srv = reg.srv(row["type"])
                sub = session._new_sub(
                    row["name"],
                    row["type"],
                    srv.request_md5,
                    srv.request,
                    C.Endpoint.SERVICE_REQUEST,
                )
                handler = handlers.get(row["name"]) or (lambda _req, s=srv: s.response.new())
                session._bind_service(pub, sub, handler)
            else:
                session.subscribe(row["name"], row["type"])
        if halves:
            raise SlotError(f"services without a request slot: {sorted(halves)}")
        return session

    @property
    def next_publisher_id(self) -> int:
        return C.FIRST_USER_TOPIC_ID + self.max_subscribers + len(self.publishers)

    @property
    def next_subscriber_id(self) -> int:
        return C.FIRST_USER_TOPIC_ID + len(self.subscribers)

    def publisher(self, name: str) -> ClientEndpoint:
        """The plain publisher slot of topic ``name``."""
        slot = self._publisher_cache.get(name)
        if slot is not None and slot.service is None and self._cached_slots == len(self.publishers):
            return slot
        for p in self.publishers:
            if p.name == name and p.service is None:
                if self._cached_slots != len(self.publishers):
                    self._publisher_cache.clear()  # slots added or removed: look up afresh
                    self._cached_slots = len(self.publishers)
                self._publisher_cache[name] = p
                return p
        raise KeyError(f"no publisher {name!r}")

    # -- sending --------------------------------------------------------------------------
    def _send(self, topic_id: int, payload: bytes) -> int:
        return self.send_frame(topic_id, encode_frame(topic_id, payload))

    def send_frame(self, topic_id: int, frame: bytes) -> int:
        """:meth:`_send` of a frame built elsewhere: ``frame`` must be
        ``encode_frame(topic_id, payload)`` (e.g. ``rdm._rdm.spinal_imu_frame``). The same
        checks, TX ring, counters and return value as ``_send(topic_id, payload)``."""
        if topic_id >= C.FIRST_USER_TOPIC_ID and not self.configured:
            self.counts["tx_not_configured"] += 1
            return 0
        n = len(frame)
        if n > self.output_size:
            self.counts["tx_too_large"] += 1
            self.log(C.LogLevel.ERROR, C.LOG_DROPPED_TOO_LARGE)
            return -1
        chunks = -(-n // self._tx_chunk_bytes)
        if self._tx_used + chunks > self._tx_chunks:
            self.counts["tx_ring_full"] += 1  # the firmware drops the frame silently
            return -1
        self._tx.append(frame)
        self._tx_used += chunks
        self.counts["tx_frames"] += 1
        return n

    def send_payload(self, topic_id: int, payload: bytes) -> int:
        """Queue ``payload`` (an encoded message) on ``topic_id``: what :meth:`publish`
        does after encoding (for callers that pack a payload themselves)."""
        return self._send(topic_id, payload)

    def publish(self, name: str, msg: Any) -> int:
        """Publish on a plain topic; returns frame bytes queued, 0 if not configured, -1 if
        dropped (too large, TX ring full)."""
        slot = self._publisher_cache.get(name)  # publisher(name), inlined for the hit
        if slot is None or slot.service is not None or self._cached_slots != len(self.publishers):
            slot = self.publisher(name)
        return self._send(slot.topic_id, slot.codec.encode(msg))

    def log(self, level: int, text: str) -> int:
        """Send a ``rosserial_msgs/Log`` line on topic 7 (sent even when not configured)."""
        return self._send(
            C.TopicId.LOG, self._log.encode(self._log.new(level=int(level), msg=text))
        )

    def take_output(self) -> bytes:
        """Drain the TX ring: the bytes to write to the wire, frames back to back."""
        if not self._tx:
            return b""  # most MCU milliseconds send nothing (the ring is empty, _tx_used 0)
        out = b"".join(self._tx)
        self._tx.clear()
        self._tx_used = 0
        return out

    def now(self, now_ms: int) -> RosTime:
        """ROS time at MCU tick ``now_ms`` (zero-based until the first time answer)."""
        return self.clock.now(now_ms)

    def _request_sync_time(self, now_ms: int) -> None:
        self._send(C.TopicId.TIME, self._time.encode(self._time.new()))
        self.clock.request_sent(now_ms)

    def _negotiate_topics(self) -> None:
        for group, size in (
            (self.publishers, self.output_size),
            (self.subscribers, self.input_size),
        ):
            for ep in group:
                info = self._topic_info.new(
                    topic_id=ep.topic_id,
                    topic_name=ep.name,
                    message_type=ep.type,
                    md5sum=ep.md5,
                    buffer_size=size,
                )
                self._send(int(ep.endpoint), self._topic_info.encode(info))
        self.configured = True

    # -- receiving --------------------------------------------------------------------------
    def spin(self, data: bytes, now_ms: int) -> list[SessionEvent]:
        """One ``spinOnce``: bytes received since the last call, at MCU tick ``now_ms``."""
        events: list[SessionEvent] = []
        # tick_diff inlined (uint32 difference): this runs every MCU millisecond
        if self.configured and (now_ms - self._last_sync_receive_time) & _MASK > C.SYNC_LOSS_MS:
            self.configured = False
            self.counts["sync_lost"] += 1
            events.append(SyncLost("no time answer for 11 s"))
        parser = self.parser
        if not data and parser._started is None and not parser._buf:
            pass  # idle parser, no bytes: feed would return no event and change nothing
        else:
            events = self._receive(data, now_ms, events)
        if self.configured and (now_ms - self._last_sync_time) & _MASK > C.TIME_REQUEST_INTERVAL_MS:
            self._request_sync_time(now_ms)
            self._last_sync_time = now_ms
        return events

    def idle_window(self) -> tuple[int, int]:
        """``(lo, hi)``: for every int ``lo <= now_ms < hi``, ``spin(b"", now_ms)`` returns no
        event and changes nothing, until the next :meth:`spin` (only ``spin`` changes what
        this depends on). Empty (``lo == hi``) while the parser holds part of a frame (its
        timeout may fire). A caller that reads no byte may skip ``spin`` inside the window."""
        parser = self.parser
        if parser._started is not None or parser._buf:
            return (0, 0)
        if not self.configured:
            return (-_FOREVER, _FOREVER)
        # both uint32 tick checks of spin stay false while 0 <= now - last <= limit
        receive, sync = self._last_sync_receive_time, self._last_sync_time
        lo = max(receive, sync)
        hi = min(receive + C.SYNC_LOSS_MS, sync + C.TIME_REQUEST_INTERVAL_MS) + 1
        return (lo, hi) if lo < hi else (0, 0)

    def _receive(self, data: bytes, now_ms: int, events: list[SessionEvent]) -> list[SessionEvent]:
        # good frames come as (topic_id, payload, offset): no Frame object for user topics
        items = self.parser._feed(data, now_ms, True)
        run = self.command_run
        if run is not None and items and not events:
            # the leading frames it takes are done (in order, before any event); the rest
            # below, as always
            taken = run(items)
            if taken:
                items = items[taken:]
        for item in items:
            if item.__class__ is tuple:
                if item[0] >= C.FIRST_USER_TOPIC_ID:
                    events.extend(self._dispatch_user(*item))
                else:
                    events.extend(self._dispatch(_new_frame(*item), now_ms))
            elif isinstance(item, BadFrame):
                events.append(FrameRejected(item))
                if item.reason == "version" and not self.configured:
                    self._request_sync_time(now_ms)
        return events

    def _dispatch(self, frame: Frame, now_ms: int) -> list[SessionEvent]:
        tid = frame.topic_id
        if tid >= C.FIRST_USER_TOPIC_ID:  # none of the reserved ids below: a user topic
            return self._dispatch_user(tid, frame.payload, frame.offset)
        if tid == C.TopicId.PUBLISHER:  # the server's topic request
            self._request_sync_time(now_ms)
            self._negotiate_topics()
            self._last_sync_time = now_ms
            self._last_sync_receive_time = now_ms
            return [Configured()]
        if tid == C.TopicId.TIME:
            try:
                answer = self._time.decode(frame.payload).data
            except DecodeError as exc:
                return self._drop(frame, f"bad time payload: {exc}")
            rtt = self.clock.answer_received(answer, now_ms)
            self._last_sync_receive_time = now_ms
            return [TimeSynced(self.clock.now(now_ms), rtt)]
        if tid == C.TopicId.TX_STOP:
            self.configured = False
            return [SyncLost("TX_STOP from server")]
        return self._dispatch_user(tid, frame.payload, frame.offset)

    def _dispatch_user(self, tid: int, payload: bytes, offset: int) -> list[SessionEvent]:
        index = tid - C.FIRST_USER_TOPIC_ID
        if not 0 <= index < len(self.subscribers):
            return self._drop_at(tid, offset, "unknown topic id")
        slot = self.subscribers[index]
        try:
            msg = slot.codec.decode(payload)
        except DecodeError as exc:
            return self._drop_at(
                tid, offset, f"payload does not decode as {slot.codec.full_name}: {exc}"
            )
        if slot.service is not None:
            try:
                response = slot.service.handler(msg)
                payload = slot.service.type.response.encode(response)
            except Exception as exc:  # a faulty handler must not stop the link
                return self._drop_at(
                    tid, offset, f"service handler of {slot.name!r} failed: {exc!r}"
                )
            self._send(slot.service.response_id, payload)
            return [ServiceHandled(slot.name, msg, response)]
        return [message_received(slot.name, slot.type, tid, msg)]

    def _drop(self, frame: Frame, reason: str) -> list[SessionEvent]:
        return self._drop_at(frame.topic_id, frame.offset, reason)

    def _drop_at(self, topic_id: int, offset: int, reason: str) -> list[SessionEvent]:
        self.counts["rx_dropped"] += 1
        return [DroppedMessage(topic_id, reason, offset)]
