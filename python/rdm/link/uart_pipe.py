"""An in-process UART: a byte pipe between two ends that live in one process.

:func:`open_inproc_uart` is the fast alternative to a pty pair
(:func:`rdm.sim.pty_pair.open_tapped_pty`) when both ends live in the lockstep process: the same
link API (``read_available``/``write``/``close``), bytes readable as soon as written, no kernel,
no barrier. A pty write costs 6 us on an idle machine but up to ~1 ms under load (the tty flush
work queue); see docs/sim.md.
"""

from __future__ import annotations

import os
from pathlib import Path

from rdm.link.capture_index import Clock
from rdm.link.tapped_link import TappedLink


class InProcessUartEnd:
    """One end of an in-process byte pipe (``read_available``/``write``/``close``)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._inbox = bytearray()
        self.peer: InProcessUartEnd | None = None
        self.closed = False

    @property
    def in_waiting(self) -> int:
        return len(self._inbox)

    @property
    def inbox(self) -> bytearray:
        """The received bytes not yet read: the live buffer (the same object for the end's
        life; read it, never change it). Empty means :meth:`read_available` returns ``b""``."""
        return self._inbox

    def read_available(self) -> bytes:
        if not self._inbox:
            return b""
        data = bytes(self._inbox)
        self._inbox.clear()
        return data

    def write(self, data: bytes) -> int:
        if self.closed:
            raise OSError(f"{self.name}: write on a closed in-process UART")
        peer = self.peer
        if peer is None or peer.closed:
            return 0  # nobody listening: the bytes are lost, as on an unplugged line
        peer._inbox += data
        return len(data)

    def close(self) -> None:
        self.closed = True


def open_inproc_uart(
    capture_dir: str | os.PathLike[str] | None = None,
    stem: str = "uart",
    ext: str = ".bin",
    clock: Clock | None = None,
) -> tuple[TappedLink, TappedLink]:
    """An in-process byte pipe as (device end, host end), captured like a tapped pty pair
    (``<stem>.device_tx<ext>``, ``<stem>.host_tx<ext>``, time-indexed with ``clock``). No
    barrier is needed."""
    dev, host = InProcessUartEnd("device"), InProcessUartEnd("host")
    dev.peer, host.peer = host, dev
    if capture_dir is None:
        return TappedLink(dev), TappedLink(host)
    d = Path(capture_dir)
    d.mkdir(parents=True, exist_ok=True)
    return (
        TappedLink(dev, d / f"{stem}.device_tx{ext}", d / f"{stem}.host_tx{ext}", clock=clock),
        TappedLink(host),
    )
