"""The PC (onboard computer) side of rosserial as a sans-IO state machine.

Mirrors the fork's ``rosserial_server`` session (fact sheet sec. 1.3): :meth:`ServerSession.start`
queues the topic request and arms a 1 s sync timer; each TopicInfo creates an endpoint and
extends the timer to 5 s; each time request is answered with the current ROS time and extends
it too; on expiry the session reports "Sync with device lost", forgets every endpoint and, like
the serial session re-opening the port, starts over after 2 s.

Unlike the real server (which only warns about a publisher whose md5 differs), this mirror
**refuses** any endpoint whose type is unknown or whose md5 differs from our ``.msg`` files:
frames on a refused id are counted and dropped, never decoded with a wrong layout.

Time is passed explicitly in seconds (``now``); the ROS time sent to the device is
``time_source(now)`` (default: ``now`` itself).
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.codec import DecodeError, MessageCodec, RosTime
from rdm.protocol.rosserial.events import (
    DroppedMessage,
    FrameRejected,
    LogReceived,
    ServiceReady,
    ServiceResponse,
    ServiceTimeout,
    SessionEvent,
    SyncLost,
    TopicRefused,
    TopicRegistered,
    message_received,
)
from rdm.protocol.rosserial.framing import (
    BadFrame,
    Frame,
    FrameParser,
    _new_frame,
    encode_frame,
)
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry
from rdm.protocol.rosserial.services import PendingCall, RemoteService, ServiceError

_TIME_ID = int(C.TopicId.TIME)  # plain ints: compared for every received frame
_LOG_ID = int(C.TopicId.LOG)


class TopicNotNegotiated(KeyError):
    """Publishing on a topic the device has not subscribed to (yet)."""

    def __str__(self) -> str:
        return f"the device has not announced a subscriber for topic {self.args[0]!r}"


class PayloadTooLarge(ValueError):
    """A message larger than the buffer the device announced for its topic."""


@dataclass
class RemoteTopic:
    """An endpoint the device announced and we accepted."""

    topic_id: int
    name: str
    type: str
    codec: MessageCodec
    buffer_size: int


def _default_time_source(now: float) -> RosTime:
    return RosTime.from_ns(max(0, round(now * 1e9)))


class ServerSession:
    """PC-side rosserial session for one device link."""

    def __init__(
        self,
        registry: TypeRegistry | None = None,
        *,
        time_source: Callable[[float], RosTime] = _default_time_source,
        max_payload: int = C.SERVER_BUFFER_MAX - 1,
        frame_timeout: float | None = None,
        attempt_interval: float = C.SERVER_ATTEMPT_INTERVAL_S,
        timeout_interval: float = C.SERVER_TIMEOUT_INTERVAL_S,
        reopen_interval: float | None = C.SERVER_REOPEN_INTERVAL_S,
        service_timeout: float = C.SERVICE_CALL_TIMEOUT_S,
    ) -> None:
        self.registry = registry or spinal_registry()
        self.time_source = time_source
        self.parser = FrameParser(max_payload, frame_timeout)
        self.attempt_interval = attempt_interval
        self.timeout_interval = timeout_interval
        self.reopen_interval = reopen_interval
        self.service_timeout = service_timeout
        self.counts: Counter[str] = Counter()
        self.active = False
        self.inbound: dict[int, RemoteTopic] = {}  # device publishers by topic id
        self.outbound: dict[str, RemoteTopic] = {}  # device subscribers by name
        self.services: dict[str, RemoteService] = {}
        self._sync_deadline = 0.0
        self._reopen_at: float | None = None
        self._tx: list[bytes] = []
        #: Deferred topics: name -> (type, decodes(payload) -> bool, handler(payload)). A good
        #: frame on such a topic (that type, a payload ``decodes`` accepts, i.e. exactly the
        #: payloads the codec decodes) is counted as received and returned from :meth:`feed` as
        #: a ``(handler, payload)`` tuple in the place of its ``MessageReceived``: the caller
        #: decodes what it reads. Empty (the default): every message is decoded.
        self.deferred: dict[str, tuple[str, Callable[[bytes], bool], Callable[[bytes], Any]]] = {}
        self._call_ids = itertools.count(1)
        self._time = self.registry.msg("std_msgs/Time")
        self._topic_info = self.registry.msg("rosserial_msgs/TopicInfo")
        self._log = self.registry.msg("rosserial_msgs/Log")

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Open the session: send the topic request (topic 0, empty) and arm the 1 s timer."""
        self.active = True
        self._reopen_at = None
        self.parser.reset()
        self.request_topics(now)

    def request_topics(self, now: float) -> None:
        """(Re-)send the topic request; the device answers with all its TopicInfo records."""
        self._tx.append(encode_frame(C.TopicId.PUBLISHER, b""))
        self._sync_deadline = now + self.attempt_interval

    def stop(self) -> None:
        """Ask the device to stop publishing (TX_STOP, topic 11) and close the session."""
        self._tx.append(encode_frame(C.TopicId.TX_STOP, b""))
        self._close()

    def _close(self) -> None:
        self.active = False
        self.inbound.clear()
        self.outbound.clear()
        self.services.clear()

    def take_output(self) -> bytes:
        """Bytes to write to the device."""
        if not self._tx:
            return b""
        out = b"".join(self._tx)
        self._tx.clear()
        return out

    # -- sending --------------------------------------------------------------------------------
    def publish(self, topic: str, msg: Any) -> int:
        """Send ``msg`` on a topic the device subscribes to; returns the frame size."""
        try:
            remote = self.outbound[topic]
        except KeyError:
            raise TopicNotNegotiated(topic) from None
        return self._send_payload(topic, remote, remote.codec.encode(msg))

    def publish_payload(self, topic: str, payload: bytes) -> int:
        """:meth:`publish` of a message the caller has already serialized with the topic's
        codec (``outbound[topic].codec.encode(msg)`` bytes): same checks, counters, frame."""
        try:
            remote = self.outbound[topic]
        except KeyError:
            raise TopicNotNegotiated(topic) from None
        return self._send_payload(topic, remote, payload)

    def try_publish_payload(self, topic: str, payload: bytes) -> bool:
        """:meth:`publish_payload` without its refusals: the same frame queued, True; False,
        with nothing queued or counted, for a topic not negotiated or a payload over the
        device's buffer (the caller then calls :meth:`publish_payload`, which counts and
        raises as always)."""
        remote = self.outbound.get(topic)
        if remote is None or len(payload) > remote.buffer_size:
            return False
        self._tx.append(encode_frame(remote.topic_id, payload))
        return True

    def _send_payload(self, topic: str, remote: Any, payload: bytes) -> int:
        """Frame a serialized message for the device (refused past its buffer)."""
        if len(payload) > remote.buffer_size:
            self.counts["tx_too_large"] += 1
            raise PayloadTooLarge(
                f"{topic}: {len(payload)}-byte payload exceeds the device buffer of "
                f"{remote.buffer_size} bytes"
            )
        frame = encode_frame(remote.topic_id, payload)
        self._tx.append(frame)
        return len(frame)

    def call_service(self, name: str, request: Any, now: float) -> int:
        """Send a request to a device service; the answer comes as :class:`ServiceResponse`
        (or :class:`ServiceTimeout` after ``service_timeout``). Returns the call id."""
        service = self.services.get(name)
        if service is None or not service.ready:
            raise ServiceError(f"service {name!r} is not (yet) offered by the device")
        if service.pending is not None:
            raise ServiceError(
                f"service {name!r} already has call {service.pending.call_id} pending"
            )
        assert service.request_id is not None
        payload = service.type.request.encode(request)
        self._tx.append(encode_frame(service.request_id, payload))
        call = PendingCall(next(self._call_ids), now + self.service_timeout)
        service.pending = call
        return call.call_id

    # -- receiving ------------------------------------------------------------------------------
    def feed(self, data: bytes, now: float) -> list[SessionEvent]:
        """Process bytes received at ``now``, then the timers. Messages on :attr:`deferred`
        topics come as ``(handler, payload)`` tuples (see there)."""
        events: list[SessionEvent] = []
        if not self.active:
            self.counts["rx_while_closed"] += len(data)
        else:
            # good frames come as (topic_id, payload, offset): no Frame object for user topics
            inbound = self.inbound
            deferred = self.deferred
            for item in self.parser._feed(data, now, True):
                if item.__class__ is tuple:
                    tid = item[0]
                    # none of the reserved ids (0-3 setup, 7 log, 10 time): a device topic
                    remote = inbound.get(tid) if tid > _LOG_ID and tid != _TIME_ID else None
                    if remote is not None:
                        later = deferred.get(remote.name) if deferred else None
                        if later is not None and later[0] == remote.type and later[1](item[1]):
                            self.counts["rx_messages"] += 1  # as _deliver
                            events.append((later[2], item[1]))  # type: ignore[arg-type]
                            continue
                        events.extend(self._deliver(tid, item[1], item[2], remote))
                    else:
                        events.extend(self._dispatch(_new_frame(*item), now))
                elif isinstance(item, BadFrame):
                    events.append(FrameRejected(item))
        events.extend(self.poll(now))
        return events

    def poll(self, now: float) -> list[SessionEvent]:
        """Run the timers: sync loss, re-open, service call timeouts."""
        events: list[SessionEvent] = []
        if self.active:
            for service in self.services.values():
                if service.pending is not None and now > service.pending.deadline:
                    events.append(ServiceTimeout(service.name, service.pending.call_id))
                    self.counts["service_timeout"] += 1
                    service.pending = None
            if now > self._sync_deadline:
                self.counts["sync_lost"] += 1
                events.append(SyncLost("Sync with device lost"))
                self._close()
                if self.reopen_interval is not None:
                    self._reopen_at = now + self.reopen_interval
        elif self._reopen_at is not None and now >= self._reopen_at:
            self.start(now)
        return events

    def _dispatch(self, frame: Frame, now: float) -> list[SessionEvent]:
        tid = frame.topic_id
        if tid > _LOG_ID and tid != _TIME_ID:  # none of the reserved branches below applies
            remote = self.inbound.get(tid)
            if remote is not None:
                return self._deliver(tid, frame.payload, frame.offset, remote)
            return self._dispatch_rest(frame, tid)
        if tid in (0, 1, 2, 3):
            return self._setup(frame, now)
        if tid == _TIME_ID:
            self._tx.append(
                encode_frame(
                    C.TopicId.TIME, self._time.encode(self._time.new(data=self.time_source(now)))
                )
            )
            self._sync_deadline = now + self.timeout_interval
            self.counts["time_requests"] += 1
            return []
        if tid == _LOG_ID:
            try:
                log = self._log.decode(frame.payload)
            except DecodeError as exc:
                return self._drop(frame, f"bad log payload: {exc}")
            return [LogReceived(log.level, log.msg)]
        remote = self.inbound.get(tid)
        if remote is not None:
            return self._deliver(tid, frame.payload, frame.offset, remote)
        return self._dispatch_rest(frame, tid)

    def _deliver(
        self, tid: int, payload: bytes, offset: int, remote: RemoteTopic
    ) -> list[SessionEvent]:
        try:
            msg = remote.codec.decode(payload)
        except DecodeError as exc:
            self.counts["rx_dropped"] += 1  # as _drop
            reason = f"payload does not decode as {remote.type}: {exc}"
            return [DroppedMessage(tid, reason, offset)]
        self.counts["rx_messages"] += 1
        return [message_received(remote.name, remote.type, tid, msg)]

    def _dispatch_rest(self, frame: Frame, tid: int) -> list[SessionEvent]:
        """Service responses, then unknown topic ids."""
        for service in self.services.values():
            if service.response_id == tid:
                try:
                    response = service.type.response.decode(frame.payload)
                except DecodeError as exc:
                    return self._drop(frame, f"bad {service.type.full_name} response: {exc}")
                if service.pending is None:
                    return self._drop(frame, "service response without a pending call")
                call_id = service.pending.call_id
                service.pending = None
                return [ServiceResponse(service.name, call_id, response)]
        return self._drop(frame, "unknown topic id")

    def _setup(self, frame: Frame, now: float) -> list[SessionEvent]:
        try:
            info = self._topic_info.decode(frame.payload)
        except DecodeError as exc:
            return self._drop(frame, f"bad TopicInfo: {exc}")
        self._sync_deadline = now + self.timeout_interval
        endpoint = C.Endpoint(frame.topic_id)
        if endpoint in (C.Endpoint.PUBLISHER, C.Endpoint.SUBSCRIBER):
            expected = (
                self.registry.md5(info.message_type)
                if self.registry.has_msg(info.message_type)
                else None
            )
        else:
            srv = (
                self.registry.srv(info.message_type)
                if self.registry.has_srv(info.message_type)
                else None
            )
            expected = (
                None
                if srv is None
                else (
                    srv.response_md5 if endpoint == C.Endpoint.SERVICE_RESPONSE else srv.request_md5
                )
            )
        if expected is None or expected != info.md5sum:
            reason = "unknown type" if expected is None else "md5 differs from our definition"
            self.counts["topic_refused"] += 1
            return [
                TopicRefused(
                    info.topic_id, info.topic_name, info.message_type, info.md5sum, expected, reason
                )
            ]
        events: list[SessionEvent] = [
            TopicRegistered(
                info.topic_id,
                info.topic_name,
                info.message_type,
                info.md5sum,
                int(endpoint),
                info.buffer_size,
            )
        ]
        if endpoint == C.Endpoint.PUBLISHER:
            codec = self.registry.msg(info.message_type)
            self.inbound[info.topic_id] = RemoteTopic(
                info.topic_id, info.topic_name, info.message_type, codec, info.buffer_size
            )
        elif endpoint == C.Endpoint.SUBSCRIBER:
            codec = self.registry.msg(info.message_type)
            self.outbound[info.topic_name] = RemoteTopic(
                info.topic_id, info.topic_name, info.message_type, codec, info.buffer_size
            )
        else:
            service = self.services.get(info.topic_name)
            if service is None or service.type.full_name != info.message_type:
                service = RemoteService(info.topic_name, self.registry.srv(info.message_type))
                self.services[info.topic_name] = service
            was_ready = service.ready
            if endpoint == C.Endpoint.SERVICE_RESPONSE:
                service.response_id = info.topic_id
            else:
                service.request_id = info.topic_id
            if service.ready and not was_ready:
                events.append(ServiceReady(service.name, info.message_type))
        return events

    def _drop(self, frame: Frame, reason: str) -> list[SessionEvent]:
        self.counts["rx_dropped"] += 1
        return [DroppedMessage(frame.topic_id, reason, frame.offset)]
