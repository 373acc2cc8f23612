"""CAN transport via python-can, chosen by one configuration string.

Spec grammar: ``<interface>:<channel>[,key=value...]`` with interface ``socketcan`` (kernel
SocketCAN: ``can0``, ``vcan0``), ``virtual`` (python-can's in-process bus; every
``virtual:<name>`` bus in one process with the same name shares traffic) or ``inproc`` (the
fast lockstep bus :class:`rdm.link.inproc_can.InProcessBus`: same sharing, timestamps from a
simulated clock, no deep copies). Options:
``bitrate=<int>`` (virtual only: SocketCAN rates are set with ``ip link``),
``receive_own_messages=0|1``.

Examples: ``"socketcan:vcan0"``, ``"socketcan:can0"``, ``"virtual:neuron_bus"``, ``"inproc:hil"``,
``"virtual:hil,bitrate=1000000"``.
"""

from __future__ import annotations

import os
import re
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import can

INTERFACES = ("socketcan", "virtual", "inproc")
_CHANNEL = {
    "socketcan": re.compile(r"^[A-Za-z0-9_.\-]{1,15}$"),  # a kernel name: IFNAMSIZ - 1 chars
    "virtual": re.compile(r"^[A-Za-z0-9_.\-]{1,64}$"),
    "inproc": re.compile(r"^[A-Za-z0-9_.\-]{1,64}$"),
}


class CanSpecError(ValueError):
    """A malformed CAN configuration string."""


class CanUnavailableError(OSError):
    """The requested CAN interface cannot be opened on this machine."""


@dataclass(frozen=True)
class CanSpec:
    interface: str
    channel: str
    bitrate: int | None = None
    receive_own_messages: bool = False
    extra: dict[str, Any] = field(default_factory=dict)

    def bus_kwargs(self) -> dict[str, Any]:
        kwargs: dict[str, Any] = {
            "interface": self.interface,
            "channel": self.channel,
            "receive_own_messages": self.receive_own_messages,
        }
        if self.bitrate is not None:
            kwargs["bitrate"] = self.bitrate
        return kwargs


def parse_can_spec(spec: str) -> CanSpec:
    """Parse ``<interface>:<channel>[,key=value...]``; raise :class:`CanSpecError` if bad."""
    if not isinstance(spec, str) or ":" not in spec:
        raise CanSpecError(
            f"CAN spec {spec!r}: expected '<interface>:<channel>[,bitrate=N]', "
            f"interface one of {', '.join(INTERFACES)} "
            "(e.g. 'socketcan:can0', 'virtual:bus', 'inproc:hil')"
        )
    interface, _, rest = spec.strip().partition(":")
    interface = interface.lower()
    if interface not in INTERFACES:
        raise CanSpecError(
            f"CAN spec {spec!r}: unknown interface {interface!r}; "
            f"use one of {', '.join(INTERFACES)}"
        )
    channel, *options = rest.split(",")
    pattern = _CHANNEL[interface]
    if not pattern.match(channel):
        raise CanSpecError(
            f"CAN spec {spec!r}: channel {channel!r} must match {pattern.pattern} for {interface}"
        )
    bitrate: int | None = None
    own = False
    for option in options:
        key, eq, value = option.partition("=")
        key = key.strip().lower()
        if not eq:
            raise CanSpecError(f"CAN spec {spec!r}: option {option!r} is not key=value")
        if key == "bitrate":
            if not value.isdigit() or not 10_000 <= int(value) <= 8_000_000:
                raise CanSpecError(f"CAN spec {spec!r}: bitrate {value!r} not 10000..8000000")
            if interface == "socketcan":
                raise CanSpecError(
                    f"CAN spec {spec!r}: SocketCAN takes no bitrate here; set it with "
                    f"'ip link set {channel} type can bitrate {value}'"
                )
            bitrate = int(value)
        elif key == "receive_own_messages":
            if value not in ("0", "1"):
                raise CanSpecError(f"CAN spec {spec!r}: receive_own_messages must be 0 or 1")
            own = value == "1"
        else:
            raise CanSpecError(
                f"CAN spec {spec!r}: unknown option {key!r} (bitrate, receive_own_messages)"
            )
    return CanSpec(interface, channel, bitrate, own)


def socketcan_available(channel: str = "vcan0") -> bool:
    """True when this kernel has SocketCAN and ``channel`` exists."""
    try:
        sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except (AttributeError, OSError):
        return False
    with sock:
        try:
            sock.bind((channel,))
        except OSError:
            return False
    return True


def open_can(spec: str) -> can.BusABC:
    """Open the bus named by ``spec``. Close it with ``bus.shutdown()`` or ``with``.

    Raises :class:`CanSpecError` for a malformed spec and :class:`CanUnavailableError` when
    the kernel has no SocketCAN or the interface does not exist.
    """
    parsed = parse_can_spec(spec)
    if parsed.interface == "inproc":
        from rdm.link.inproc_can import InProcessBus

        return InProcessBus(parsed.channel, receive_own_messages=parsed.receive_own_messages)
    try:
        return can.Bus(**parsed.bus_kwargs())
    except OSError as exc:
        if parsed.interface != "socketcan":
            raise
        if exc.errno == 97:  # EAFNOSUPPORT: no CAN in this kernel
            why = "this kernel has no SocketCAN (AF_CAN: errno 97)"
        elif exc.errno == 19:  # ENODEV
            why = f"no network interface {parsed.channel!r} (create it: ip link add ... type vcan)"
        else:
            why = f"{exc.strerror or exc} (errno {exc.errno})"
        raise CanUnavailableError(
            exc.errno,
            f"cannot open {spec!r}: {why}. Use 'virtual:<name>' for an in-process bus, or run "
            "inside the vcan VM harness for kernel SocketCAN.",
        ) from exc
    except can.CanError as exc:
        if parsed.interface == "socketcan":
            raise CanUnavailableError(
                None, f"cannot open {spec!r}: {exc}. Use 'virtual:<name>' or the vcan VM harness."
            ) from exc
        raise


def candump_logger(path: str | os.PathLike[str], channel: str = "can0") -> can.Listener:
    """A ``candump -L`` style writer for ``.log`` files (python-can ``CanutilsLogWriter``).

    Use as a ``can.Notifier`` listener or call ``on_message_received(msg)``; ``stop()`` closes.
    """
    if not str(path).endswith(".log"):
        raise ValueError(f"candump_logger: {path!r} must end in .log")
    return can.CanutilsLogWriter(path, channel=channel)


def neuron_message(can_id: int, data: bytes) -> can.Message:
    """A classic 11-bit CAN message as the Neuron link uses."""
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def send_neuron_payload(bus: can.BusABC, can_id: int, data: bytes) -> bool:
    """Send one classic 11-bit frame without blocking; False if the bus refused it.

    The in-process bus takes the fast path (``send_standard``: no sender-side ``Message``);
    any other python-can bus gets :func:`neuron_message`."""
    try:
        fast = getattr(bus, "send_standard", None)
        if fast is not None:
            fast(can_id, data)
        else:
            bus.send(neuron_message(can_id, data), timeout=0)
    except (can.CanError, OSError):
        return False
    return True


def send_neuron_payload_via(
    bus: can.BusABC, fast: Callable[[int, bytes], None] | None, can_id: int, data: bytes
) -> bool:
    """:func:`send_neuron_payload` with the bus's ``send_standard`` looked up once by the
    caller (``fast``; None for a bus without it). False if the bus refused the frame."""
    if fast is None:
        return send_neuron_payload(bus, can_id, data)
    try:
        fast(can_id, data)
    except (can.CanError, OSError):
        return False
    return True
