"""Time index of a raw byte capture: when each write reached the wire.

A UART capture (``spinal.device_tx.bin``, ``leptrino_foot.device_tx.lep``) is the bytes of one
direction of a link and nothing else, so ``rdm decode`` and any third-party tool read it as a
real port's dump. The simulated time of each write lives beside it, in ``<capture>.idx``:

* 8 bytes of magic, ``RDMCIDX1``;
* then one 16-byte record per write, little-endian: ``int64`` simulated time in ns (rounded to
  the microsecond, as candump writes its stamps) and ``uint64`` the capture's length after the
  write (its end offset).

Times never decrease and end offsets strictly increase; the last end offset is the capture's
size. :func:`read_capture_index` checks all of this and raises :class:`CaptureIndexError` with
what is wrong. A byte's time is the time of the write that carried it
(:meth:`CaptureIndex.time_ns_of`), so a frame is timed by its first byte.
"""

from __future__ import annotations

import bisect
import contextlib
import os
import struct
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from rdm._rdm import capture_index_records
from rdm.output_files import open_output

MAGIC = b"RDMCIDX1"
INDEX_SUFFIX = ".idx"
_RECORD = struct.Struct("<qQ")

#: Simulated time in seconds, read at each write.
Clock = Callable[[], float]


class CaptureIndexError(ValueError):
    """An index that does not describe its capture (bad magic, truncated, out of order)."""


def index_path(capture: str | os.PathLike[str]) -> Path:
    """Where the index of ``capture`` lives (``<capture>.idx``)."""
    p = Path(capture)
    return p.with_name(p.name + INDEX_SUFFIX)


def time_ns(t: float) -> int:
    """Simulated seconds as index nanoseconds, rounded to the microsecond (candump's stamp
    resolution, and what 1 ms physics steps add up to despite the float sum's drift)."""
    return round(t * 1e6) * 1000


class TimedCaptureFile:
    """A capture file that indexes every write with the clock's time (see the module text).

    It stands in for the plain file a :class:`rdm.link.tapped_link.TappedLink` writes (``write``,
    ``flush``, ``close``, ``closed``), so the lockstep kernel's direct writes are timed too.
    """

    def __init__(self, path: str | os.PathLike[str], clock: Clock) -> None:
        self._clock = clock
        self._data: BinaryIO = open_output(path, "wb")
        try:
            self._index: BinaryIO = open_output(index_path(path), "wb")
        except OSError:
            self._data.close()
            raise
        self._index.write(MAGIC)
        self._end = 0
        self._last_ns = -(2**63)  # before any time
        #: (capture end when staged, marks) of :meth:`marked`, else None
        self._staged: tuple[int, Sequence[tuple[float, int]]] | None = None

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Write ``data``: bytes a staged mark covers at its time (:meth:`marked`), the rest at
        the clock's present time. The records come from ``capture_index_records`` (Rust)."""
        n = len(data)
        if not n:
            return 0
        start = self._end
        records, last = capture_index_records(start, n, self._staged, self._clock, self._last_ns)
        self._data.write(data)
        self._end = start + n
        self._last_ns = last
        self._index.write(records)
        return n

    @contextlib.contextmanager
    def marked(self, marks: Sequence[tuple[float, int]]) -> Iterator[None]:
        """Within the block, the next bytes written up to each ``end`` (counted from here)
        were produced at ``time`` (s), for ``(time, end)`` in ``marks``: a batch of ticks
        written at once (the lockstep kernel's deferred writes) keeps each tick's time, however
        the writer splits it. Bytes past the marks, or never written in the block, are not
        marked."""
        self._staged = (self._end, marks)
        try:
            yield
        finally:
            self._staged = None

    def write_marked(
        self, data: bytes | bytearray | memoryview, marks: Sequence[tuple[float, int]]
    ) -> int:
        """:meth:`write` of ``data`` with ``marks`` (``(time s, end in data)``, see
        :meth:`marked`)."""
        self._staged = (self._end, marks)  # marked(), without a generator per batch
        try:
            return self.write(data)
        finally:
            self._staged = None

    def flush(self) -> None:
        self._data.flush()
        self._index.flush()

    @property
    def closed(self) -> bool:
        return self._data.closed

    def close(self) -> None:
        for f in (self._data, self._index):
            if not f.closed:
                f.close()


@dataclass(frozen=True)
class CaptureIndex:
    """The writes of one capture: ``times_ns[k]`` is when bytes up to ``ends[k]`` were written."""

    times_ns: tuple[int, ...]
    ends: tuple[int, ...]

    def time_ns_of(self, offset: int) -> int:
        """Time of the write that carried byte ``offset`` of the capture."""
        k = bisect.bisect_right(self.ends, offset)
        if offset < 0 or k >= len(self.ends):
            raise CaptureIndexError(f"byte {offset} is outside the indexed {self.size} bytes")
        return self.times_ns[k]

    @property
    def size(self) -> int:
        """Bytes the index covers (the capture's size when they agree)."""
        return self.ends[-1] if self.ends else 0


def read_capture_index(
    capture: str | os.PathLike[str], *, partial_ok: bool = False
) -> CaptureIndex:
    """Read and check the index beside ``capture`` (FileNotFoundError when there is none).

    ``partial_ok``: accept an index that covers more or fewer bytes than the capture has, as
    a run that did not close its files (killed) leaves them: each file lost its own unwritten
    buffer. The records themselves are still checked."""
    path = index_path(capture)
    raw = path.read_bytes()
    if raw[: len(MAGIC)] != MAGIC:
        raise CaptureIndexError(f"{path}: not a capture index (magic {raw[:8]!r})")
    body = memoryview(raw)[len(MAGIC) :]
    if len(body) % _RECORD.size:
        raise CaptureIndexError(
            f"{path}: {len(body)} bytes of records is not a whole number of {_RECORD.size}-byte"
            " records (truncated?)"
        )
    times: list[int] = []
    ends: list[int] = []
    for k, (ns, end) in enumerate(_RECORD.iter_unpack(body)):
        if times and ns < times[-1]:
            raise CaptureIndexError(f"{path}: record {k} goes back in time ({ns} < {times[-1]})")
        if end <= (ends[-1] if ends else 0):
            raise CaptureIndexError(f"{path}: record {k} does not advance the offset ({end})")
        times.append(ns)
        ends.append(end)
    size = Path(capture).stat().st_size
    index = CaptureIndex(tuple(times), tuple(ends))
    if index.size != size and not partial_ok:
        raise CaptureIndexError(f"{path}: indexes {index.size} bytes but the capture has {size}")
    return index


def timed_capture_of(link: object) -> TimedCaptureFile | None:
    """The time-indexed transmit capture of ``link`` or of a link it wraps (``.link``, as
    ``DroppableLink`` and ``TappedLink`` hold theirs), None when there is none."""
    for _ in range(8):  # wrappers are a few deep; never loop on a cycle
        tx = getattr(link, "_tx", None)
        if isinstance(tx, TimedCaptureFile):
            return tx
        link = getattr(link, "link", None)
        if link is None:
            return None
    return None
