"""MCAP archive of raw blocks: writer with rotation, tail-tolerant reader, recovery.

The archive is millwatch's log: every zenoh message is written *first* and
*byte-identical* as received, one MCAP channel per key (topic = key expression).

Encoding choice
---------------
Byte-identical raw payloads and "Foxglove can plot it" are in tension: Foxglove
plots only well-known encodings (CDR/ros2msg, JSON, protobuf, …), and wrapping the
payload in any of those changes the bytes (CDR adds an encapsulation header and a
length prefix). We choose **byte-identical**:

- channel ``message_encoding = "millwatch.block.v1"``: message data *is* the wire
  payload of :mod:`ingest.wire`, untouched;
- one schema per file, name ``millwatch.block.v1``, encoding
  ``millwatch.block.v1.layout``, whose data is the human-readable byte layout (the
  :mod:`ingest.wire` docstring), so every file documents itself.

Reasons: (1) malformed blocks must be archived as received (DESIGN: "archived as-is
if possible"), which no typed schema can hold; (2) replay and crash recovery must
feed the analyzer exactly the bytes live ingest saw, so results are identical;
(3) a checksum of a payload means the same thing on the wire and in the archive.
Standard MCAP tools (``mcap info``, ``mcap cat``, ``mcap.reader.make_reader``) list
and read these files; plotting in Foxglove needs a derived export (not done here).

Files and rotation
------------------
Files are named ``<prefix>_<YYYYmmddTHHMMSS>Z.mcap`` after the UTC log time of their
first message (``-<n>`` is appended on a name clash, e.g. a size rotation within one
second). A new file starts when the log time enters a new ``rotate_seconds`` window
(windows aligned to the Unix epoch, so hourly files start on the hour) or when the
file reaches ``rotate_bytes``. Each file is standalone: schema and channels are
registered again in every file. Chunks are zstd-compressed.

Crash safety
------------
The MCAP header is flushed to the OS when a file opens. A chunk is closed and
written when it exceeds ``chunk_size`` *or* when the oldest unwritten message is
``max_latency_s`` old (checked on every :meth:`ArchiveWriter.write` and by
:meth:`ArchiveWriter.flush_if_due`, which an idle ingest loop calls). A SIGKILLed
writer therefore loses at most about ``max_latency_s`` (default 0.1 s) of data;
nothing is fsynced unless ``fsync=True`` (a process kill does not lose data the OS
already holds; a power cut can). A killed writer leaves a file without summary and
footer, which ``mcap``'s seeking reader rejects: :class:`TailTolerantReader` reads
such files front to back up to the last complete record, and :func:`recover_file`
rewrites them as finished, indexed files.
"""

from __future__ import annotations

import dataclasses
import io
import logging
import os
import re
import struct
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Schema
from mcap.stream_reader import get_chunk_data_stream
from mcap.writer import CompressionType, Writer

from ingest import wire
from ingest.archive.mcap_append import MessageAppender, appender, pack_chunk_indexes
from ingest.keys import key_matches

log = logging.getLogger(__name__)

MESSAGE_ENCODING = "millwatch.block.v1"
SCHEMA_NAME = "millwatch.block.v1"
SCHEMA_ENCODING = "millwatch.block.v1.layout"
PROFILE = "millwatch"
LIBRARY = "millwatch-archive/1"
MCAP_MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_FILE_RE = re.compile(r"(?P<prefix>.+)_(?P<ts>\d{8}T\d{6})Z(?:-(?P<n>\d{1,6}))?\.mcap")
_PREFIX_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}")
_MAX_NAME_CLASHES = 100_000
_UINT32 = 2**32


class ArchiveError(Exception):
    """A file is not a readable millwatch MCAP archive."""


