"""Archive writer: append raw blocks to rotating, standalone MCAP files.

The file format and names are in :mod:`ingest.archive.files`.

Rotation
--------
A new file starts when the log time enters a new ``rotate_seconds`` window
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
footer, which ``mcap``'s seeking reader rejects: :mod:`ingest.archive.reader` reads
such files up to the last complete record, and :mod:`ingest.archive.recovery`
rewrites them as finished, indexed files.
"""

from __future__ import annotations

import io
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from ingest import wire
from ingest.archive.files import (
    LIBRARY,
    MESSAGE_ENCODING,
    PREFIX_RE,
    PROFILE,
    SCHEMA_ENCODING,
    SCHEMA_NAME,
    ArchiveError,
    ArchivePosition,
    archive_file_name,
)
from ingest.archive.mcap_append import MessageAppender, appender, pack_chunk_indexes

__all__ = ["ArchiveWriter"]

log = logging.getLogger(__name__)

_MAX_NAME_CLASHES = 100_000
_UINT32 = 2**32


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
        if not PREFIX_RE.fullmatch(prefix):
            raise ValueError(f"prefix {prefix!r} must match {PREFIX_RE.pattern}")
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
