"""ROS1 md5 sums of message and service definitions, computed the genmsg way.

The hashed text has one line per constant (``type NAME=value``) followed by one line per field:
``type name`` for builtins (array suffix kept) and ``<md5 of the sub-message> name`` for nested
messages (array suffix dropped). A service's md5 hashes the request text followed directly by
the response text. rosserial puts these strings into TopicInfo and the PC side compares them.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

from rdm.protocol.rosserial.msgdef import MsgSpec, SrvSpec

SpecLookup = Callable[[str], MsgSpec]


def md5_text(spec: MsgSpec, lookup: SpecLookup, _cache: dict[str, str] | None = None) -> str:
    """The canonical text genmsg hashes for ``spec``; ``lookup`` resolves nested types."""
    cache = {} if _cache is None else _cache
    lines = [f"{c.type} {c.name}={c.value_text}" for c in spec.constants]
    for f in spec.fields:
        if f.is_primitive:
            lines.append(f"{f.type_text} {f.name}")
        else:
            lines.append(f"{msg_md5(lookup(f.base_type), lookup, cache)} {f.name}")
    return "\n".join(lines).strip()


def msg_md5(spec: MsgSpec, lookup: SpecLookup, _cache: dict[str, str] | None = None) -> str:
    """The md5 sum ROS1 reports for a message type."""
    cache = {} if _cache is None else _cache
    if spec.full_name not in cache:
        text = md5_text(spec, lookup, cache)
        cache[spec.full_name] = hashlib.md5(text.encode()).hexdigest()
    return cache[spec.full_name]


def srv_md5(spec: SrvSpec, lookup: SpecLookup) -> str:
    """The md5 sum ROS1 reports for a service type."""
    text = md5_text(spec.request, lookup) + md5_text(spec.response, lookup)
    return hashlib.md5(text.encode()).hexdigest()
