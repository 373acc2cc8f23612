"""The time index beside a byte capture (rdm.link.capture_index): what each write records, the
batches the lockstep kernel writes at once, and indexes that do not describe their capture."""

from __future__ import annotations

import hashlib
import math
import struct

import numpy as np
import pytest

from rdm._rdm import capture_index_records
from rdm.link.capture_index import (
    MAGIC,
    CaptureIndexError,
    TimedCaptureFile,
    index_path,
    read_capture_index,
    time_ns,
)
from rdm.link.tapped_link import TappedLink
from rdm.link.uart_pipe import open_inproc_uart


class _Clock:
    """A settable simulated clock (the plant's time in a run)."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _brute_time(writes: list[tuple[float, bytes]], offset: int) -> int:
    """The time of byte ``offset`` by walking the writes (the oracle of bisect)."""
    start = 0
    for t, data in writes:
        if start <= offset < start + len(data):
            return time_ns(t)
        start += len(data)
    raise AssertionError("offset outside the writes")


def test_every_write_is_indexed_at_the_clock_time(tmp_path):
    clock = _Clock()
    path = tmp_path / "x.device_tx.bin"
    f = TimedCaptureFile(path, clock)
    writes = [(0.001 * k + 0.0004 * (k % 3), bytes([k]) * (1 + k % 5)) for k in range(40)]
    for t, data in writes:
        clock.t = t
        assert f.write(data) == len(data)
    f.write(b"")  # an empty write adds no record
    f.close()
    assert f.closed
    assert path.read_bytes() == b"".join(d for _, d in writes)
    index = read_capture_index(path)
    assert len(index.ends) == len(writes)
    assert index.size == path.stat().st_size
    for offset in range(index.size):
        assert index.time_ns_of(offset) == _brute_time(writes, offset)
    for bad in (-1, index.size):
        with pytest.raises(CaptureIndexError, match="outside"):
            index.time_ns_of(bad)


def test_times_are_whole_microseconds_of_the_float_sum_of_steps():
    t = 0.0
    for _ in range(42_389):
        t += 0.001  # what 1 ms physics steps leave in data.time
    assert t != 42.389
    assert time_ns(t) == 42_389_000_000


def test_a_batch_keeps_each_ticks_time(tmp_path):
    clock = _Clock()
    path = tmp_path / "b.bin"
    f = TimedCaptureFile(path, clock)
    clock.t = 0.025  # written at 25 ms ...
    f.write_marked(b"aaabbbbcc", [(0.021, 3), (0.022, 7), (0.024, 9)])  # ... made at 21-24 ms
    # the rest at the clock's time, held at the mark before it (the index never goes back)
    f.write_marked(b"dd" + b"ee", [(0.026, 2)])
    clock.t = 0.030
    f.write_marked(b"ff", [(math.nan, 2)])  # a mark without a time: the clock's
    f.close()
    index = read_capture_index(path)
    assert [index.time_ns_of(k) // 1_000_000 for k in range(path.stat().st_size)] == [
        21, 21, 21, 22, 22, 22, 22, 24, 24, 26, 26, 26, 26, 30, 30,
    ]  # fmt: skip


def test_marks_hold_however_the_writer_splits_the_batch(tmp_path):
    """A pump that writes a batch in pieces (a full pty): each piece's bytes keep their tick's
    time; bytes written after the block take the clock's."""
    clock = _Clock()
    path = tmp_path / "s.bin"
    f = TimedCaptureFile(path, clock)
    f.write(b"zz")  # at 0
    clock.t = 0.050
    with f.marked([(0.041, 4), (0.042, 6), (0.043, 10)]):
        for piece in (b"aa", b"aab", b"bccc", b"c"):
            f.write(piece)
    f.write(b"yy")
    f.close()
    index = read_capture_index(path)
    assert [index.time_ns_of(k) // 1_000_000 for k in range(path.stat().st_size)] == [
        0, 0, 41, 41, 41, 41, 42, 42, 43, 43, 43, 43, 50, 50,
    ]  # fmt: skip
    assert index.ends == (2, 4, 6, 7, 8, 11, 12, 14)


def test_a_clock_that_steps_back_keeps_the_index_ordered(tmp_path):
    clock = _Clock()
    path = tmp_path / "c.bin"
    f = TimedCaptureFile(path, clock)
    for t in (0.002, 0.001, 0.003):
        clock.t = t
        f.write(b"xy")
    f.close()
    assert read_capture_index(path).times_ns == (2_000_000, 2_000_000, 3_000_000)


def _write_index(capture, records, magic=MAGIC, tail=b""):
    body = b"".join(struct.pack("<qQ", ns, end) for ns, end in records)
    index_path(capture).write_bytes(magic + body + tail)


@pytest.mark.parametrize(
    ("records", "magic", "tail", "match"),
    [
        ([(0, 4)], b"RDMCIDX0", b"", "not a capture index"),
        ([(0, 4)], MAGIC, b"\x01\x02", "not a whole number"),
        ([(5, 2), (4, 4)], MAGIC, b"", "goes back in time"),
        ([(1, 2), (2, 2), (3, 4)], MAGIC, b"", "does not advance"),
        ([(1, 3)], MAGIC, b"", "indexes 3 bytes but the capture has 4"),
        ([(1, 2), (2, 6)], MAGIC, b"", "indexes 6 bytes but the capture has 4"),
    ],
)
def test_an_index_that_does_not_fit_is_refused(tmp_path, records, magic, tail, match):
    capture = tmp_path / "d.bin"
    capture.write_bytes(b"abcd")
    _write_index(capture, records, magic, tail)
    with pytest.raises(CaptureIndexError, match=match):
        read_capture_index(capture)


