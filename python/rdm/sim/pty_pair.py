"""A lockstep barrier for pty pairs, and pty pairs with their captures.

:class:`PtyPair` is the lockstep barrier of a pty pair. Linux delivers pty bytes through a
kernel work queue, so bytes written in one tick may not be readable yet in the next (most
writes are not visible immediately, some only after tens of ms on a loaded machine).
That would make the tick at which a node sees a byte depend on the kernel scheduler. ``settle()``
blocks until every byte written so far on either end is readable on the other, so the byte
timeline is a function of simulated time only.

Both ends in the lockstep process need no pty: :func:`rdm.link.uart_pipe.open_inproc_uart` is
the in-process pipe with the same link API.
"""

from __future__ import annotations

import os
import select
import time
from pathlib import Path
from typing import Any

from rdm.link.capture_index import Clock
from rdm.link.tapped_link import TappedLink


class PtyPair:
    """Lockstep barrier over two :class:`TappedLink` ends of one pty pair."""

    def __init__(self, a: TappedLink, b: TappedLink, timeout: float = 5.0) -> None:
        self.a = a
        self.b = b
        self.timeout = timeout
        self.waits = 0  # settles that had to wait for the kernel

    @staticmethod
    def _missing(writer: TappedLink, reader: TappedLink) -> int:
        return writer.tx_bytes - reader.rx_bytes - reader.in_waiting

    def settle(self) -> None:
        """Block until every byte written on either end is readable on the other."""
        a, b = self.a, self.b
        if a.tx_bytes == b.rx_bytes and b.tx_bytes == a.rx_bytes:
            return  # nothing in flight
        if self._missing(a, b) <= 0 and self._missing(b, a) <= 0:
            return
        t0 = time.perf_counter()
        self.waits += 1
        deadline = t0 + self.timeout
        while True:
            pending = [r for w, r in ((a, b), (b, a)) if self._missing(w, r) > 0]
            if not pending:
                break
            left = deadline - time.perf_counter()
            if left <= 0:
                raise TimeoutError(
                    f"PtyPair.settle: {sum(self._missing(w, r) for w, r in ((a, b), (b, a)))} "
                    f"bytes still in the kernel after {self.timeout} s"
                )
            # Wakes when the reader has data; partial arrivals loop again.
            select.select([r.fileno() for r in pending], [], [], min(left, 0.001))


def open_tapped_pty(
    capture_dir: str | os.PathLike[str] | None = None,
    stem: str = "uart",
    ext: str = ".bin",
    clock: Clock | None = None,
) -> tuple[TappedLink, TappedLink, PtyPair]:
    """A pty pair as (device end, host end, barrier). With ``capture_dir``, the device end's
    bytes go to ``<stem>.device_tx<ext>`` and the host's to ``<stem>.host_tx<ext>``, each with
    a time index when ``clock`` is given."""
    from rdm.link.serial import open_pty_pair

    device, host = open_pty_pair()
    if capture_dir is None:
        dev = TappedLink(device)
    else:
        d = Path(capture_dir)
        d.mkdir(parents=True, exist_ok=True)
        dev = TappedLink(
            device, d / f"{stem}.device_tx{ext}", d / f"{stem}.host_tx{ext}", clock=clock
        )
    hst = TappedLink(host)
    device.peer = None  # each TappedLink closes its own end
    return dev, hst, PtyPair(dev, hst)


def open_device_pty(
    capture_dir: str | os.PathLike[str] | None = None,
    stem: str = "uart",
    ext: str = ".bin",
    clock: Clock | None = None,
) -> tuple[TappedLink, Any]:
    """A pty whose master is the device's end (tapped as :func:`open_tapped_pty` taps it) and
    whose slave is for another process to open by its path: returns (device end, the slave
    link). The slave stays open here without being read, so the pty never hangs up while the
    other process reopens it."""
    from rdm.link.serial import open_pty_pair

    slave, master = open_pty_pair()
    slave.peer = None  # each end closes itself
    if capture_dir is None:
        return TappedLink(master), slave
    d = Path(capture_dir)
    d.mkdir(parents=True, exist_ok=True)
    dev = TappedLink(master, d / f"{stem}.device_tx{ext}", d / f"{stem}.host_tx{ext}", clock)
    return dev, slave
