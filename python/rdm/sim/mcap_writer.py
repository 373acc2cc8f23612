"""An MCAP file writer: the chunks' message records built in Rust, the other records by the
``mcap`` package's record classes.

:class:`McapWriter` lays a file out as ``mcap.writer.Writer`` does with its defaults (chunked;
schemas and channels written into the open chunk; message, chunk, attachment and metadata
indexes; schemas, channels and statistics repeated in the summary; summary offsets; the
summary CRC and no data-section CRC): the same calls give the same bytes
(tests/test_truthlog_mcap.py writes the same messages through both). A message record and its
index entry are appended by ``rdm._rdm.McapChunkBatch`` (``rdm_core::sim::mcap_chunk``) in one
call, a flat JSON record encoded straight into it (``add_record``, ``add_fields``). A chunk
closes once its records pass ``chunk_size`` bytes; it is compressed (zstd level 3, lz4 or
none) and written with its MessageIndex records on one worker thread while the caller goes on
(compression and CRC release the GIL); chunks are written in order and :meth:`finish` waits
for them.
"""

from __future__ import annotations

import importlib.util
import struct
import zlib
from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from itertools import chain
from typing import Any, BinaryIO

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import MCAP0_MAGIC, CompressionType

from rdm._rdm import McapChunkBatch

#: ``McapChunkBatch`` add results: declined (nothing added); added and the chunk full.
_DECLINED, _FULL = 0, 2

#: MessageIndex record head: opcode, record length, channel id, records length.
_INDEX_HEAD = "<BQHI"


def _message_index(channel_id: int, records: list[tuple[int, int]]) -> bytes:
    """A MessageIndex record (opcode, length, channel, records length, then (time, offset)
    pairs as u64) in one ``struct.pack``."""
    n = len(records)
    return struct.pack(
        f"{_INDEX_HEAD}{2 * n}Q",
        Opcode.MESSAGE_INDEX,
        2 + 4 + 16 * n,
        channel_id,
        16 * n,
        *chain.from_iterable(records),
    )


