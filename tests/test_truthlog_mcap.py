"""The MCAP writer's native message path: message records built in Rust
(``McapChunkBatch``) and handed to the ``mcap`` library's chunk builder in batches, JSON records
encoded straight into the chunk, chunks closed here or on a worker thread. Whole files are
compared with the library's own ``Writer.add_message`` path and the Python fast path."""

from __future__ import annotations

import dataclasses
import struct
from typing import Any

import mcap
import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader
from mcap.writer import CompressionType

from rdm._rdm import McapChunkBatch
from rdm.plant import Plant
from rdm.plant.truth import GroundTruth
from rdm.protocol.rosserial.registry import spinal_registry
from rdm.sim import McapLogger
from rdm.sim.mcap_fast import VERIFIED_MCAP, ChunkBatchWriter, ChunkMessageWriter

MODES = {
    "library": {"fast_messages": False},
    "python": {"native_messages": False},
    "native": {"background_chunks": False},
    "background": {},  # the default
}

pytestmark = pytest.mark.skipif(
    ".".join(mcap.__version__.split(".")[:2]) not in VERIFIED_MCAP,
    reason="the fast writers are off on this mcap release",
)


@dataclasses.dataclass(frozen=True)
class _WithProperty:
    t: float
    x: np.ndarray

    @property
    def time(self) -> float:
        return self.t


@dataclasses.dataclass(frozen=True, slots=True)
class _Slotted:
    time: float
    v: np.ndarray


def _truths(n: int) -> list[GroundTruth]:
    plant = Plant("rdm", seed=3, ceiling_height=1.6, floor_height=0.0)
    plant.reset(base_position=(0.0, 0.0, 0.05))
    out = []
    for k in range(n):
        if k == 20:
            plant.set_rotor_thrusts([9.5, 9.5, 9.5, 9.5])
        plant.step(10)
        out.append(plant._ground_truth())
    return out