def test_no_index_is_file_not_found(tmp_path):
    capture = tmp_path / "e.bin"
    capture.write_bytes(b"abcd")
    with pytest.raises(FileNotFoundError):
        read_capture_index(capture)


def test_a_tapped_link_with_a_clock_captures_the_same_bytes(tmp_path):
    clock = _Clock()
    plain_dev, plain_host = open_inproc_uart(tmp_path / "plain", "spinal", ".bin")
    timed_dev, timed_host = open_inproc_uart(tmp_path / "timed", "spinal", ".bin", clock)
    for k in range(30):
        clock.t = k * 0.001
        data = bytes(range(k % 7, k % 7 + 1 + k % 4))
        for dev, host in ((plain_dev, plain_host), (timed_dev, timed_host)):
            dev.write(data)
            host.write(data[::-1])
            assert dev.read_available() == data[::-1]
            assert host.read_available() == data
    for end in (plain_dev, plain_host, timed_dev, timed_host):
        end.close()
    for name in ("spinal.device_tx.bin", "spinal.host_tx.bin"):
        plain = (tmp_path / "plain" / name).read_bytes()
        assert (tmp_path / "timed" / name).read_bytes() == plain
        assert not index_path(tmp_path / "plain" / name).exists()
        index = read_capture_index(tmp_path / "timed" / name)
        assert len(index.ends) == 30
        assert index.times_ns == tuple(k * 1_000_000 for k in range(30))


def test_write_marked_on_an_untimed_capture_writes_the_bytes(tmp_path):
    dev, host = open_inproc_uart(tmp_path, "x", ".bin")
    assert isinstance(dev, TappedLink)
    assert dev.write_marked(b"abcdef", [(0.1, 3), (0.2, 6)]) == 6
    assert host.read_available() == b"abcdef"
    dev.close()
    assert (tmp_path / "x.device_tx.bin").read_bytes() == b"abcdef"


def _random_marks(rng, base_shift: int, n: int) -> list[tuple[float, int]]:
    marks = []
    for _ in range(int(rng.integers(0, 14))):
        kind = rng.random()
        if kind < 0.05:
            t = math.nan
        elif kind < 0.08:
            t = math.inf
        else:
            t = float(rng.uniform(-1.0, 50.0))  # also times that step back
        marks.append((t, int(rng.integers(-5, n + 10)) + base_shift))
    return sorted(marks, key=lambda m: m[1]) if rng.random() < 0.8 else marks


#: SHA-256 of the index the random batches below write: the records the format's rule gives
#: (module text of rdm.link.capture_index), held as golden bytes.
RANDOM_BATCHES_INDEX_SHA256 = "e37345738c53fbf9fd00d8a2b8ba8cc16905d88eb62840a18fd0b6d81d2e322e"


def test_random_batches_write_the_golden_index(tmp_path):
    rng = np.random.default_rng(7)
    clock_t = [0.0]
    f = TimedCaptureFile(tmp_path / "cap.bin", lambda: clock_t[0])
    for _ in range(3000):
        n = int(rng.integers(1, 40))
        clock_t[0] = float(rng.uniform(0.0, 60.0))
        staged = None
        if rng.random() < 0.7:
            base = f._end - int(rng.integers(0, 20))  # marks staged before earlier writes
            staged = (base, _random_marks(rng, f._end - base, n))
        f._staged = staged
        f.write(bytes(n))
        f._staged = None
    f.close()
    written = (tmp_path / "cap.bin.idx").read_bytes()
    assert hashlib.sha256(written).hexdigest() == RANDOM_BATCHES_INDEX_SHA256
    assert len(written) > 16 * 3000  # marks split many writes into several records
    read_capture_index(tmp_path / "cap.bin")  # ordered, and covers the capture


def test_the_records_of_one_write_worked_by_hand():
    # 10 bytes at offset 5 after a record at 1 us; the clock on a microsecond tie (2.0000005 s
    # rounds to even: 2 000 000 us).
    clock = lambda: 2.0000005  # noqa: E731
    rec = struct.Struct("<qQ").pack
    # no marks: the clock's time for all 10 bytes
    assert capture_index_records(5, 10, None, clock, 1_000) == (rec(2_000_000_000, 15), 2 * 10**9)
    # a mark ending before the write (skipped), then one without a time: the clock's
    staged = (0, [(1.5e-6, 3), (math.nan, 9)])
    assert capture_index_records(5, 10, staged, clock, 1_000) == (rec(2 * 10**9, 15), 2 * 10**9)
    # a mark ending at the write's start (skipped), then one past its end: its time for all
    staged = (4, [(0.0000025, 1), (3.0, 50)])
    assert capture_index_records(5, 10, staged, clock, 1_000) == (rec(3 * 10**9, 15), 3 * 10**9)
    # a clock that cannot be a time: the same errors as Python's round, nothing written
    with pytest.raises(ValueError, match="NaN"):
        capture_index_records(0, 4, None, lambda: math.nan, 0)
    with pytest.raises(OverflowError):
        capture_index_records(0, 4, None, lambda: math.inf, 0)
    with pytest.raises(OverflowError, match="int64"):
        capture_index_records(0, 4, None, lambda: 1e13, 0)
    called = []
    assert capture_index_records(0, 4, (0, [(1.0, 4)]), lambda: called.append(1), 0)[1] == (
        1_000_000_000
    )
    assert not called  # the marks covered every byte: no clock read
