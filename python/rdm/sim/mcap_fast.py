"""Message records into an ``mcap`` Writer's open chunk, with fewer Python calls.

``mcap.writer.Writer.add_message`` builds a ``Message`` dataclass, updates the file statistics
and the chunk's message index, then writes the record through six ``RecordBuilder`` calls (a
placeholder length, a seek back, the real length). :class:`ChunkMessageWriter` does the same
bookkeeping on the same objects and writes the record with one ``struct.pack`` and the data:
the file is byte-identical (tests/test_sampler_fast_paths.py compares whole files). It reaches
into the writer's private state, so it is used only with the ``mcap`` releases it was checked
against (``VERIFIED_MCAP``, by the whole-file test); with any other release, or when that state
is not there, or the writer does not chunk, :func:`chunk_message_writer` returns None and the
caller keeps ``Writer.add_message``.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from itertools import chain
from typing import Any

import mcap
import mcap.writer as mcap_writer
from mcap.records import Chunk, ChunkIndex, MessageIndex
from mcap.writer import CompressionType, IndexType, Writer

from rdm._rdm import McapChunkBatch

#: ``mcap`` releases (major.minor) whose writer internals this module mirrors; checked by the
#: whole-file comparison in tests/test_sampler_fast_paths.py. Add one only after that test.
VERIFIED_MCAP = ("1.6",)

#: Opcode, record length, channel id, sequence, log time, publish time (MCAP Message record).
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_OPCODE = 0x05
#: Bytes of a Message record's fields before its data.
_MESSAGE_FIELDS = 2 + 4 + 8 + 8


class ChunkMessageWriter:
    """``Writer.add_message`` for a chunking writer, the same bytes and bookkeeping."""

    __slots__ = ("_chunk", "_chunk_size", "_finalize", "_plain", "_stats")

    def __init__(self, stats: Any, chunk: Any, chunk_size: int, finalize: Any, plain: Any) -> None:
        self._stats = stats
        self._chunk = chunk
        self._chunk_size = chunk_size
        self._finalize = finalize
        self._plain = plain

    def add(self, channel_id: int, time_ns: int, sequence: int, data: bytes) -> None:
        """One message with ``log_time == publish_time == time_ns``."""
        try:
            head = _MESSAGE_HEAD.pack(
                _MESSAGE_OPCODE, _MESSAGE_FIELDS + len(data), channel_id, sequence, time_ns, time_ns
            )
        except struct.error:
            # A field out of range: the library's own path, which leaves the state (and the
            # error) exactly as it does.
            self._plain(
                channel_id=channel_id,
                log_time=time_ns,
                publish_time=time_ns,
                sequence=sequence,
                data=data,
            )
            return
        stats = self._stats
        if stats.message_count == 0:
            stats.message_start_time = time_ns
        else:
            stats.message_start_time = min(time_ns, stats.message_start_time)
        stats.message_end_time = max(time_ns, stats.message_end_time)
        stats.channel_message_counts[channel_id] += 1
        stats.message_count += 1
        chunk = self._chunk
        if chunk.num_messages == 0:
            chunk.message_start_time = time_ns
        else:
            chunk.message_start_time = min(chunk.message_start_time, time_ns)
        chunk.message_end_time = max(chunk.message_end_time, time_ns)
        index = chunk.message_indices.get(channel_id)
        if index is None:
            index = chunk.message_indices[channel_id] = MessageIndex(
                channel_id=channel_id, records=[]
            )
        buffer = chunk.record_writer._buffer  # replaced by each finished chunk: read it now
        index.records.append((time_ns, buffer.tell()))
        chunk.num_messages += 1
        buffer.write(head)
        buffer.write(data)
        if buffer.tell() > self._chunk_size:
            self._finalize()


def chunk_message_writer(writer: Writer) -> ChunkMessageWriter | None:
    """The fast message writer of ``writer``, or None (no chunking, an unverified ``mcap``)."""
    version = getattr(mcap, "__version__", "")
    if ".".join(version.split(".")[:2]) not in VERIFIED_MCAP:
        return None
    stats = getattr(writer, "_Writer__statistics", None)
    chunk = getattr(writer, "_Writer__chunk_builder", None)
    size = getattr(writer, "_Writer__chunk_size", None)
    finalize = getattr(writer, "_Writer__maybe_finalize_chunk", None)
    if stats is None or chunk is None or not isinstance(size, int) or finalize is None:
        return None
    needed = ("num_messages", "message_indices", "message_start_time", "record_writer")
    if not all(hasattr(chunk, a) for a in needed):
        return None
    if not hasattr(chunk.record_writer, "_buffer"):
        return None
    if not hasattr(stats, "channel_message_counts"):
        return None
    # ``finalize``: the writer's own size check and chunk write (it rechecks the size).
    return ChunkMessageWriter(stats, chunk, size, finalize, writer.add_message)


# ------------------------------------------------------------------ native message batches
#: MessageIndex record head: opcode, record length, channel id, records length.
_INDEX_HEAD = "<BQHI"
_INDEX_OPCODE = 0x07


def _write_message_index(builder: Any, channel_id: int, records: list[tuple[int, int]]) -> None:
    """``MessageIndex(channel_id, records).write(builder)`` in one ``struct.pack`` (the same
    bytes: opcode, length, channel, records length, then (time, offset) pairs as u64)."""
    n = len(records)
    builder.write(
        struct.pack(
            f"{_INDEX_HEAD}{2 * n}Q",
            _INDEX_OPCODE,
            2 + 4 + 16 * n,
            channel_id,
            16 * n,
            *chain.from_iterable(records),
        )
    )


class ChunkBatchWriter:
    """``Writer.add_message`` for a chunking writer with the chunk's message records built in
    Rust (:class:`rdm._rdm.McapChunkBatch`): one call per message, JSON records encoded
    straight into the chunk. The batch goes to the library's chunk builder (bytes, message
    index entries, chunk and file statistics, in message order) before the library writes
    anything else into that chunk (:meth:`outside`) and when the chunk is full; the chunk is
    then closed by :meth:`_close_chunk`, the library's ``__finalize_chunk`` step for step, on
    this thread or, with ``background``, on one worker thread (compression and CRC release
    the GIL) while the caller goes on: chunks are written in order and :meth:`drain` (called
    by :meth:`outside` and before the writer finishes) waits for them. The file is
    byte-identical with ``Writer.add_message`` (tests/test_truthlog_mcap.py)."""

    def __init__(
        self, writer: Writer, stats: Any, chunk: Any, chunk_size: int, background: bool
    ) -> None:
        self.core = McapChunkBatch(chunk_size)
        self._writer = writer
        self._stats = stats
        self._chunk = chunk
        self._chunk_size = chunk_size
        self._plain = writer.add_message
        self._flush = writer._Writer__flush  # type: ignore[attr-defined]
        self._record_builder = writer._Writer__record_builder  # type: ignore[attr-defined]
        self._stream = writer._Writer__stream  # type: ignore[attr-defined]
        self._chunk_indices = writer._Writer__chunk_indices  # type: ignore[attr-defined]
        self._compression = writer._Writer__compression  # type: ignore[attr-defined]
        self._crcs = writer._Writer__enable_crcs  # type: ignore[attr-defined]
        self._message_index = bool(
            writer._Writer__index_types & IndexType.MESSAGE  # type: ignore[attr-defined]
        )
        self.background = background
        self._zstd: Any = None
        self._executor: ThreadPoolExecutor | None = None
        self._jobs: list[Future] = []
        self._failed: BaseException | None = None
        self.core.set_base(chunk.count)

    # ------------------------------------------------------------------ messages
    def add(self, channel_id: int, time_ns: int, sequence: int, data: bytes) -> None:
        """One message with ``log_time == publish_time == time_ns``."""
        code = self.core.add(channel_id, sequence, time_ns, data)
        if code != 1:
            self.after(code, channel_id, time_ns, sequence, data)

    def after(self, code: int, channel_id: int, time_ns: int, sequence: int, data: Any) -> None:
        """What an add's code asks for: 2 closes the full chunk; 0 (declined: a field out
        of the record's range, data not bytes) writes the message on the library's path."""
        if code == 2:
            self.sync()
            if self._chunk.count > self._chunk_size:
                self._close_chunk()
            self.core.set_base(self._chunk.count)
            return
        with self.outside():
            self._plain(
                channel_id=channel_id,
                log_time=time_ns,
                publish_time=time_ns,
                sequence=sequence,
                data=data,
            )

    def sync(self) -> None:
        """Hand the pending messages to the library's chunk builder (what ``add_message``
        would have done to it, message by message)."""
        batch = self.core.take()
        if batch is None:
            return
        data, n, first, last, channels = batch
        stats = self._stats
        if stats.message_count == 0:
            stats.message_start_time = first
        else:
            stats.message_start_time = min(first, stats.message_start_time)
        stats.message_end_time = max(last, stats.message_end_time)
        counts = stats.channel_message_counts
        chunk = self._chunk
        indices = chunk.message_indices
        for channel_id, records in channels:
            counts[channel_id] += len(records)
            index = indices.get(channel_id)
            if index is None:
                index = indices[channel_id] = MessageIndex(channel_id=channel_id, records=[])
            index.records.extend(records)
        stats.message_count += n
        if chunk.num_messages == 0:
            chunk.message_start_time = first
        else:
            chunk.message_start_time = min(chunk.message_start_time, first)
        chunk.message_end_time = max(chunk.message_end_time, last)
        chunk.num_messages += n
        chunk.record_writer._buffer.write(data)

    @contextmanager
    def outside(self) -> Iterator[None]:
        """Around a call of the writer's own (a schema, a channel, a message on the library's
        path, ``finish``): the chunks in flight written, the batch handed over before, the
        chunk buffer's size read back after."""
        self.drain()
        self.sync()
        try:
            yield
        finally:
            self.core.set_base(self._chunk.count)

    # ------------------------------------------------------------------ chunks
    def _close_chunk(self) -> None:
        """``Writer.__finalize_chunk``: the chunk's records and index taken from the builder
        here, compressed and written by :meth:`_write_chunk` (here or on the worker)."""
        chunk = self._chunk
        if chunk.num_messages == 0:
            return
        self._stats.chunk_count += 1
        job = (
            chunk.end(),
            chunk.message_start_time,
            chunk.message_end_time,
            list(chunk.message_indices.items()),
        )
        chunk.reset()
        if not self.background:
            self._write_chunk(*job)
            return
        if self._failed is not None:
            raise self._failed
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcap-chunk")
        self._jobs = [f for f in self._jobs if not f.done() or f.exception() is not None]
        self._jobs.append(self._executor.submit(self._write_chunk_job, job))

    def _write_chunk_job(self, job: tuple) -> None:
        if self._failed is not None:
            return  # a chunk before this one failed: the file stops there
        try:
            self._write_chunk(*job)
        except BaseException as e:
            self._failed = e
            raise

    def _write_chunk(
        self, chunk_data: bytes, start: int, end: int, indices: list[tuple[int, Any]]
    ) -> None:
        """The rest of ``Writer.__finalize_chunk`` (mcap 1.6): compress, the Chunk record,
        its ChunkIndex, the chunk's MessageIndex records, each group flushed to the file."""
        compression = self._compression
        if compression == CompressionType.LZ4:
            name = "lz4"
            compressed = mcap_writer.lz4.frame.compress(chunk_data)
        elif compression == CompressionType.ZSTD:
            name = "zstd"
            # ``zstandard.compress(data)`` is ``ZstdCompressor(level=3).compress(data)``
            # (its documentation; the same bytes, tests/test_truthlog_mcap.py): one
            # compressor kept instead of a new context per chunk.
            if self._zstd is None:
                self._zstd = mcap_writer.zstandard.ZstdCompressor(level=3)
            compressed = self._zstd.compress(chunk_data)
        else:
            name = ""
            compressed = chunk_data
        chunk = Chunk(
            compression=name,
            data=compressed,
            message_start_time=start,
            message_end_time=end,
            uncompressed_crc=zlib.crc32(chunk_data) if self._crcs else 0,
            uncompressed_size=len(chunk_data),
        )
        builder = self._record_builder
        self._flush()
        chunk_start_offset = self._stream.tell()
        chunk.write(builder)
        chunk_index = ChunkIndex(
            message_start_time=start,
            message_end_time=end,
            chunk_start_offset=chunk_start_offset,
            chunk_length=builder.count,
            message_index_offsets={},
            message_index_length=0,
            compression=name,
            compressed_size=len(compressed),
            uncompressed_size=len(chunk_data),
        )
        self._flush()
        index_start = self._stream.tell()
        if self._message_index:
            offsets = chunk_index.message_index_offsets
            for channel_id, index in indices:
                offsets[channel_id] = index_start + builder.count
                _write_message_index(builder, index.channel_id, index.records)
        chunk_index.message_index_length = builder.count
        self._flush()
        self._chunk_indices.append(chunk_index)

    def drain(self) -> None:
        """Wait for the chunks in flight; raise the first error of one."""
        jobs, self._jobs = self._jobs, []
        for job in jobs:
            job.result()
        if self._failed is not None:
            raise self._failed

    def close(self) -> None:
        """Stop the worker (after :meth:`drain`)."""
        if self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None


def chunk_batch_writer(writer: Writer, background: bool = False) -> ChunkBatchWriter | None:
    """The native message writer of ``writer``, or None (no chunking, an unverified
    ``mcap``, or the writer's private state not as :class:`ChunkBatchWriter` needs it)."""
    if chunk_message_writer(writer) is None:
        return None
    needed = (
        "_Writer__flush",
        "_Writer__record_builder",
        "_Writer__stream",
        "_Writer__chunk_indices",
        "_Writer__compression",
        "_Writer__enable_crcs",
        "_Writer__index_types",
    )
    if not all(hasattr(writer, a) for a in needed):
        return None
    chunk = writer._Writer__chunk_builder  # type: ignore[attr-defined]
    if not hasattr(chunk, "reset") or not hasattr(chunk, "end"):
        return None
    return ChunkBatchWriter(
        writer,
        writer._Writer__statistics,  # type: ignore[attr-defined]
        chunk,
        writer._Writer__chunk_size,  # type: ignore[attr-defined]
        background,
    )