@dataclass(frozen=True, slots=True)
class ArchivePosition:
    """A point in the archive log, for checkpoints.

    ``file`` is the base name of an archive file; the first ``index`` messages of that
    file (file order) lie before the position; ``log_time_ns`` is the log time of the
    last of them (0 if ``index == 0``), ns since the Unix epoch (UTC).
    """

    file: str
    index: int
    log_time_ns: int = 0

    def as_dict(self) -> dict[str, str | int]:
        """JSON-ready form."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, str | int]) -> ArchivePosition:
        """Inverse of :meth:`as_dict`."""
        return cls(str(data["file"]), int(data["index"]), int(data.get("log_time_ns", 0)))


def archive_file_name(prefix: str, log_time_ns: int, clash: int = 0) -> str:
    """``<prefix>_<YYYYmmddTHHMMSS>Z[-<clash>].mcap`` for a UTC log time in ns."""
    stamp = datetime.fromtimestamp(log_time_ns // 1_000_000_000, tz=UTC).strftime("%Y%m%dT%H%M%S")
    suffix = "" if clash == 0 else "-" + str(clash)
    return prefix + "_" + stamp + "Z" + suffix + ".mcap"


def _file_sort_key(name: str) -> tuple[str, int]:
    match = _FILE_RE.fullmatch(name)
    if match is None:
        raise ArchiveError(f"not an archive file name: {name!r}")
    return match["ts"], int(match["n"] or 0)


def archive_file_order(name: str) -> tuple[str, int]:
    """Sort key of an archive file's base name: the files of one prefix in archive order (so
    positions in different files compare by it); :class:`ArchiveError` if not an archive name."""
    return _file_sort_key(name)


def list_archive_files(directory: str | Path, prefix: str) -> list[Path]:
    """Archive files of ``prefix`` in ``directory``, oldest first."""
    names = [
        p.name
        for p in Path(directory).glob(prefix + "_*.mcap")
        if (m := _FILE_RE.fullmatch(p.name)) is not None and m["prefix"] == prefix
    ]
    return [Path(directory) / n for n in sorted(names, key=_file_sort_key)]


# --------------------------------------------------------------------------- writer


@dataclass(slots=True)
class _OpenFile:
    path: Path
    stream: io.BufferedWriter
    writer: Writer
    window: int
    channels: dict[str, int] = field(default_factory=dict)
    count: int = 0
    last_log_time_ns: int = 0
    written_bytes: int = 0
    append: MessageAppender | None = None


class ArchiveWriter:
    """Append raw blocks to rotating MCAP files.

    ``rotate_seconds`` (s) and ``rotate_bytes`` bound each file; ``chunk_size``
    (bytes, uncompressed) bounds each zstd chunk; ``max_latency_s`` (s) bounds how
    long a written message may stay in memory before its chunk is written to the OS
    (``None`` disables the time bound: then a kill loses up to one chunk).
    Not thread-safe: one writer thread owns it.
    """

    def __init__(
        self,
        directory: str | Path,
        prefix: str,
        rotate_seconds: float = 3600.0,
        rotate_bytes: int = 256 * 2**20,
        chunk_size: int = 64 * 2**10,
        *,
        max_latency_s: float | None = 0.1,
        fsync: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not _PREFIX_RE.fullmatch(prefix):
            raise ValueError(f"prefix {prefix!r} must match {_PREFIX_RE.pattern}")
        if rotate_seconds <= 0 or rotate_bytes <= 0 or chunk_size <= 0:
            raise ValueError("rotate_seconds, rotate_bytes and chunk_size must be > 0")
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.prefix = prefix
        self._rotate_ns = round(rotate_seconds * 1e9)
        self._rotate_bytes = rotate_bytes
        self._chunk_size = chunk_size
        self._max_latency_s = max_latency_s
        self._fsync = fsync
        self._clock = clock
        self._file: _OpenFile | None = None
        self._pending_since: float | None = None
        self._last_position: ArchivePosition | None = None
        self.files_written: list[Path] = []
        self.out_of_order = 0

    # -- public API

    def write(self, key: str, payload: bytes, log_time_ns: int) -> None:
        """Archive ``payload`` (raw, byte-identical) on channel ``key`` at ``log_time_ns``.

        ``log_time_ns`` is int ns since the Unix epoch (UTC); the ingest daemon uses the
        receive time. May rotate the file and write a chunk.
        """
        if log_time_ns < 0:
            raise ValueError(f"log_time_ns must be >= 0, got {log_time_ns}")
        current = self._file_for(int(log_time_ns))
        if log_time_ns < current.last_log_time_ns:
            self._note_out_of_order(key, log_time_ns, current.last_log_time_ns)
        channel_id = self._channel_id(current, key)
        if current.append is not None:
            current.append.append(channel_id, current.count % _UINT32, log_time_ns, bytes(payload))
        else:
            current.writer.add_message(
                channel_id, log_time=log_time_ns, data=bytes(payload), publish_time=log_time_ns,
                sequence=current.count % _UINT32,
            )  # fmt: skip
        current.count += 1
        current.last_log_time_ns = max(current.last_log_time_ns, log_time_ns)
        if self._pending_since is None:
            self._pending_since = self._clock()
        self._after_add(current)

    def flush(self) -> ArchivePosition | None:
        """Write the open chunk and flush to the OS; return the now-durable position."""
        if self._file is None:
            return self._last_position
        self._file.writer.flush()
        self._sync(self._file)
        return self.position

    def flush_if_due(self) -> bool:
        """Flush if the oldest unwritten message is older than ``max_latency_s``."""
        if not self._due():
            return False
        self.flush()
        return True

    @property
    def position(self) -> ArchivePosition | None:
        """Position just after the last message written (durable only after flush)."""
        if self._file is None:
            return self._last_position
        f = self._file
        return ArchivePosition(f.path.name, f.count, f.last_log_time_ns)

    @property
    def current_file(self) -> Path | None:
        """The file being written, if any."""
        return None if self._file is None else self._file.path

    def close(self) -> None:
        """Finish the current file (summary, indexes, footer). Idempotent."""
        if self._file is not None:
            self._finish(self._file)
            self._file = None

    def __enter__(self) -> ArchiveWriter:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # -- internals

    def _due(self) -> bool:
        if self._max_latency_s is None or self._pending_since is None:
            return False
        return self._clock() - self._pending_since >= self._max_latency_s

    def _after_add(self, current: _OpenFile) -> None:
        if self._due():
            self.flush()
            return
        size = current.stream.tell()
        if size != current.written_bytes:  # mcap closed a full chunk into the buffer
            self._sync(current)

    def _sync(self, current: _OpenFile) -> None:
        current.stream.flush()
        if self._fsync:
            os.fsync(current.stream.fileno())
        current.written_bytes = current.stream.tell()
        self._pending_since = None

    def _note_out_of_order(self, key: str, log_time_ns: int, last_ns: int) -> None:
        if self.out_of_order == 0:
            log.warning("archive %s: log time goes back on %s (%d < %d ns); file order kept",
                        self.prefix, key, log_time_ns, last_ns)  # fmt: skip
        self.out_of_order += 1

    def _file_for(self, log_time_ns: int) -> _OpenFile:
        window = log_time_ns // self._rotate_ns
        current = self._file
        if current is not None and (
            window != current.window or current.written_bytes >= self._rotate_bytes
        ):
            self._finish(current)
            current = None
        if current is None:
            current = self._file = self._open(log_time_ns, window)
        return current

    def _free_path(self, log_time_ns: int) -> Path:
        for clash in range(_MAX_NAME_CLASHES):
            path = self.directory / archive_file_name(self.prefix, log_time_ns, clash)
            if not path.exists():
                return path
        raise ArchiveError(f"no free file name for {self.prefix} at {log_time_ns} ns")

    def _open(self, log_time_ns: int, window: int) -> _OpenFile:
        path = self._free_path(log_time_ns)
        stream = open(path, "xb")  # noqa: SIM115 - closed in _finish
        writer = Writer(stream, chunk_size=self._chunk_size, compression=CompressionType.ZSTD)
        writer.start(profile=PROFILE, library=LIBRARY)
        writer.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, (wire.__doc__ or "").encode())
        opened = _OpenFile(path=path, stream=stream, writer=writer, window=window,
                           append=appender(writer, self._chunk_size))  # fmt: skip
        self._sync(opened)
        log.info("archive: opened %s", path)
        return opened

    def _channel_id(self, current: _OpenFile, key: str) -> int:
        channel_id = current.channels.get(key)
        if channel_id is None:
            channel_id = current.writer.register_channel(
                topic=key, message_encoding=MESSAGE_ENCODING, schema_id=1,
                metadata={"wire_version": str(wire.FORMAT_VERSION)},
            )  # fmt: skip
            current.channels[key] = channel_id
        return channel_id

    def _finish(self, current: _OpenFile) -> None:
        self._last_position = ArchivePosition(
            current.path.name, current.count, current.last_log_time_ns
        )
        pack_chunk_indexes(current.writer)
        current.writer.finish()
        current.stream.flush()
        if self._fsync:
            os.fsync(current.stream.fileno())
        current.stream.close()
        self._pending_since = None
        self.files_written.append(current.path)
        log.info("archive: closed %s (%d messages)", current.path, current.count)


# --------------------------------------------------------------------------- reading


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
        """Decode the payload; raises :class:`ingest.wire.WireError` if malformed."""
        return wire.decode_block(self.payload)

    @property
    def position(self) -> ArchivePosition:
        """Position just after this block (checkpoint value once it is processed)."""
        return ArchivePosition(self.file, self.index + 1, self.log_time_ns)


def _decompress(chunk: Chunk, zstd: zstandard.ZstdDecompressor | None = None) -> bytes:
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


class TailTolerantReader:
    """Read an MCAP file front to back, also one whose writer died (no footer).

    Reading stops at the first record that is incomplete (a torn tail) or corrupt
    (bad chunk CRC or decompression error); everything before it is returned. After
    iteration: ``finished`` (data-end record seen), ``torn_bytes`` (bytes after the
    last complete record of an unfinished file, 0 for a finished one), ``error``
    (why reading stopped early, or ``None``), ``schemas``/``channels`` (by id) and
    ``message_count``.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.finished = False
        self.valid_bytes = 0
        self.torn_bytes = 0
        self.error: str | None = None
        self.message_count = 0

    def messages(self) -> Iterator[RawMessage]:
        """All messages in file order (single pass)."""
        with open(self.path, "rb") as stream:
            if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
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
            records = list(_iter_records(_decompress(chunk)))  # validate before yielding
            for inner_opcode, inner_body in records:
                yield from self._record(inner_opcode, inner_body)
        elif opcode == Opcode.MESSAGE:
            yield self._message(body)
        elif opcode == Opcode.SCHEMA:
            schema = Schema.read(ReadDataStream(io.BytesIO(body)))
            self.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            channel = Channel.read(ReadDataStream(io.BytesIO(body)))
            self.channels[channel.id] = channel

    def _message(self, body: bytes | memoryview) -> RawMessage:
        channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(body)
        channel = self.channels.get(channel_id)
        if channel is None:
            raise ArchiveError(f"message on unknown channel id {channel_id}")
        index = self.message_count
        self.message_count += 1
        payload = bytes(body[_MESSAGE_HEAD.size :])
        return RawMessage(channel.topic, log_time, publish_time, sequence, payload, index, channel)


