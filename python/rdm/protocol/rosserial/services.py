"""Service endpoints as the fork's rosserial sees them (fact sheet sec. 1.3 item 3).

A device-side service server occupies one publisher slot (the response, announced on
endpoint 2) and one subscriber slot (the request, endpoint 3). Both TopicInfo records carry the
*service* type as ``message_type`` and the md5 of the Response or Request message.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rdm.protocol.rosserial.registry import ServiceType

ServiceHandler = Callable[[Any], Any]


class ServiceError(RuntimeError):
    """A service call that cannot be made (unknown, not ready, or a call already pending)."""


@dataclass
class DeviceServiceServer:
    """Client side: a service the device serves; ``handler(request) -> response``."""

    name: str
    type: ServiceType
    handler: ServiceHandler
    request_id: int
    response_id: int


@dataclass
class PendingCall:
    """Server side: a request sent to the device and not yet answered."""

    call_id: int
    deadline: float


@dataclass
class RemoteService:
    """Server side: a device service as learned from its two TopicInfo records."""

    name: str
    type: ServiceType
    request_id: int | None = None
    response_id: int | None = None
    pending: PendingCall | None = field(default=None)

    @property
    def ready(self) -> bool:
        return self.request_id is not None and self.response_id is not None