def _write(path, mode: str, chunk_size: int, compression: CompressionType, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    truths = _truths(60)
    imu = spinal_registry().msg("spinal/Imu")
    with McapLogger(path, chunk_size=chunk_size, compression=compression, **MODES[mode]) as log:
        want = {
            "library": type(None),
            "python": ChunkMessageWriter,
            "native": ChunkBatchWriter,
            "background": ChunkBatchWriter,
        }[mode]
        assert type(log._fast) is want
        t = 0.0
        for k in range(700):
            t += float(rng.choice([0.0, 0.001, 0.0105]))
            kind = k % 7
            if kind == 0:
                gt = truths[k // 7 % len(truths)]
                log.log_truth(dataclasses.replace(gt, time=t))
            elif kind == 1:
                n = int(rng.integers(0, 300))
                values = rng.standard_normal(n)
                values[rng.random(n) < 0.05] = np.nan
                log.log_json("/x/y", t, {"t": t, "v": values, "k": k, "s": "a\u00e9"})
            elif kind == 2:
                # outside the flat form (a nested dict, numpy ints): the general path
                log.log_json("/nested", t, {"t": t, "d": {"a": [1, 2]}, "i": np.int64(k)})
            elif kind == 3:
                log.log_ros1("/imu", "spinal/Imu", t, imu.new(acc=[0.0, 0.1, 9.8]))
            elif kind == 4:
                log.log_ros1("/raw", "spinal/Imu", t, bytearray(imu.encode(imu.new())))
            elif kind == 5:
                log.log_truth(_WithProperty(t, rng.standard_normal(3)), "/prop")
                log.log_truth(_Slotted(t, rng.standard_normal(2)), "/slots")
            else:
                log.log_json("/onboard/status", t, {"t": t, "duties": [0.5, 0.6], "x": None})
            if k == 300:
                log.log_json("/late", 0.5 * t, {"late": True})  # earlier time: min/max
                log.log_ros1("/late_imu", "spinal/Imu", 0.25 * t, imu.new())
        with pytest.raises(ValueError):
            log.log_json("/x/y", -1.0, {"t": -1.0})
        with pytest.raises(ValueError):
            log.log_truth(dataclasses.replace(truths[0], time=float("nan")))
        counters = (log.messages, dict(log._seq))
    return {"bytes": path.read_bytes(), "counters": counters}


@pytest.mark.parametrize(
    ("chunk_size", "compression"),
    [
        (64 * 1024, CompressionType.ZSTD),
        (4000, CompressionType.ZSTD),
        (700, CompressionType.LZ4),
        (1, CompressionType.NONE),
    ],
)
def test_every_writer_path_gives_the_same_file(tmp_path, chunk_size, compression):
    files = {m: _write(tmp_path / f"{m}.mcap", m, chunk_size, compression, 7) for m in MODES}
    ref = files["library"]
    for mode, got in files.items():
        assert got["counters"] == ref["counters"], mode
        assert got["bytes"] == ref["bytes"], mode
    with open(tmp_path / "background.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        msgs = list(reader.iter_messages())
    assert summary.statistics.message_count == len(msgs) == ref["counters"][0]
    if chunk_size == 4000:
        assert summary.statistics.chunk_count > 20


def test_native_time_beyond_uint64_fails_as_the_library(tmp_path):
    counters = []
    for mode in MODES:
        log = McapLogger(tmp_path / f"{mode}.mcap", **MODES[mode])
        log.log_json("/x", 1.0, {"t": 1.0})
        log.log_truth(_truths(1)[0])
        with pytest.raises(struct.error):
            log.log_json("/x", 2e10, {"t": 1.0})
        with pytest.raises(struct.error):
            log.finish()
        counters.append((log.messages, dict(log._seq)))
    assert all(c == counters[0] for c in counters)


def test_reused_zstd_compressor_equals_the_module_function():
    rng = np.random.default_rng(2)
    c = zstandard.ZstdCompressor(level=3)
    chunks = [b"", b"x", rng.bytes(70_000), b"abc" * 30_000]
    chunks += [",".join(map(repr, rng.standard_normal(8000).tolist())).encode()] * 2
    for data in chunks:
        assert c.compress(data) == zstandard.compress(data)


class _FailingFile:
    """A file that fails once more than ``limit`` bytes were written."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.written = 0

    def write(self, data: Any) -> int:
        self.written += len(data)
        if self.written > self.limit:
            raise OSError("disk full")
        return len(data)

    def tell(self) -> int:
        return self.written

    def close(self) -> None:
        pass


def test_a_failed_background_chunk_is_raised_and_stops_the_file(tmp_path):
    log = McapLogger(tmp_path / "x.mcap", chunk_size=500)
    batch = log._batch
    assert batch is not None
    failing = _FailingFile(3000)
    batch._stream = failing
    batch._flush = lambda: failing.write(batch._record_builder.end())
    with pytest.raises(OSError, match="disk full"):
        for k in range(400):
            log.log_json("/x", k * 0.01, {"t": k * 0.01, "v": list(np.arange(20.0))})
            if k % 50 == 0:
                batch.drain()
    written = failing.written
    with pytest.raises(OSError, match="disk full"):
        batch.drain()  # the error stays: no later chunk is written
    assert failing.written == written
    batch.close()
    log._file.close()


def test_chunk_batch_adds_declines_and_hands_over():
    b = McapChunkBatch(100)
    assert b.take() is None and len(b) == 0
    assert b.add(1, 0, 5, b"ab") == 1
    assert b.add(1, 0, 5, bytearray(b"ab")) == 0  # not bytes: the library's path
    assert b.add(70_000, 0, 5, b"") == 0  # channel beyond u16
    assert b.add(1, 2**32, 5, b"") == 0  # sequence beyond u32
    assert b.add(1, 0, 2**64, b"") == 0  # time beyond u64
    assert b.add(1, 0, -1, b"") == 0
    assert b.add(1, 0, 5.0, b"") == 0  # not an int
    assert b.add_record(2, 0, 3, {"a": {"b": 1}}) == 0  # nested
    assert b.add_record(2, 0, 3, [("a", 1.0)]) == 0  # not a dict
    assert b.add_fields(2, 0, 3, {"a": 1.0}, ("a", "b")) == 0  # a missing key
    assert b.add_fields(2, 0, 3, {"a": 1.0}, ["a"]) == 0  # keys not a tuple
    assert len(b) == 1
    assert b.add_fields(2, 7, 3, {"b": True, "a": 1.5}, ("a", "b")) == 1  # 82 bytes
    assert b.add_record(1, 1, 9, {"x": None}) == 2  # 123 > 100: the chunk is full
    data, n, first, last, channels = b.take()
    assert (n, first, last) == (3, 3, 9)
    assert channels == [(1, [(5, 0), (9, 33 + 31 + 18)]), (2, [(3, 33)])]
    text = b'{"a":1.5,"b":true}'
    assert data[33 + 31 :].startswith(text)
    assert data[1:9] == struct.pack("<Q", 22 + 2) and data[-10:] == b'{"x":null}'
    assert data[33 + 9 : 33 + 15] == struct.pack("<HI", 2, 7)
    assert b.next_offset() == len(data) and len(b) == 0 and b.take() is None
    b.set_base(10)
    assert b.add(1, 0, 5, b"") == 1 and b.take()[4] == [(1, [(5, 10)])]
