"""Archive reader: messages of MCAP files front to back, also of files whose writer died.

:class:`TailTolerantReader` reads one file record by record and stops at the first record
that is incomplete (a torn tail of a killed writer, or the file being written right now) or
corrupt, keeping everything before it; ``mcap``'s seeking reader would reject such a file.
:class:`ArchiveReader` walks the files of one writer prefix in archive order, filtered by key
pattern, log time and checkpoint position, yielding :class:`ArchivedBlock` values.
:mod:`millwatch.ingest.archive.batches` reads the same files with the same rules into arrays.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Schema, Statistics
from mcap.stream_reader import get_chunk_data_stream

from millwatch.ingest import wire
from millwatch.ingest.archive.files import (
    MCAP_MAGIC,
    ArchiveError,
    ArchivePosition,
    archive_file_order,
    list_archive_files,
)
from millwatch.ingest.keys import key_matches

__all__ = [
    "ArchiveReader",
    "ArchivedBlock",
    "RawMessage",
    "TailTolerantBase",
    "TailTolerantReader",
    "decompress_chunk",
    "finished_statistics",
]

_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")


@dataclass(frozen=True, slots=True)
class RawMessage:
    """One archived message as stored: key, times (ns, UTC), raw payload, file index."""

    key: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    payload: bytes
    index: int
    channel: Channel = field(repr=False)


@dataclass(frozen=True, slots=True)
class ArchivedBlock:
    """A block read from the archive: key, log time (ns, UTC), raw payload, position."""

    key: str
    log_time_ns: int
    payload: bytes
    file: str
    index: int

    def decode(self) -> wire.Block:
        """Decode the payload; raises :class:`millwatch.ingest.wire.WireError` if malformed."""
        return wire.decode_block(self.payload)

    @property
    def position(self) -> ArchivePosition:
        """Position just after this block (checkpoint value once it is processed)."""
        return ArchivePosition(self.file, self.index + 1, self.log_time_ns)


def decompress_chunk(chunk: Chunk, zstd: zstandard.ZstdDecompressor | None = None) -> bytes:
    """The chunk's records, CRC-checked; ``zstd``: a decompressor to reuse (one per reader)."""
    if chunk.compression == "":
        data = chunk.data
    elif chunk.compression == "zstd":
        data = (zstd or zstandard.ZstdDecompressor()).decompress(
            chunk.data, max_output_size=chunk.uncompressed_size
        )
    else:
        stream, size = get_chunk_data_stream(chunk)
        data = stream.read(size)
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ArchiveError("chunk CRC mismatch")
    return data


def _iter_records(data: bytes | memoryview) -> Iterator[tuple[int, memoryview]]:
    """(opcode, body) of every complete record in ``data``; raises on a torn record."""
    view = memoryview(data)
    pos, end = 0, len(view)
    while pos < end:
        if pos + _RECORD_HEAD.size > end:
            raise ArchiveError("torn record header")
        opcode, length = _RECORD_HEAD.unpack_from(view, pos)
        pos += _RECORD_HEAD.size
        if length > end - pos:
            raise ArchiveError("torn record body")
        yield opcode, view[pos : pos + length]
        pos += length


class TailTolerantBase:
    """What a front-to-back read of one MCAP file learns, and the rules it stops by.

    Reading stops at the first record that is incomplete (a torn tail) or corrupt
    (bad chunk CRC or decompression error); everything before it is returned. With
    ``empty_ok`` a file that ends within the magic (an archive file made while the disk was
    full: nothing written yet) is torn and empty, not an error. After
    iteration: ``finished`` (data-end record seen), ``torn_bytes`` (bytes after the
    last complete record of an unfinished file, 0 for a finished one), ``error``
    (why reading stopped early, or ``None``), ``schemas``/``channels`` (by id) and
    ``message_count``. Subclasses say what they yield per message.
    """

    def __init__(self, path: str | Path, *, empty_ok: bool = False) -> None:
        self.path = Path(path)
        self.empty_ok = empty_ok
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.finished = False
        self.valid_bytes = 0
        self.torn_bytes = 0
        self.error: str | None = None
        self.message_count = 0

    def _metadata(self, opcode: int, body: bytes | memoryview) -> None:
        """Keep a schema or channel record (other records carry nothing for a reader)."""
        if opcode == Opcode.SCHEMA:
            schema = Schema.read(ReadDataStream(io.BytesIO(body)))
            self.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            channel = Channel.read(ReadDataStream(io.BytesIO(body)))
            self.channels[channel.id] = channel


