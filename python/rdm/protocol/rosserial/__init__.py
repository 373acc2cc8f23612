"""rosserial (protocol v2, JSK fork) between Spinal and the onboard PC.

One concept per module: :mod:`.msgdef` (.msg/.srv parser), :mod:`.md5` (ROS md5 sums),
:mod:`.codec` (ROS1 serialization and message classes), :mod:`.registry` (types of a package
tree; :func:`spinal_registry`), :mod:`.framing` (frames and the resyncing parser, over the
Rust frame builder and scan), :mod:`.timesync` (client clock), :mod:`.services`,
:mod:`.client` (Spinal role), :mod:`.server` (PC role), :mod:`.events`, :mod:`.constants`.
"""

from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import DecodeError, EncodeError, RosDuration, RosTime
from rdm.protocol.rosserial.framing import BadFrame, Frame, FrameParser, SkippedBytes, encode_frame
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry
from rdm.protocol.rosserial.server import ServerSession

__all__ = [
    "BadFrame",
    "ClientSession",
    "DecodeError",
    "EncodeError",
    "Frame",
    "FrameParser",
    "RosDuration",
    "RosTime",
    "ServerSession",
    "SkippedBytes",
    "TypeRegistry",
    "encode_frame",
    "spinal_registry",
]
