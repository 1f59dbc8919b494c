"""Append message records to an ``mcap`` :class:`~mcap.writer.Writer`'s open chunk, fast.

``Writer.add_message`` costs ~15 µs a message in Python (a ``Message`` dataclass, a dozen small
``struct.pack`` and ``BytesIO`` calls per record, and as many again per message-index entry when
the chunk closes); the archive writes every received block, 8000 a second at 200 mills. This
appender produces the same bytes (MCAP spec: Message record, opcode 0x05 —
``channel_id u16, sequence u32, log_time u64, publish_time u64, data``; Message Index record,
opcode 0x07 — ``channel_id u16, records length u32, (log_time u64, offset u64)…``) with one
``struct.pack`` and one buffer write per message, one pack per index record, and keeps the
writer's statistics and chunk index exactly as ``add_message`` would. Chunk closing, compression,
summary and footer stay the library's.

It reaches into the writer's private chunk builder and statistics (``mcap`` 1.6); when they are
not where it expects them, :func:`appender` returns None and the caller uses ``add_message``.
"""

from __future__ import annotations

import logging
import struct
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from mcap.opcode import Opcode
from mcap.records import ChunkIndex, MessageIndex
from mcap.writer import Writer

__all__ = ["MessageAppender", "appender", "pack_chunk_indexes"]

log = logging.getLogger(__name__)

_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, then the message fields
_MESSAGE_FIELDS = 22  # bytes of the fields before the data
_OP_MESSAGE = int(Opcode.MESSAGE)  # 0x05
_OP_MESSAGE_INDEX = int(Opcode.MESSAGE_INDEX)  # 0x07
_OP_CHUNK_INDEX = int(Opcode.CHUNK_INDEX)  # 0x08


class _PackedIndex(MessageIndex):
    """A message index whose record is written with one ``struct.pack`` (same bytes)."""

    def write(self, stream: Any) -> None:
        n = len(self.records)
        flat = [v for pair in self.records for v in pair]
        stream.write(struct.pack(f"<BQHI{2 * n}Q", _OP_MESSAGE_INDEX, 6 + 16 * n,
                                 self.channel_id, 16 * n, *flat))  # fmt: skip


class _PackedChunkIndex(ChunkIndex):
    """A chunk index whose record (written in the summary) is packed in one go (same bytes as
    ``ChunkIndex.write``: with hundreds of channels a chunk's index lists hundreds of offsets)."""

    def write(self, stream: Any) -> None:
        offsets = self.message_index_offsets
        compression = self.compression.encode()
        flat = [v for pair in offsets.items() for v in pair]
        body = struct.pack(
            f"<QQQQI{'HQ' * len(offsets)}QI{len(compression)}sQQ",
            self.message_start_time, self.message_end_time, self.chunk_start_offset,
            self.chunk_length, 10 * len(offsets), *flat, self.message_index_length,
            len(compression), compression, self.compressed_size, self.uncompressed_size,
        )  # fmt: skip
        stream.write(struct.pack("<BQ", _OP_CHUNK_INDEX, len(body)) + body)


def pack_chunk_indexes(writer: Writer) -> None:
    """Before ``writer.finish()``: have the chunk indexes written by :class:`_PackedChunkIndex`
    (no-op when this ``mcap`` version keeps them elsewhere)."""
    indexes = getattr(writer, "_Writer__chunk_indices", None)
    if not isinstance(indexes, list):
        return
    for index in indexes:
        if type(index) is ChunkIndex:
            index.__class__ = _PackedChunkIndex


class MessageAppender:
    """``append(channel_id, sequence, log_time_ns, data)`` = ``writer.add_message(channel_id,
    log_time_ns, data, log_time_ns, sequence)``, byte for byte; see the module docstring."""

    def __init__(self, writer: Writer, chunk_size: int) -> None:
        self._writer = writer
        self._stats = writer._Writer__statistics  # type: ignore[attr-defined]  # mcap keeps it private
        self._builder = writer._Writer__chunk_builder  # type: ignore[attr-defined]  # mcap keeps it private
        finalize = writer._Writer__finalize_chunk  # type: ignore[attr-defined]  # mcap keeps it private
        self._finalize: Callable[[], None] = finalize
        self._chunk_size = chunk_size

    def append(self, channel_id: int, sequence: int, log_time_ns: int, data: bytes) -> None:
        stats, builder = self._stats, self._builder
        if stats.message_count == 0 or log_time_ns < stats.message_start_time:
            stats.message_start_time = log_time_ns
        if log_time_ns > stats.message_end_time:
            stats.message_end_time = log_time_ns
        stats.channel_message_counts[channel_id] += 1
        stats.message_count += 1
        if builder.num_messages == 0 or log_time_ns < builder.message_start_time:
            builder.message_start_time = log_time_ns
        if log_time_ns > builder.message_end_time:
            builder.message_end_time = log_time_ns
        buffer = builder.record_writer._buffer
        offset = buffer.tell()
        index = builder.message_indices.get(channel_id)
        if index is None:
            index = builder.message_indices[channel_id] = _PackedIndex(channel_id, [])
        index.records.append((log_time_ns, offset))
        builder.num_messages += 1
        buffer.write(_MESSAGE_HEAD.pack(_OP_MESSAGE, _MESSAGE_FIELDS + len(data), channel_id,
                                        sequence, log_time_ns, log_time_ns))  # fmt: skip
        buffer.write(data)
        if offset + _MESSAGE_HEAD.size + len(data) > self._chunk_size:
            self._finalize()


def appender(writer: Writer, chunk_size: int) -> MessageAppender | None:
    """A fast appender for ``writer`` (chunked, as the archive writes), or None when this
    ``mcap`` version keeps its internals elsewhere (then use ``add_message``)."""
    try:
        fast = MessageAppender(writer, chunk_size)
        fast._builder.record_writer._buffer.tell()
        ok = isinstance(fast._stats.channel_message_counts, defaultdict)
    except AttributeError:
        ok = False
    if not ok:
        log.info("mcap internals not as expected: the archive uses Writer.add_message")
        return None
    return fast
