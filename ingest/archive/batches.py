"""Read the archive as batches of messages held in arrays (for replay at many × real time).

:class:`~millwatch.ingest.archive.reader.TailTolerantReader` yields one Python object per message
(~5 µs each);
replaying an hour of 50 mills is 7.2 million messages. :class:`BatchReader` reads the same files
with the same tolerance (it stops where that reader stops, at the first torn or corrupt record,
and yields exactly the messages that reader yields) but returns each chunk's messages as one
:class:`MessageBatch`: the decompressed chunk bytes and, per message, its file index, channel id,
log time and the payload's offset and length — record boundaries found by a compiled scan
(MCAP spec: records are ``opcode u8, length u64, body``; a Message body is ``channel_id u16,
sequence u32, log_time u64, publish_time u64, data``).

:func:`archive_batches` walks the files of an archive after a checkpoint position, as
:meth:`millwatch.ingest.archive.reader.ArchiveReader.blocks` does, merging consecutive chunks of a
file into batches of at least ``min_messages``.
"""

from __future__ import annotations

import mmap
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zstandard
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Chunk

from millwatch.ingest.archive.batch_kernels import message_heads, pack_ranges, record_bounds
from millwatch.ingest.archive.files import (
    MCAP_MAGIC,
    ArchiveError,
    ArchivePosition,
    archive_file_order,
    list_archive_files,
)
from millwatch.ingest.archive.reader import TailTolerantBase, decompress_chunk

__all__ = ["BatchReader", "MessageBatch", "archive_batches"]

_MESSAGE_HEAD = np.dtype([("channel", "<u2"), ("sequence", "<u4"), ("log_time", "<u8"),
                          ("publish_time", "<u8")])  # fmt: skip
_RECORD_HEAD = 9  # opcode u8 + length u64
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, CRC, compression length
_TOP_LEVEL = np.array([Opcode.CHUNK, Opcode.MESSAGE, Opcode.SCHEMA, Opcode.CHANNEL,
                       Opcode.DATA_END], dtype=np.int64)  # fmt: skip


@dataclass(frozen=True, slots=True)
class MessageBatch:
    """Consecutive messages of one archive file: ``buf`` holds their payloads at
    ``offset[k] : offset[k] + length[k]``; ``index`` is the file order (as
    :class:`~millwatch.ingest.archive.files.ArchivePosition` counts it), ``channel`` the MCAP
    channel id (topic
    in ``topics``), ``log_time`` ns since the Unix epoch (UTC)."""

    file: str
    buf: np.ndarray
    index: np.ndarray
    channel: np.ndarray
    log_time: np.ndarray
    offset: np.ndarray
    length: np.ndarray
    topics: dict[int, str]

    def __len__(self) -> int:
        return int(self.index.shape[0])

    def payload(self, k: int) -> bytes:
        """The raw payload of message ``k`` (a copy)."""
        a = int(self.offset[k])
        return self.buf[a : a + int(self.length[k])].tobytes()

    def select(self, keep: np.ndarray) -> MessageBatch:
        """The messages where the boolean mask ``keep`` is True (same buffer)."""
        return MessageBatch(self.file, self.buf, self.index[keep], self.channel[keep],
                            self.log_time[keep], self.offset[keep], self.length[keep],
                            self.topics)  # fmt: skip

    def compact(self) -> MessageBatch:
        """The same messages with a buffer of only their payloads, back to back (a batch to
        send to another process: :meth:`select` keeps the whole chunk's buffer)."""
        offset = np.zeros(len(self), dtype=np.int64)
        if len(self) > 1:
            np.cumsum(self.length[:-1], out=offset[1:])
        buf = pack_ranges(self.buf, self.offset, self.length, int(self.length.sum()))
        return MessageBatch(self.file, buf, self.index, self.channel, self.log_time, offset,
                            self.length.copy(), self.topics)  # fmt: skip

    @staticmethod
    def concat(batches: list[MessageBatch]) -> MessageBatch:
        """One batch of the messages of ``batches`` (consecutive, one file), in order."""
        if len(batches) == 1:
            return batches[0]
        shifts = np.cumsum([0] + [b.buf.shape[0] for b in batches[:-1]])
        topics: dict[int, str] = {}
        for b in batches:
            topics |= b.topics
        return MessageBatch(
            batches[0].file,
            np.concatenate([b.buf for b in batches]),
            np.concatenate([b.index for b in batches]),
            np.concatenate([b.channel for b in batches]),
            np.concatenate([b.log_time for b in batches]),
            np.concatenate([b.offset + s for b, s in zip(batches, shifts, strict=True)]),
            np.concatenate([b.length for b in batches]),
            topics,
        )


