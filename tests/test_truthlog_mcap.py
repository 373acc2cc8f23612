"""The run logger's MCAP files against the ``mcap`` package: every call the logger makes of its
writer (:class:`rdm.sim.mcap_writer.McapWriter`) is replayed through ``mcap.writer.Writer``
(the JSON records' text by ``json.dumps``) and the two files compared byte for byte; the files
read back with ``mcap.reader``. Also: chunks closed on the worker thread, a failed chunk, and
``McapChunkBatch``'s records against their layout written out with ``struct``."""

from __future__ import annotations

import dataclasses
import io
import json
import math
import struct
from typing import Any

import numpy as np
import pytest
import zstandard
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from rdm._rdm import McapChunkBatch
from rdm.plant import Plant
from rdm.plant.truth import GroundTruth
from rdm.protocol.rosserial.registry import spinal_registry
from rdm.sim import McapLogger


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


def _plain(v: Any) -> Any:
    """A record value as plain JSON values (NaN and infinities as None)."""
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


class _Recording:
    """The logger's writer, every call recorded (a flat record's text by ``json.dumps``)."""

    def __init__(self, writer: Any) -> None:
        self.writer = writer
        self.calls: list[tuple] = []

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        self.calls.append(("schema", name, encoding, data))
        return self.writer.register_schema(name=name, encoding=encoding, data=data)

    def register_channel(self, topic, message_encoding, schema_id, metadata=None) -> int:
        self.calls.append(("channel", topic, message_encoding, schema_id, dict(metadata or {})))
        return self.writer.register_channel(topic, message_encoding, schema_id, metadata)

    def add_message(self, channel_id: int, time_ns: int, sequence: int, data: bytes) -> None:
        self.writer.add_message(channel_id, time_ns, sequence, data)
        self.calls.append(("message", channel_id, time_ns, sequence, bytes(data)))

    def _json(self, channel_id, time_ns, sequence, values) -> None:
        text = json.dumps(_plain(dict(values)), separators=(",", ":")).encode()
        self.calls.append(("message", channel_id, time_ns, sequence, text))

    def add_record(self, channel_id, time_ns, sequence, values) -> bool:
        taken = self.writer.add_record(channel_id, time_ns, sequence, values)
        if taken:
            self._json(channel_id, time_ns, sequence, values)
        return taken

    def add_fields(self, channel_id, time_ns, sequence, attributes, keys) -> bool:
        taken = self.writer.add_fields(channel_id, time_ns, sequence, attributes, keys)
        if taken:
            self._json(channel_id, time_ns, sequence, {k: attributes[k] for k in keys})
        return taken

    def finish(self) -> None:
        self.writer.finish()


def _replayed(calls: list[tuple], chunk_size: int, compression: CompressionType) -> bytes:
    """The file ``mcap.writer.Writer`` writes for the recorded calls."""
    out = io.BytesIO()
    w = Writer(out, chunk_size=chunk_size, compression=compression)
    w.start(profile="ros1", library="rdm")
    for call in calls:
        if call[0] == "schema":
            w.register_schema(name=call[1], encoding=call[2], data=call[3])
        elif call[0] == "channel":
            w.register_channel(
                topic=call[1], message_encoding=call[2], schema_id=call[3], metadata=call[4]
            )
        else:
            _, cid, ns, seq, data = call
            w.add_message(channel_id=cid, log_time=ns, publish_time=ns, sequence=seq, data=data)
    w.finish()
    return out.getvalue()


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


def _write(path, chunk_size: int, compression: CompressionType, seed: int) -> tuple:
    """Log a random mix of records; (the file, the recorded writer calls, the counters)."""
    rng = np.random.default_rng(seed)
    truths = _truths(60)
    imu = spinal_registry().msg("spinal/Imu")
    with McapLogger(path, chunk_size=chunk_size, compression=compression) as log:
        recording = log._writer = _Recording(log._writer)
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
                # outside the flat form (a nested dict, numpy ints): json.dumps writes it
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
                log.log_ros1("/late_imu", "spinal/Imu", 0.25 * t, imu.new(acc=[1.0, 2.0, 3.0]))
        with pytest.raises(ValueError):
            log.log_json("/x/y", -1.0, {"t": -1.0})
        with pytest.raises(ValueError):
            log.log_truth(dataclasses.replace(truths[0], time=float("nan")))
        counters = (log.messages, dict(log._seq))
    return path.read_bytes(), recording.calls, counters


@pytest.mark.parametrize(
    ("chunk_size", "compression"),
    [
        (64 * 1024, CompressionType.ZSTD),
        (4000, CompressionType.ZSTD),
        (700, CompressionType.LZ4),
        (1, CompressionType.NONE),
    ],
)
def test_the_file_is_the_mcap_packages_for_the_same_calls(tmp_path, chunk_size, compression):
    data, calls, (messages, seqs) = _write(tmp_path / "x.mcap", chunk_size, compression, 7)
    assert data == _replayed(calls, chunk_size, compression)
    sent = [c for c in calls if c[0] == "message"]
    assert len(sent) == messages == sum(seqs.values()) == 700 + 100 + 2
    with open(tmp_path / "x.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        msgs = list(reader.iter_messages(log_time_order=False))
    assert summary is not None and summary.statistics.message_count == len(msgs) == messages
    assert [m.data for _, _, m in msgs] == [c[4] for c in sent]
    if chunk_size == 4000:
        assert summary.statistics.chunk_count > 20


def test_a_time_beyond_uint64_is_refused_and_the_file_stays_whole(tmp_path):
    log = McapLogger(tmp_path / "x.mcap")
    log.log_json("/x", 1.0, {"t": 1.0})
    log.log_truth(_truths(1)[0])
    with pytest.raises(ValueError, match="time"):
        log.log_json("/x", 2e10, {"t": 1.0})  # 2e19 ns
    log.finish()
    assert log.messages == 2 and log._seq == {1: 1, 2: 1}
    with open(tmp_path / "x.mcap", "rb") as f:
        assert len(list(make_reader(f).iter_messages())) == 2


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


def test_a_failed_chunk_is_raised_and_stops_the_file(tmp_path):
    log = McapLogger(tmp_path / "x.mcap", chunk_size=500)
    writer = log._writer
    failing = _FailingFile(3000)
    writer._stream = failing  # the chunks are written on the worker thread
    with pytest.raises(OSError, match="disk full"):
        for k in range(400):
            log.log_json("/x", k * 0.01, {"t": k * 0.01, "v": list(np.arange(20.0))})
            if k % 50 == 0:
                writer._drain()
    written = failing.written
    with pytest.raises(OSError, match="disk full"):
        writer._drain()  # the error stays: no later chunk is written
    assert failing.written == written
    with pytest.raises(OSError, match="disk full"):
        log.finish()


def test_chunk_batch_adds_declines_and_hands_over():
    b = McapChunkBatch(100)
    assert b.take() is None and len(b) == 0
    assert b.add(1, 0, 5, b"ab") == 1
    assert b.add(1, 0, 5, bytearray(b"ab")) == 0  # not bytes
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