def _finished_time_range(path: Path) -> tuple[int, int] | None:
    """(first, last) log time of a finished file from its summary, else None."""
    try:
        with open(path, "rb") as stream:
            stream.seek(-len(MCAP_MAGIC), os.SEEK_END)
            if stream.read() != MCAP_MAGIC:
                return None
            stream.seek(0)
            summary = make_reader(stream).get_summary()
    except (OSError, McapError, struct.error, ValueError, StopIteration):
        return None
    if summary is None or summary.statistics is None:
        return None
    return summary.statistics.message_start_time, summary.statistics.message_end_time


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
            for msg in TailTolerantReader(path).messages():
                if msg.index < skip or not _wanted(msg, pattern, start_ns, end_ns):
                    continue
                yield ArchivedBlock(msg.key, msg.log_time_ns, msg.payload, path.name, msg.index)

    def _files_after(self, after: ArchivePosition | None) -> list[Path]:
        files = self.files()
        if after is None:
            return files
        pivot = _file_sort_key(after.file)
        return [p for p in files if _file_sort_key(p.name) >= pivot]

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


# --------------------------------------------------------------------------- recovery


@dataclass(frozen=True, slots=True)
class RecoveryReport:
    """Outcome of :func:`recover_file`. Times in ns since the Unix epoch (UTC)."""

    src: Path
    dst: Path | None
    was_finished: bool
    messages: int
    channels: int
    valid_bytes: int
    dropped_bytes: int
    first_log_time_ns: int | None
    last_log_time_ns: int | None
    last_log_time_by_key: dict[str, int]
    error: str | None

    def summary(self) -> str:
        """One human-readable line for the CLI."""
        state = "already finished" if self.was_finished else "recovered"
        return (
            f"{self.src}: {state}; {self.messages} messages on {self.channels} channels, "
            f"{self.dropped_bytes} trailing bytes dropped"
            + (f" ({self.error})" if self.error else "")
            + (f" -> {self.dst}" if self.dst else "")
        )


