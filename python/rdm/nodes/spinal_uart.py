"""A never-blocking UART byte pump for the Spinal mirror.

pyserial's ``write`` blocks when the kernel buffer is full (a pty whose peer does not read
holds only about 4 KiB), and with ``write_timeout=0`` it spins on ``EAGAIN``. A firmware
mirror must never stall its loop on the wire, so outgoing bytes go through a bounded queue:
each :meth:`UartPump.pump` writes what the port accepts now and keeps the rest. When the queue
exceeds ``max_pending`` bytes (the peer is gone), the queued bytes are discarded and counted;
the peer's rosserial parser resynchronises on the next frame, as after a UART overrun.
"""

from __future__ import annotations

import os
import select
from typing import Any

from rdm.link.uart_pipe import InProcessUartEnd

#: Bytes kept for a slow peer before the backlog is discarded (8 KiB = Spinal's TX ring).
DEFAULT_MAX_PENDING = 128 * 64
#: Wrappers whose ``read_available`` with nothing underneath returns ``b""`` and changes
#: nothing (module, class name): the capture tap and the stack's cuttable link.
_TAPPED = ("rdm.link.tapped_link", "TappedLink")
_DROPPABLE = ("rdm.scenarios.stack", "DroppableLink")
_PURE_READ_WRAPPERS = {_TAPPED, _DROPPABLE}
_MAX_WRAPPERS = 8


def _kind(link: Any) -> tuple[str, str]:
    cls = type(link)
    return cls.__module__, cls.__qualname__


def source_inbox(link: Any) -> bytearray | None:
    """The in-process receive buffer under ``link`` when reading ``link`` with that buffer
    empty is a no-op returning ``b""`` (a chain of known wrappers over an
    :class:`rdm.link.uart_pipe.InProcessUartEnd`); None for anything else (ptys, serial ports)."""
    for _ in range(_MAX_WRAPPERS):
        cls = type(link)
        if cls is InProcessUartEnd:
            return link.inbox
        if (cls.__module__, cls.__qualname__) not in _PURE_READ_WRAPPERS:
            return None
        link = link.link
    return None


def inproc_chain(link: Any) -> tuple[Any, Any, InProcessUartEnd] | None:
    """``(droppable, tapped, end)`` when ``link`` is exactly the stack's chain
    ``[DroppableLink ->] [TappedLink ->] InProcessUartEnd`` (each optional wrapper None when
    absent; exact classes, no subclass), else None. :meth:`UartPump.read` and
    :meth:`UartPump._write` then do what the chain's ``read_available`` / ``write`` do
    without the calls through the wrappers."""
    droppable = tapped = None
    if _kind(link) == _DROPPABLE:
        droppable, link = link, link.link
    if _kind(link) == _TAPPED:
        tapped, link = link, link.link
    if type(link) is InProcessUartEnd:
        return droppable, tapped, link
    return None


