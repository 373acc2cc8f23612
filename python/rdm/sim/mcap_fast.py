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
from typing import Any

import mcap
from mcap.records import MessageIndex
from mcap.writer import Writer

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