@dataclass(slots=True)
class _Stats:
    last_by_key: dict[str, int] = field(default_factory=dict)
    first: int | None = None
    last: int | None = None

    def observe(self, msg: RawMessage) -> None:
        t = msg.log_time_ns
        self.first = t if self.first is None else min(self.first, t)
        self.last = t if self.last is None else max(self.last, t)
        self.last_by_key[msg.key] = max(self.last_by_key.get(msg.key, t), t)


@dataclass(slots=True)
class _Copier:
    writer: Writer
    schema_ids: dict[int, int] = field(default_factory=dict)
    channel_ids: dict[int, int] = field(default_factory=dict)

    def copy(self, reader: TailTolerantReader, msg: RawMessage) -> None:
        new_channel = self._channel(reader, msg.channel)
        self.writer.add_message(
            new_channel, log_time=msg.log_time_ns, data=msg.payload,
            publish_time=msg.publish_time_ns, sequence=msg.sequence,
        )  # fmt: skip

    def _channel(self, reader: TailTolerantReader, channel: Channel) -> int:
        if channel.id not in self.channel_ids:
            schema_id = self._schema(reader.schemas.get(channel.schema_id))
            self.channel_ids[channel.id] = self.writer.register_channel(
                channel.topic, channel.message_encoding, schema_id, dict(channel.metadata)
            )
        return self.channel_ids[channel.id]

    def _schema(self, schema: Schema | None) -> int:
        if schema is None:
            return 0
        if schema.id not in self.schema_ids:
            self.schema_ids[schema.id] = self.writer.register_schema(
                schema.name, schema.encoding, schema.data
            )
        return self.schema_ids[schema.id]