class UartPump:
    """Non-blocking reads and writes on a :class:`rdm.link.serial.SerialLink` (or any object
    with ``read_available()`` and ``port``/``write``)."""

    def __init__(self, link: Any, max_pending: int = DEFAULT_MAX_PENDING) -> None:
        self.link = link  # resolves inbox (see the property)
        self.max_pending = max_pending
        self.pending = bytearray()
        self.bytes_in = 0
        self.bytes_out = 0
        self.bytes_discarded = 0
        self.write_errors = 0
        self.read_errors = 0
        port = getattr(link, "port", None)
        try:
            self._fd: int | None = port.fileno() if port is not None else None
        except (AttributeError, OSError, ValueError):
            self._fd = None  # URL ports (loop://, socket://) have no usable fd

    @property
    def link(self) -> Any:
        """The byte link (assignable: :attr:`inbox` follows it)."""
        return self._link

    @link.setter
    def link(self, link: Any) -> None:
        self._link = link
        #: :func:`source_inbox` of the link: while it is empty, :meth:`read` returns ``b""``
        #: and changes nothing (callers may skip it); None when that is not known.
        self.inbox = source_inbox(link)
        #: :func:`inproc_chain` of the link (read and written directly), or None.
        self._chain = inproc_chain(link)

    def read(self) -> bytes:
        """Everything received so far (``b""`` if nothing or on a port error, counted)."""
        try:
            chain = self._chain
            data = self.link.read_available() if chain is None else self._read_chain(chain)
        except (OSError, ValueError) as exc:  # SerialException is an OSError
            del exc
            self.read_errors += 1
            return b""
        self.bytes_in += len(data)
        return data

    @staticmethod
    def _read_chain(chain: tuple[Any, Any, InProcessUartEnd]) -> bytes:
        """``read_available`` through an :func:`inproc_chain` without the calls through the
        wrappers (same bytes, counters and captures)."""
        droppable, tapped, end = chain
        inbox = end._inbox
        if inbox:
            data = bytes(inbox)
            inbox.clear()
            if tapped is not None:
                tapped.rx_bytes += len(data)
                if tapped._rx is not None:
                    tapped._rx.write(data)
        else:
            data = b""
        if droppable is not None and droppable.dropped:
            droppable.bytes_lost += len(data)
            return b""
        return data

    def send(self, data: bytes) -> None:
        """Write as much of ``data`` as the port takes now and queue the rest (behind any
        bytes already queued); a queue over ``max_pending`` bytes is discarded and counted."""
        if data and not self.pending and type(data) is bytes:  # written without a copy
            if len(data) > self.max_pending:
                self.bytes_discarded += len(data)
                return
            n = self._write(data)
            if n < len(data):
                self.pending += data[n:]
            self.bytes_out += n
            return
        if data:
            self.pending += data
        if len(self.pending) > self.max_pending:
            self.bytes_discarded += len(self.pending)
            self.pending.clear()
            return
        self.pump()

    def pump(self) -> int:
        """Write queued bytes the port accepts without blocking; returns bytes written."""
        if not self.pending:
            return 0
        n = self._write(bytes(self.pending))
        del self.pending[:n]
        self.bytes_out += n
        return n

    def _write(self, data: bytes) -> int:
        """Write what the port takes now of ``data``: bytes written (0 if none, or on a port
        error, counted)."""
        try:
            chain = self._chain
            if chain is not None:
                return self._write_chain(chain, data)
            if self._fd is not None:
                _, writable, _ = select.select([], [self._fd], [], 0)
                if not writable:
                    return 0
                try:
                    return os.write(self._fd, data)
                except BlockingIOError:
                    return 0
            return self.link.write(data)
        except (OSError, ValueError):
            self.write_errors += 1
            return 0

    def writes_whole(self) -> bool:
        """Whether :meth:`send` of any ``bytes`` of 1 to :attr:`max_pending` bytes writes
        them all now, through the chain, with nothing left pending: the in-process
        chain with nothing queued and the line cut (the bytes are counted lost) or both ends
        open. Then several such sends and one send of their bytes joined (up to
        ``max_pending``) leave the same bytes, counters and captures; this holds until
        Python code changes the chain (the lockstep kernel's deferred Spinal output)."""
        chain = self._chain
        if chain is None or self.pending:
            return False
        droppable, _tapped, end = chain
        if droppable is not None and droppable.dropped:
            return True
        peer = end.peer
        return not end.closed and peer is not None and not peer.closed

    @staticmethod
    def _write_chain(chain: tuple[Any, Any, InProcessUartEnd], data: bytes) -> int:
        """``DroppableLink.write(TappedLink.write(end.write(data)))`` of an
        :func:`inproc_chain` without the calls through the wrappers (same bytes, counters,
        captures and ``OSError``)."""
        droppable, tapped, end = chain
        n = len(data)
        if droppable is not None and droppable.dropped:
            droppable.bytes_lost += n
            return n
        if tapped is not None and not data:
            return 0
        if end.closed:
            raise OSError(f"{end.name}: write on a closed in-process UART")
        peer = end.peer
        if peer is None or peer.closed:
            n = 0  # nobody listening: the bytes are lost, as on an unplugged line
        else:
            peer._inbox += data
        if tapped is not None:
            tapped.tx_bytes += n
            if tapped._tx is not None and n:
                tapped._tx.write(data[:n])
        return n
