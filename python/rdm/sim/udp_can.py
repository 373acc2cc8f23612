"""A CAN bus shared by separate processes on a host without SocketCAN.

python-can's ``virtual`` bus is in-process only; its ``udp_multicast`` interface carries each
frame as one UDP multicast datagram (msgpack-encoded) to every socket of the group, across
processes. Two differences from a CAN bus, handled here:

* a ``udp_multicast`` socket receives its own datagrams (multicast loopback) and python-can
  cannot switch that off (``receive_own_messages=True`` raises, ``False`` is not honoured):
  :class:`UdpMulticastCan` drops its own frames (FIFO of what it sent; its own frames come
  back in send order);
* every group on the same UDP port reaches every socket bound to that port on Linux, so each
  run picks its own port (:func:`random_udp_spec`).

Spec: ``udp_multicast:<group>[,port=N]`` (e.g. ``udp_multicast:239.74.163.2,port=43113``).
:func:`open_bus` also takes every spec of :func:`rdm.link.can.open_can`.
"""

from __future__ import annotations

import random
from collections import deque

import can

from rdm.link.can import open_can

UDP_PREFIX = "udp_multicast:"
DEFAULT_UDP_PORT = 43113


def _key(msg: can.Message) -> tuple:
    return (
        msg.arbitration_id,
        msg.is_extended_id,
        msg.is_remote_frame,
        msg.is_fd,
        msg.dlc,
        bytes(msg.data),
    )


class UdpMulticastCan(can.BusABC):
    """python-can ``udp_multicast`` without self-reception (see the module doc)."""

    def __init__(self, group: str, port: int = DEFAULT_UDP_PORT, **kwargs) -> None:
        self._inner = can.Bus(interface="udp_multicast", channel=group, port=port)
        self._own: deque[tuple] = deque(maxlen=100_000)
        self.own_dropped = 0
        self.channel_info = f"udp_multicast {group}:{port}"
        super().__init__(channel=group, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._own.append(_key(msg))
        self._inner.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        while True:
            msg = self._inner.recv(timeout)
            if msg is None:
                return None, False
            if self._own and _key(msg) == self._own[0]:
                self._own.popleft()
                self.own_dropped += 1
                timeout = 0.0  # our own echo: look once more for a peer's frame
                continue
            return msg, False

    def fileno(self) -> int:
        return self._inner.fileno()

    def shutdown(self) -> None:
        self._inner.shutdown()
        super().shutdown()


def parse_udp_spec(spec: str) -> tuple[str, int]:
    """(group, port) of ``udp_multicast:<group>[,port=N]``; ValueError naming the bad part."""
    rest = spec[len(UDP_PREFIX) :]
    group, *opts = rest.split(",")
    port = DEFAULT_UDP_PORT
    for opt in opts:
        key, _, value = opt.partition("=")
        if key.strip() != "port" or not value.isdigit() or not 0 < int(value) < 65536:
            raise ValueError(f"CAN spec {spec!r}: option {opt!r} (only port=1..65535)")
        port = int(value)
    if not group:
        raise ValueError(f"CAN spec {spec!r}: no multicast group")
    return group, port


def open_bus(spec: str) -> can.BusABC:
    """Open ``udp_multicast:<group>[,port=N]`` here, anything else with ``open_can``."""
    if spec.startswith(UDP_PREFIX):
        group, port = parse_udp_spec(spec)
        return UdpMulticastCan(group, port)
    return open_can(spec)


def random_udp_spec(rng: random.Random | None = None) -> str:
    """A fresh administratively scoped group and port, so concurrent runs do not mix."""
    r = rng or random.SystemRandom()
    return (
        f"{UDP_PREFIX}239.{r.randint(1, 254)}.{r.randint(1, 254)}.{r.randint(1, 254)},"
        f"port={r.randint(20000, 60000)}"
    )
