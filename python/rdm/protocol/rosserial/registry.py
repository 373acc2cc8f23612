"""Message and service types loaded from a tree of ROS package folders (``pkg/msg/*.msg``,
``pkg/srv/*.srv``), each with its compiled codec and its ROS md5 sum.

The default tree is ``firmware_protocol/spinal/`` of the source checkout; the environment
variable ``RDM_SPINAL_MSGS`` points elsewhere (e.g. for an installed wheel).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from rdm.protocol.rosserial.codec import MessageCodec
from rdm.protocol.rosserial.md5 import msg_md5, srv_md5
from rdm.protocol.rosserial.msgdef import MsgSpec, SrvSpec, parse_msg, parse_srv


class UnknownTypeError(KeyError):
    """A message or service type that is not in the registry."""

    def __str__(self) -> str:
        return f"unknown ROS type {self.args[0]!r}"


@dataclass(frozen=True)
class ServiceType:
    """A service: its type name, md5, and the request/response message codecs."""

    full_name: str
    md5: str
    request: MessageCodec
    response: MessageCodec
    request_md5: str
    response_md5: str


class TypeRegistry:
    """All message/service definitions of a package tree, compiled on first use."""

    def __init__(self) -> None:
        self._msg_specs: dict[str, MsgSpec] = {}
        self._srv_specs: dict[str, SrvSpec] = {}
        self._codecs: dict[str, MessageCodec] = {}
        self._md5: dict[str, str] = {}

    @classmethod
    def from_directory(cls, root: str | os.PathLike[str]) -> TypeRegistry:
        """Load every ``<pkg>/msg/*.msg`` and ``<pkg>/srv/*.srv`` under ``root``."""
        reg = cls()
        root = Path(root)
        for path in sorted(root.glob("*/msg/*.msg")):
            reg.add_msg(f"{path.parts[-3]}/{path.stem}", path.read_text())
        for path in sorted(root.glob("*/srv/*.srv")):
            reg.add_srv(f"{path.parts[-3]}/{path.stem}", path.read_text())
        return reg

    def add_msg(self, full_name: str, text: str) -> None:
        """Register a message from its ``.msg`` text."""
        self._msg_specs[full_name] = parse_msg(full_name, text)

    def add_srv(self, full_name: str, text: str) -> None:
        """Register a service; its request/response become messages ``<name>Request`` etc."""
        spec = parse_srv(full_name, text)
        self._srv_specs[full_name] = spec
        self._msg_specs[spec.request.full_name] = spec.request
        self._msg_specs[spec.response.full_name] = spec.response

    @property
    def message_names(self) -> list[str]:
        """Every message type (including service request/response halves)."""
        return sorted(self._msg_specs)

    @property
    def service_names(self) -> list[str]:
        return sorted(self._srv_specs)

    def spec(self, full_name: str) -> MsgSpec:
        try:
            return self._msg_specs[full_name]
        except KeyError:
            raise UnknownTypeError(full_name) from None

    def has_msg(self, full_name: str) -> bool:
        return full_name in self._msg_specs

    def has_srv(self, full_name: str) -> bool:
        return full_name in self._srv_specs

    def msg(self, full_name: str) -> MessageCodec:
        """The compiled codec (with ``.cls``, ``.encode``, ``.decode``) of a message type."""
        codec = self._codecs.get(full_name)
        if codec is None:
            codec = MessageCodec(self.spec(full_name), self.msg)
            self._codecs[full_name] = codec
        return codec

    def md5(self, full_name: str) -> str:
        """ROS md5 sum of a message type."""
        return msg_md5(self.spec(full_name), self.spec, self._md5)

    def srv(self, full_name: str) -> ServiceType:
        """A service type with both halves compiled."""
        try:
            spec = self._srv_specs[full_name]
        except KeyError:
            raise UnknownTypeError(full_name) from None
        return ServiceType(
            full_name,
            srv_md5(spec, self.spec),
            self.msg(spec.request.full_name),
            self.msg(spec.response.full_name),
            self.md5(spec.request.full_name),
            self.md5(spec.response.full_name),
        )


def spinal_msgs_dir() -> Path:
    """Where the Spinal ``.msg``/``.srv`` tree lives (env ``RDM_SPINAL_MSGS`` overrides)."""
    env = os.environ.get("RDM_SPINAL_MSGS")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[4] / "firmware_protocol" / "spinal"


@lru_cache(maxsize=1)
def spinal_registry() -> TypeRegistry:
    """The registry of every Spinal, std_msgs, std_srvs and rosserial_msgs type (cached)."""
    root = spinal_msgs_dir()
    if not (root / "spinal" / "msg").is_dir():
        raise FileNotFoundError(
            f"Spinal message definitions not found under {root}; set RDM_SPINAL_MSGS"
        )
    return TypeRegistry.from_directory(root)
