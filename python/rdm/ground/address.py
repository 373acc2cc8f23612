"""``udp:HOST:PORT``: the address of a ground-link end (``rdm onboard --control``,
``rdm ctl --to``)."""

from __future__ import annotations


def parse_udp(spec: str, what: str = "address") -> tuple[str, int]:
    """``(host, port)`` of ``udp:HOST:PORT`` (IPv4 address or host name, port 0-65535);
    ``ValueError`` naming ``what`` and the expected form otherwise."""
    rest = spec.removeprefix("udp:")
    host, _, port = rest.rpartition(":")
    if not spec.startswith("udp:") or not host or not port.isdigit() or int(port) > 65535:
        raise ValueError(f"{what} {spec!r}: expected udp:HOST:PORT (port 0-65535)")
    return host, int(port)
