"""A byte link end that counts, and optionally captures, its traffic.

:class:`TappedLink` wraps one end of a byte link (``read_available``/``write``/``close``, as
:class:`rdm.link.serial.SerialLink`): it counts the bytes and appends what is written to
``tx_path`` and what is read to ``rx_path``. Raw bytes, nothing added, so ``rdm decode`` reads
the files directly (``.lep`` Leptrino, ``.bin`` rosserial).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import BinaryIO

from rdm.link.capture_index import Clock, TimedCaptureFile
from rdm.output_files import open_output


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
    (:mod:`rdm.link.capture_index`): ``rdm decode RUN --mcap`` times every message by it."""

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

    def close(self) -> None:
        for f in (self._tx, self._rx):
            if f is not None and not f.closed:
                f.close()
        self.link.close()