class TailTolerantReader(TailTolerantBase):
    """Read an MCAP file front to back, also one whose writer died (no footer), one
    :class:`RawMessage` per message; the stopping rules and the attributes left after
    iteration are those of :class:`TailTolerantBase`."""

    def messages(self) -> Iterator[RawMessage]:
        """All messages in file order (single pass)."""
        with open(self.path, "rb") as stream:
            magic = stream.read(len(MCAP_MAGIC))
            if self.empty_ok and magic != MCAP_MAGIC and MCAP_MAGIC.startswith(magic):
                self.error = "torn magic (nothing written yet)"  # (e.g. a full disk at its start)
                self.torn_bytes = len(magic)
                return
            if magic != MCAP_MAGIC:
                raise ArchiveError(f"{self.path}: not an MCAP file (bad magic)")
            self.valid_bytes = len(MCAP_MAGIC)
            size = os.fstat(stream.fileno()).st_size  # a live file may grow: read a snapshot
            yield from self._top_level(stream, size)
            self.torn_bytes = 0 if self.finished else size - self.valid_bytes

    def _top_level(self, stream: io.BufferedReader, size: int) -> Iterator[RawMessage]:
        while self.valid_bytes < size:
            head = stream.read(_RECORD_HEAD.size)
            if len(head) < _RECORD_HEAD.size:
                self.error = "torn record header at end of file"
                return
            opcode, length = _RECORD_HEAD.unpack(head)
            body = stream.read(length) if length <= size - self.valid_bytes else b""
            if len(body) < length:
                self.error = "torn record at end of file"
                return
            try:
                yield from self._record(opcode, body)
            except (ArchiveError, McapError, zstandard.ZstdError, struct.error, ValueError) as exc:
                self.error = f"corrupt record at byte {self.valid_bytes}: {exc}"
                return
            self.valid_bytes += _RECORD_HEAD.size + length
            if opcode == Opcode.DATA_END:
                self.finished = True
                return

    def _record(self, opcode: int, body: bytes | memoryview) -> Iterator[RawMessage]:
        if opcode == Opcode.CHUNK:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
            records = list(_iter_records(decompress_chunk(chunk)))  # validate before yielding
            for inner_opcode, inner_body in records:
                yield from self._record(inner_opcode, inner_body)
        elif opcode == Opcode.MESSAGE:
            yield self._message(body)
        else:
            self._metadata(opcode, body)

    def _message(self, body: bytes | memoryview) -> RawMessage:
        channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(body)
        channel = self.channels.get(channel_id)
        if channel is None:
            raise ArchiveError(f"message on unknown channel id {channel_id}")
        index = self.message_count
        self.message_count += 1
        payload = bytes(body[_MESSAGE_HEAD.size :])
        return RawMessage(channel.topic, log_time, publish_time, sequence, payload, index, channel)


def finished_statistics(path: Path) -> Statistics | None:
    """The summary statistics of a finished file (message count, per-channel counts, first and
    last log time), read from its summary section; None for an unfinished file."""
    try:
        with open(path, "rb") as stream:
            stream.seek(-len(MCAP_MAGIC), os.SEEK_END)
            if stream.read() != MCAP_MAGIC:
                return None
            stream.seek(0)
            summary = make_reader(stream).get_summary()
    except (OSError, McapError, struct.error, ValueError, StopIteration):
        return None
    return None if summary is None else summary.statistics


def _finished_time_range(path: Path) -> tuple[int, int] | None:
    """(first, last) log time of a finished file from its summary, else None."""
    stats = finished_statistics(path)
    return None if stats is None else (stats.message_start_time, stats.message_end_time)


class ArchiveReader:
    """Iterate archived blocks of one writer ``prefix`` across rotated files.

    Order is archive (file) order, which is log-time order when the writer was fed
    in log-time order (the ingest daemon stamps receive time). Unfinished files (a
    killed writer, or the file being written right now) are read up to their last
    complete record.
    """

    def __init__(self, directory: str | Path, prefix: str) -> None:
        self.directory = Path(directory)
        self.prefix = prefix

    def files(self) -> list[Path]:
        """Archive files, oldest first."""
        return list_archive_files(self.directory, self.prefix)

    def blocks(
        self,
        pattern: str | None = None,
        start_ns: int | None = None,
        end_ns: int | None = None,
        after: ArchivePosition | None = None,
    ) -> Iterator[ArchivedBlock]:
        """Blocks whose key matches zenoh ``pattern`` (``*``/``**``; None = all) and whose
        log time is in ``[start_ns, end_ns)`` (ns, UTC; None = open), strictly after
        checkpoint ``after`` if given."""
        for path in self._files_after(after):
            skip = after.index if after is not None and path.name == after.file else 0
            if skip == 0 and not self._may_overlap(path, start_ns, end_ns):
                continue
            for msg in TailTolerantReader(path, empty_ok=True).messages():
                if msg.index < skip or not _wanted(msg, pattern, start_ns, end_ns):
                    continue
                yield ArchivedBlock(msg.key, msg.log_time_ns, msg.payload, path.name, msg.index)

    def _files_after(self, after: ArchivePosition | None) -> list[Path]:
        files = self.files()
        if after is None:
            return files
        pivot = archive_file_order(after.file)
        return [p for p in files if archive_file_order(p.name) >= pivot]

    @staticmethod
    def _may_overlap(path: Path, start_ns: int | None, end_ns: int | None) -> bool:
        if start_ns is None and end_ns is None:
            return True
        span = _finished_time_range(path)
        if span is None:
            return True
        first, last = span
        return (start_ns is None or last >= start_ns) and (end_ns is None or first < end_ns)


def _wanted(msg: RawMessage, pattern: str | None, start: int | None, end: int | None) -> bool:
    if start is not None and msg.log_time_ns < start:
        return False
    if end is not None and msg.log_time_ns >= end:
        return False
    return pattern is None or key_matches(pattern, msg.key)