class McapWriter:
    """Write an MCAP file to ``stream`` (opened for binary writing, positioned at 0): call
    :meth:`start`, register schemas and channels, add messages, then :meth:`finish` (it does
    not close ``stream``). Used from one thread."""

    def __init__(
        self,
        stream: BinaryIO,
        *,
        chunk_size: int,
        compression: CompressionType = CompressionType.ZSTD,
    ) -> None:
        if compression not in (CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE):
            raise ValueError(f"McapWriter: compression {compression!r} is not a CompressionType")
        if compression == CompressionType.LZ4 and importlib.util.find_spec("lz4") is None:
            raise ValueError("McapWriter: compression LZ4 needs the lz4 package")
        self._stream = stream
        self._chunk_size = chunk_size
        self._compression = compression
        self._batch = McapChunkBatch(chunk_size)
        # the open chunk: records handed over from the batch or written here, its messages,
        # time range and per-channel (time, offset) index in the order of first message
        self._chunk = bytearray()
        self._chunk_messages = 0
        self._chunk_start = 0
        self._chunk_end = 0
        self._chunk_index: dict[int, list[tuple[int, int]]] = {}
        # the file
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._chunk_count = 0
        self._message_count = 0
        self._message_start = 0
        self._message_end = 0
        self._channel_counts: dict[int, int] = {}
        # chunks in flight
        self._compressor: Any = None
        self._executor: ThreadPoolExecutor | None = None
        self._jobs: list[Future] = []
        self._failed: BaseException | None = None

    # ------------------------------------------------------------------ records
    def start(self, profile: str = "", library: str = "") -> None:
        """The magic and the Header record."""
        builder = RecordBuilder()
        Header(profile, library).write(builder)
        self._stream.write(MCAP0_MAGIC)
        self._stream.write(builder.end())

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A Schema record into the open chunk; its id (1, 2, ...)."""
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._into_chunk(schema)
        return schema.id

    def register_channel(
        self,
        topic: str,
        message_encoding: str,
        schema_id: int,
        metadata: Mapping[str, str] | None = None,
    ) -> int:
        """A Channel record into the open chunk; its id (1, 2, ...)."""
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._channels.append(channel)
        self._into_chunk(channel)
        return channel.id

    def add_message(self, channel_id: int, time_ns: int, sequence: int, data: bytes) -> None:
        """A Message record with ``log_time == publish_time == time_ns``."""
        if type(data) is not bytes:
            data = bytes(data)
        if not self._after(self._batch.add(channel_id, sequence, time_ns, data)):
            raise ValueError(
                f"McapWriter: channel id {channel_id!r} must be in 0..65535, sequence "
                f"{sequence!r} in 0..4294967295 and time {time_ns!r} ns in 0..2**64-1"
            )

    def add_record(
        self, channel_id: int, time_ns: int, sequence: int, values: Mapping[str, Any]
    ) -> bool:
        """A Message record whose data is the flat record ``values`` as compact
        ``json.dumps`` text (NaN and infinities as null); False (nothing written) when
        ``values`` is not a dict of str keys and None, bool, int, float, str, 1-D float64
        arrays or lists of floats."""
        return self._after(self._batch.add_record(channel_id, sequence, time_ns, values))

    def add_fields(
        self,
        channel_id: int,
        time_ns: int,
        sequence: int,
        attributes: dict[str, Any],
        keys: tuple[str, ...],
    ) -> bool:
        """:meth:`add_record` of ``{k: attributes[k] for k in keys}`` (an instance
        ``__dict__`` and its field names) without building the dict."""
        code = self._batch.add_fields(channel_id, sequence, time_ns, attributes, keys)
        return self._after(code)

    def _after(self, code: int) -> bool:
        """True when the batch took the message (a full chunk then closed), False when it
        declined it (nothing written)."""
        if code == _FULL:
            self._take()
            self._close_chunk()
            self._batch.set_base(len(self._chunk))
        return code != _DECLINED

    def _into_chunk(self, record: Any) -> None:
        """A record written into the open chunk after the pending messages; a chunk past its
        size closes (when it holds a message)."""
        self._take()
        builder = RecordBuilder()
        record.write(builder)
        self._chunk += builder.end()
        if len(self._chunk) > self._chunk_size:
            self._close_chunk()
        self._batch.set_base(len(self._chunk))

    def _take(self) -> None:
        """The batch's pending messages into the open chunk and the file's statistics."""
        taken = self._batch.take()
        if taken is None:
            return
        data, n, first, last, channels = taken
        if self._message_count == 0:
            self._message_start = first
        else:
            self._message_start = min(first, self._message_start)
        self._message_end = max(last, self._message_end)
        self._message_count += n
        counts = self._channel_counts
        index = self._chunk_index
        for channel_id, records in channels:
            counts[channel_id] = counts.get(channel_id, 0) + len(records)
            known = index.get(channel_id)
            if known is None:
                index[channel_id] = records
            else:
                known.extend(records)
        if self._chunk_messages == 0:
            self._chunk_start = first
        else:
            self._chunk_start = min(first, self._chunk_start)
        self._chunk_end = max(last, self._chunk_end)
        self._chunk_messages += n
        self._chunk += data

    # ------------------------------------------------------------------ chunks
    def _close_chunk(self) -> None:
        """The open chunk handed to the worker and a new one opened; a chunk without a
        message stays open."""
        if self._chunk_messages == 0:
            return
        self._chunk_count += 1
        job = (
            bytes(self._chunk),
            self._chunk_start,
            self._chunk_end,
            list(self._chunk_index.items()),
        )
        self._chunk = bytearray()
        self._chunk_messages = self._chunk_start = self._chunk_end = 0
        self._chunk_index = {}
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

    def _compress(self, data: bytes) -> tuple[str, bytes]:
        if self._compression == CompressionType.ZSTD:
            if self._compressor is None:
                import zstandard

                # ``zstandard.compress(data)`` is ``ZstdCompressor(level=3).compress(data)``
                # (its documentation): one compressor kept instead of one per chunk.
                self._compressor = zstandard.ZstdCompressor(level=3)
            return "zstd", self._compressor.compress(data)
        if self._compression == CompressionType.LZ4:
            import lz4.frame

            return "lz4", lz4.frame.compress(data)
        return "", data

    def _write_chunk(
        self, data: bytes, start: int, end: int, index: list[tuple[int, list[tuple[int, int]]]]
    ) -> None:
        """The Chunk record, then the chunk's MessageIndex records; its ChunkIndex kept."""
        name, compressed = self._compress(data)
        builder = RecordBuilder()
        Chunk(
            compression=name,
            data=compressed,
            message_start_time=start,
            message_end_time=end,
            uncompressed_crc=zlib.crc32(data),
            uncompressed_size=len(data),
        ).write(builder)
        stream = self._stream
        chunk_start = stream.tell()
        chunk_length = builder.count
        stream.write(builder.end())
        index_start = chunk_start + chunk_length
        offsets: dict[int, int] = {}
        parts = []
        length = 0
        for channel_id, records in index:
            offsets[channel_id] = index_start + length
            part = _message_index(channel_id, records)
            parts.append(part)
            length += len(part)
        stream.write(b"".join(parts))
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_start,
                chunk_length=chunk_length,
                message_index_offsets=offsets,
                message_index_length=length,
                compression=name,
                compressed_size=len(compressed),
                uncompressed_size=len(data),
            )
        )

    def _drain(self) -> None:
        """Wait for the chunks in flight; raise the first error of one."""
        jobs, self._jobs = self._jobs, []
        for job in jobs:
            job.result()
        if self._failed is not None:
            raise self._failed

    # ------------------------------------------------------------------ end
    def finish(self) -> None:
        """The last chunk, DataEnd, the summary, the Footer and the closing magic."""
        try:
            self._take()
            self._close_chunk()
            self._drain()
        finally:
            if self._executor is not None:
                self._executor.shutdown(wait=True)
                self._executor = None
        stream = self._stream
        builder = RecordBuilder()
        DataEnd(0).write(builder)
        stream.write(builder.end())
        summary_start = stream.tell()
        summary = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: list[Any]) -> None:
            begin = summary.count
            for r in records:
                r.write(summary)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + begin,
                    group_length=summary.count - begin,
                )
            )

        statistics = Statistics(
            attachment_count=0,
            channel_count=len(self._channels),
            channel_message_counts=self._channel_counts,
            chunk_count=self._chunk_count,
            message_count=self._message_count,
            message_end_time=self._message_end,
            message_start_time=self._message_start,
            metadata_count=0,
            schema_count=len(self._schemas),
        )
        group(Opcode.SCHEMA, self._schemas)
        group(Opcode.CHANNEL, self._channels)
        group(Opcode.STATISTICS, [statistics])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, [])
        group(Opcode.METADATA_INDEX, [])
        offset_start = summary_start + summary.count
        for o in offsets:
            o.write(summary)
        data = summary.end()
        crc = zlib.crc32(data)
        crc = zlib.crc32(
            struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, offset_start), crc
        )
        stream.write(data)
        Footer(
            summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc
        ).write(builder)
        stream.write(builder.end())
        stream.write(MCAP0_MAGIC)
