"""Events the session state machines return from ``feed``/``poll`` (sans-IO: no callbacks)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rdm.protocol.rosserial.codec import RosTime
from rdm.protocol.rosserial.framing import BadFrame


@dataclass(frozen=True)
class MessageReceived:
    """A user-topic message decoded from a good frame."""

    topic: str
    type: str
    topic_id: int
    message: Any


def message_received(topic: str, type_: str, topic_id: int, message: Any) -> MessageReceived:
    """``MessageReceived(...)`` without the frozen-dataclass ``__init__`` (one per message)."""
    event = object.__new__(MessageReceived)
    fields = event.__dict__
    fields["topic"] = topic
    fields["type"] = type_
    fields["topic_id"] = topic_id
    fields["message"] = message
    return event


@dataclass(frozen=True)
class TopicRegistered:
    """Server: a TopicInfo accepted (``endpoint`` is the :class:`Endpoint` it came on)."""

    topic_id: int
    topic: str
    type: str
    md5: str
    endpoint: int
    buffer_size: int


@dataclass(frozen=True)
class TopicRefused:
    """Server: a TopicInfo rejected (unknown type or md5 differing from our definition)."""

    topic_id: int
    topic: str
    type: str
    md5: str
    expected_md5: str | None
    reason: str


@dataclass(frozen=True)
class LogReceived:
    """Server: a ``rosserial_msgs/Log`` line from the device."""

    level: int
    text: str


@dataclass(frozen=True)
class TimeSynced:
    """Client: the clock was set from a time answer; ``round_trip_ms`` since the request."""

    time: RosTime
    round_trip_ms: int


@dataclass(frozen=True)
class Configured:
    """Client: topics negotiated, user topics flow. Server: first endpoint registered."""


@dataclass(frozen=True)
class SyncLost:
    """The peer went silent too long (client: 11 s without time; server: sync timeout)."""

    reason: str


@dataclass(frozen=True)
class ServiceReady:
    """Server: both halves of a device service are registered and the md5s agree."""

    service: str
    type: str


@dataclass(frozen=True)
class ServiceResponse:
    """Server: the device answered call ``call_id``."""

    service: str
    call_id: int
    response: Any


@dataclass(frozen=True)
class ServiceTimeout:
    """Server: no answer to call ``call_id`` within the timeout."""

    service: str
    call_id: int


@dataclass(frozen=True)
class ServiceHandled:
    """Client: a request was served and the response queued."""

    service: str
    request: Any
    response: Any


@dataclass(frozen=True)
class DroppedMessage:
    """A good frame that could not be delivered: unknown topic id, or payload not decodable."""

    topic_id: int
    reason: str
    offset: int


@dataclass(frozen=True)
class FrameRejected:
    """A bad frame from the parser (never delivered)."""

    bad: BadFrame


SessionEvent = (
    MessageReceived
    | TopicRegistered
    | TopicRefused
    | LogReceived
    | TimeSynced
    | Configured
    | SyncLost
    | ServiceReady
    | ServiceResponse
    | ServiceTimeout
    | ServiceHandled
    | DroppedMessage
    | FrameRejected
)