def _scan(src: Path) -> tuple[TailTolerantReader, _Stats]:
    reader, stats = TailTolerantReader(src), _Stats()
    for msg in reader.messages():
        stats.observe(msg)
    return reader, stats


def _rewrite(src: Path, tmp: Path) -> tuple[TailTolerantReader, _Stats]:
    reader, stats = TailTolerantReader(src), _Stats()
    with open(tmp, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile=PROFILE, library=LIBRARY + " (recovered)")
        copier = _Copier(writer)
        for msg in reader.messages():
            copier.copy(reader, msg)
            stats.observe(msg)
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
    return reader, stats


def recover_file(src: str | Path, dst: str | Path | None = None) -> RecoveryReport:
    """Rewrite an MCAP file whose writer died into a finished, indexed file.

    Keeps every complete message (byte-identical, same log/publish times and sequence
    numbers) and drops the torn tail. ``dst=None`` replaces ``src`` atomically (via a
    ``.recovering`` temp file) and leaves an already finished ``src`` untouched; with
    ``dst`` the rewrite always happens. Returns what was kept and dropped. Never run it
    on the file a live :class:`ArchiveWriter` is still appending to.
    """
    src = Path(src)
    if dst is None:
        probe, stats = _scan(src)
        if probe.finished:
            return _report(src, None, probe, stats)
    target = src if dst is None else Path(dst)
    tmp = target.with_name(target.name + ".recovering")
    try:
        reader, stats = _rewrite(src, tmp)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, target)
    log.info("archive: recovered %s -> %s (%d messages)", src, target, reader.message_count)
    return _report(src, target, reader, stats)


def _report(
    src: Path, dst: Path | None, reader: TailTolerantReader, stats: _Stats
) -> RecoveryReport:
    return RecoveryReport(
        src=src, dst=dst, was_finished=reader.finished, messages=reader.message_count,
        channels=len(reader.channels), valid_bytes=reader.valid_bytes,
        dropped_bytes=reader.torn_bytes, first_log_time_ns=stats.first,
        last_log_time_ns=stats.last, last_log_time_by_key=dict(stats.last_by_key),
        error=reader.error,
    )  # fmt: skip
