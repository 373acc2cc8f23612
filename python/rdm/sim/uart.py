"""UART byte captures and a lockstep barrier for pty pairs.

:class:`TappedLink` wraps one end of a byte link (``read_available``/``write``/``close``, as
:class:`rdm.link.serial.SerialLink`): it counts the bytes and appends what is written to
``tx_path`` and what is read to ``rx_path``. Raw bytes, nothing added, so ``rdm decode`` reads
the files directly (``.lep`` Leptrino, ``.bin`` rosserial).

:class:`PtyPair` is the lockstep barrier of a pty pair. Linux delivers pty bytes through a
kernel work queue, so bytes written in one tick may not be readable yet in the next (most
writes are not visible immediately, some only after tens of ms on a loaded machine).
That would make the tick at which a node sees a byte depend on the kernel scheduler. ``settle()``
blocks until every byte written so far on either end is readable on the other, so the byte
timeline is a function of simulated time only.

:func:`open_inproc_uart` is the fast alternative when both ends live in the lockstep process: an
in-process byte pipe with the same link API (bytes are readable as soon as written, no kernel,
no barrier). A pty write costs 6 us on an idle machine but up to ~1 ms under load (the tty
flush work queue); see docs/sim.md.
"""

from __future__ import annotations

import os
import select
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, BinaryIO

from rdm.output_files import open_output
from rdm.sim.capture_index import Clock, TimedCaptureFile


def _capture_file(
    path: str | os.PathLike[str] | None, clock: Clock | None
) -> BinaryIO | TimedCaptureFile | None:
    if path is None:
        return None
    if clock is None:
        return open_output(path, "wb")
    return TimedCaptureFile(path, clock)


class TappedLink:
    """A byte link end that counts and optionally captures its traffic. With ``clock`` (the
    simulated time in s), each capture gets a time index beside it
    (:mod:`rdm.sim.capture_index`): ``rdm decode RUN --mcap`` times every message by it."""

    def __init__(
        self,
        link,
        tx_path: str | os.PathLike[str] | None = None,
        rx_path: str | os.PathLike[str] | None = None,
        clock: Clock | None = None,
    ) -> None:
        self.link = link
        self.tx_bytes = 0
        self.rx_bytes = 0
        self._tx: BinaryIO | TimedCaptureFile | None = _capture_file(tx_path, clock)
        self._rx: BinaryIO | TimedCaptureFile | None = _capture_file(rx_path, clock)
        port = getattr(link, "port", None)
        if port is not None and hasattr(port, "write_timeout"):
            port.write_timeout = 0  # never block the lockstep loop on a full pty

    def read_available(self) -> bytes:
        data = self.link.read_available()
        if data:
            self.rx_bytes += len(data)
            if self._rx is not None:
                self._rx.write(data)
        return data

    def write(self, data: bytes) -> int:
        return self.write_marked(data, ())

    def write_marked(self, data: bytes, marks: Sequence[tuple[float, int]]) -> int:
        """:meth:`write` of a batch of ticks' bytes, ``marks`` their ``(time s, end)`` in
        ``data``: a time-indexed capture keeps each tick's time (a plain one ignores them)."""
        if not data:
            return 0
        n = self.link.write(data)
        n = len(data) if n is None else int(n)
        self.tx_bytes += n
        tx = self._tx
        if tx is not None and n:
            if marks and isinstance(tx, TimedCaptureFile):
                tx.write_marked(data[:n], marks)
            else:
                tx.write(data[:n])
        return n

    @property
    def in_waiting(self) -> int:
        """Bytes waiting to be read at this end now."""
        own = getattr(self.link, "in_waiting", None)
        return int(own if own is not None else self.link.port.in_waiting)

    def fileno(self) -> int:
        return self.link.port.fileno()

    def flush_captures(self) -> None:
        for f in (self._tx, self._rx):
            if f is not None:
                f.flush()

    def close(self) -> None:
        for f in (self._tx, self._rx):
            if f is not None and not f.closed:
                f.close()
        self.link.close()


class PtyPair:
    """Lockstep barrier over two :class:`TappedLink` ends of one pty pair."""

    def __init__(self, a: TappedLink, b: TappedLink, timeout: float = 5.0) -> None:
        self.a = a
        self.b = b
        self.timeout = timeout
        self.waits = 0  # settles that had to wait for the kernel
        self.wait_s = 0.0

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
        self.wait_s += time.perf_counter() - t0


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
    """An in-process byte pipe as (device end, host end), captured like :func:`open_tapped_pty`
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