def _scan_from(data: np.ndarray, pos: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(opcode, body start, body length) of the complete records from byte ``pos`` on, and
    the status where the scan stopped: 0 at the end, 1 torn header, 2 torn body."""
    cap = (data.shape[0] - pos) // _RECORD_HEAD + 1
    ops = np.empty(cap, dtype=np.int64)
    starts = np.empty(cap, dtype=np.int64)
    lengths = np.empty(cap, dtype=np.int64)
    n, status = record_bounds(data, pos, ops, starts, lengths)
    return ops[:n], starts[:n], lengths[:n], status


def _scan_records(data: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(opcode, body start, body length) of every record of a chunk's records section;
    :class:`ArchiveError` on a torn record (as the per-message reader raises)."""
    ops, starts, lengths, status = _scan_from(data, 0)
    if status == 1:
        raise ArchiveError("torn record header")
    if status == 2:
        raise ArchiveError("torn record body")
    return ops, starts, lengths


class BatchReader(TailTolerantBase):
    """:class:`~millwatch.ingest.archive.reader.TailTolerantReader` whose :meth:`messages` yields
    one
    :class:`MessageBatch` per chunk (and per unchunked message) instead of one object per
    message; the same messages, the same stopping rules and the same attributes afterwards."""

    _zstd: zstandard.ZstdDecompressor | None = None
    _known: tuple[int, np.ndarray, dict[int, str]] | None = None

    def _known_channels(self) -> tuple[np.ndarray, dict[int, str]]:
        """Whether each u16 channel id is registered, and the topics (kept until a channel
        record adds one: channels are only ever added)."""
        if self._known is None or self._known[0] != len(self.channels):
            known = np.zeros(1 << 16, dtype=bool)
            known[list(self.channels)] = True
            topics = {c: ch.topic for c, ch in self.channels.items()}
            self._known = (len(self.channels), known, topics)
        return self._known[1], self._known[2]

    def messages(self) -> Iterator[MessageBatch]:
        """Batches of all messages in file order (single pass). The file is memory-mapped at
        its length when opened (a live file may grow: this is a snapshot; archive files are
        only appended to, never truncated), so its bytes are not copied, only decompressed."""
        self._zstd = zstandard.ZstdDecompressor()
        with open(self.path, "rb") as stream:
            size = os.fstat(stream.fileno()).st_size
            data = mmap.mmap(stream.fileno(), size, access=mmap.ACCESS_READ) if size else b""
        magic = bytes(data[: len(MCAP_MAGIC)])
        if self.empty_ok and magic != MCAP_MAGIC and MCAP_MAGIC.startswith(magic):
            self.error = "torn magic (nothing written yet)"  # (e.g. a full disk at its start)
            self.torn_bytes = size
            return
        if magic != MCAP_MAGIC:
            raise ArchiveError(f"{self.path}: not an MCAP file (bad magic)")
        self.valid_bytes = len(MCAP_MAGIC)
        yield from self._records(np.frombuffer(data, dtype=np.uint8))
        self.torn_bytes = 0 if self.finished else size - self.valid_bytes

    def _records(self, data: np.ndarray) -> Iterator[MessageBatch]:
        """The top-level records from the compiled scan; only chunks, messages, schemas,
        channels and the data end are looked at (indexes and the summary are skipped)."""
        head = len(MCAP_MAGIC)
        ops, starts, lengths, status = _scan_from(data, head)
        wanted = np.isin(ops, _TOP_LEVEL)
        for r in np.flatnonzero(wanted).tolist():
            self.valid_bytes = int(starts[r]) - _RECORD_HEAD
            opcode, a = int(ops[r]), int(starts[r])
            body = data[a : a + int(lengths[r])].data  # a memoryview: no copy of a chunk
            try:
                yield from self._record(opcode, body)
            except (ArchiveError, McapError, zstandard.ZstdError, struct.error, ValueError) as exc:
                self.error = f"corrupt record at byte {self.valid_bytes}: {exc}"
                return
            if opcode == Opcode.DATA_END:
                self.valid_bytes = a + int(lengths[r])
                self.finished = True
                return
        self.valid_bytes = int(starts[-1] + lengths[-1]) if ops.size else head
        if status:
            self.error = (
                "torn record header at end of file"
                if status == 1
                else ("torn record at end of file")
            )

    def _record(self, opcode: int, body: bytes | memoryview) -> Iterator[MessageBatch]:
        if opcode == Opcode.CHUNK:
            yield from self._chunk(self._decompress(memoryview(body)))
        elif opcode == Opcode.MESSAGE:
            data = np.frombuffer(bytes(body), dtype=np.uint8)
            yield from self._messages(data, np.zeros(1, np.int64), np.array([len(data)]))
        else:
            self._metadata(opcode, bytes(body))  # schemas, channels: no messages

    def _decompress(self, body: memoryview) -> np.ndarray:
        """The records of a Chunk record's body (MCAP spec: message start and end time u64,
        uncompressed size u64, uncompressed CRC u32, compression string, records u64-prefixed),
        decompressed and CRC-checked as :func:`~millwatch.ingest.archive.reader.decompress_chunk`
        does, without copying the compressed bytes first."""
        start, end, size, crc, n = _CHUNK_HEAD.unpack_from(body, 0)
        pos = _CHUNK_HEAD.size + n
        compression = bytes(body[_CHUNK_HEAD.size : pos]).decode()
        (length,) = struct.unpack_from("<Q", body, pos)
        pos += 8
        if length > len(body) - pos:
            raise ArchiveError("chunk records run past the chunk")
        records: Any = body[pos : pos + length]  # (Chunk says bytes; any buffer serves)
        chunk = Chunk(
            compression=compression, data=records, message_end_time=end,
            message_start_time=start, uncompressed_crc=crc, uncompressed_size=size,
        )  # fmt: skip
        return np.frombuffer(decompress_chunk(chunk, self._zstd), dtype=np.uint8)

    def _chunk(self, data: np.ndarray) -> Iterator[MessageBatch]:
        ops, starts, lengths = _scan_records(data)
        is_msg = ops == Opcode.MESSAGE
        first = 0  # next message record position to yield
        for r in np.flatnonzero(~is_msg).tolist():  # channels and schemas, in record order
            yield from self._messages_between(data, ops, starts, lengths, is_msg, first, r)
            first = r + 1
            body = data[starts[r] : starts[r] + lengths[r]].tobytes()
            yield from self._record(int(ops[r]), body)
        yield from self._messages_between(data, ops, starts, lengths, is_msg, first, ops.size)

    def _messages_between(
        self, data: np.ndarray, ops: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
        is_msg: np.ndarray, a: int, b: int,
    ) -> Iterator[MessageBatch]:  # fmt: skip
        sel = np.flatnonzero(is_msg[a:b]) + a
        if sel.size:
            yield from self._messages(data, starts[sel], lengths[sel])

    def _messages(
        self, data: np.ndarray, starts: np.ndarray, lengths: np.ndarray
    ) -> Iterator[MessageBatch]:
        """Message records with bodies at ``starts``/``lengths``: the valid prefix as a batch,
        then the error the per-message reader raises at the first invalid one."""
        size = _MESSAGE_HEAD.itemsize
        known, topics = self._known_channels()
        channel = np.empty(starts.shape[0], dtype=np.int64)
        log_time = np.empty(starts.shape[0], dtype=np.int64)
        n = message_heads(data, starts, lengths, known, channel, log_time)
        if n:
            index = self.message_count + np.arange(n, dtype=np.int64)
            self.message_count += n
            yield MessageBatch(self.path.name, data, index, channel[:n], log_time[:n],
                               starts[:n] + size, lengths[:n] - size, topics)  # fmt: skip
        if n < starts.shape[0]:
            if lengths[n] < size:
                raise ArchiveError(f"message record of {int(lengths[n])} bytes is too short")
            raise ArchiveError(f"message on unknown channel id {int(channel[n])}")


def archive_batches(
    directory: str | Path,
    prefix: str,
    after: ArchivePosition | None = None,
    min_messages: int = 20_000,
) -> Iterator[MessageBatch]:
    """The archive's messages strictly after ``after`` (all when None), in archive order, as
    batches of at least ``min_messages`` (a file's last one may be smaller)."""
    files = list_archive_files(directory, prefix)
    if after is not None:
        pivot = archive_file_order(after.file)
        files = [p for p in files if archive_file_order(p.name) >= pivot]
    for path in files:
        skip = after.index if after is not None and path.name == after.file else 0
        group: list[MessageBatch] = []
        size = 0
        for batch in BatchReader(path, empty_ok=True).messages():
            if skip and batch.index[0] < skip:
                batch = batch.select(batch.index >= skip)
                if not len(batch):
                    continue
            group.append(batch)
            size += len(batch)
            if size >= min_messages:
                yield MessageBatch.concat(group)
                group, size = [], 0
        if group:
            yield MessageBatch.concat(group)
