"""SocketCAN tests on a real kernel vcan interface.

Every test in this directory is marked ``vcan``. When ``vcan0`` is absent (this host's kernel
may not even have AF_CAN) the tests are skipped; ``scripts/test-vcan.sh`` runs them inside a
small VM that has real SocketCAN. With ``RDM_VCAN_REQUIRED=1`` (set by that script) a missing
interface is an error instead of a skip, so a broken harness cannot pass by skipping.

Fixtures for tests of the project's nodes over the bus:

* ``vcan_channel``: the interface name (``"vcan0"``, or ``$RDM_VCAN_CHANNEL``).
* ``vcan_bus``: a factory ``vcan_bus(**kwargs) -> can.BusABC`` opening python-can
  ``socketcan`` buses on that channel; every bus it opened is shut down after the test.
* ``recv_all``: drain a bus, collecting the frames that arrive within a time window.
"""

from __future__ import annotations

import os
import socket
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import can
import pytest

HERE = Path(__file__).resolve().parent
# Helper modules beside the tests (can_frames.py) must import under --import-mode=importlib too.
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
CHANNEL = os.environ.get("RDM_VCAN_CHANNEL", "vcan0")
SKIP_REASON = "vcan0 absent: run scripts/test-vcan.sh (boots a VM with real SocketCAN)"
IFF_UP = 0x1


def vcan_problem(channel: str) -> str | None:
    """Why ``channel`` cannot carry the tests, or None when it is an up SocketCAN interface."""
    try:
        socket.if_nametoindex(channel)
    except OSError:
        return SKIP_REASON if channel == "vcan0" else f"{channel} absent"
    flags_file = Path("/sys/class/net") / channel / "flags"
    if flags_file.exists() and not int(flags_file.read_text(), 16) & IFF_UP:
        return f"{channel} is down: sudo ip link set up {channel}"
    return None


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test here ``vcan`` (before ``-m`` selection runs) and skip them without vcan0."""
    problem = vcan_problem(CHANNEL)
    required = os.environ.get("RDM_VCAN_REQUIRED") == "1"
    for item in items:
        if HERE not in Path(item.path).resolve().parents:
            continue
        item.add_marker(pytest.mark.vcan)
        if problem is None:
            continue
        if required:
            raise pytest.UsageError(f"RDM_VCAN_REQUIRED=1 but {problem}")
        item.add_marker(pytest.mark.skip(reason=problem))


@pytest.fixture(scope="session")
def vcan_channel() -> str:
    """Name of the SocketCAN interface the tests use."""
    return CHANNEL


@pytest.fixture
def vcan_bus(vcan_channel: str) -> Iterator[Callable[..., can.BusABC]]:
    """Factory for python-can socketcan buses on ``vcan_channel``; all are shut down afterwards.

    Keyword arguments go to ``can.Bus`` (``can_filters``, ``fd``, ``receive_own_messages``, ...).
    """
    opened: list[can.BusABC] = []

    def open_bus(**kwargs: object) -> can.BusABC:
        kwargs.setdefault("channel", vcan_channel)
        bus = can.Bus(interface="socketcan", **kwargs)
        opened.append(bus)
        return bus

    yield open_bus
    for bus in opened:
        bus.shutdown()


def _recv_all(bus: can.BusABC, window: float, limit: int | None = None) -> list[can.Message]:
    """Frames received on ``bus`` until ``window`` seconds pass (or ``limit`` frames arrive)."""
    frames: list[can.Message] = []
    deadline = time.monotonic() + window
    while limit is None or len(frames) < limit:
        left = deadline - time.monotonic()
        if left <= 0:
            break
        msg = bus.recv(timeout=left)
        if msg is not None:
            frames.append(msg)
    return frames


@pytest.fixture
def recv_all() -> Callable[..., list[can.Message]]:
    """``recv_all(bus, window, limit=None)``: drain ``bus`` for ``window`` seconds."""
    return _recv_all
