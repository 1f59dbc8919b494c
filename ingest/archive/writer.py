"""Archive writer: append raw blocks to rotating, standalone MCAP files.

The file format and names are in :mod:`millwatch.ingest.archive.files`.

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
footer, which ``mcap``'s seeking reader rejects: :mod:`millwatch.ingest.archive.reader` reads
such files up to the last complete record, and :mod:`millwatch.ingest.archive.recovery`
rewrites them as finished, indexed files.

Failed writes (a full disk)
---------------------------
The ``mcap`` writer writes into memory (:class:`_FileTail`); the writer hands those bytes to
the OS in one ``pwrite`` per chunk. When that fails (``ENOSPC``, ``EIO``, …) the file on disk
is readable to its last good chunk (what a failed write left after it is a torn tail, as after
a kill); the unwritten bytes stay in memory and are written again at the same offsets, in
order, at the next attempt (at most every ``retry_s``), so the file ends up exactly as if
nothing had failed. While writes fail:

* :attr:`ArchiveWriter.failure` holds the error (None once a write succeeds again);
* messages are still accepted into memory until ``max_unwritten_bytes`` wait there; beyond,
  :meth:`ArchiveWriter.write` refuses them with :class:`ArchiveFullError` (nothing of the
  message is kept: the caller keeps it or fetches it again later);
* the file is not rotated (a new file starts after the old one is complete on disk);
* :attr:`ArchiveWriter.durable_position` — what a checkpoint may rely on — stays at the last
  message written whole, and :meth:`ArchiveWriter.flush` raises the error instead of returning
  a position that is not on disk.

A writer closed while writes still fail leaves its file readable to its last good chunk
(unfinished, repairable with ``millwatch archive recover``) and logs how many messages it lost.
"""

from __future__ import annotations

import errno
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from millwatch.ingest import wire
from millwatch.ingest.archive.files import (
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
from millwatch.ingest.archive.mcap_append import MessageAppender, appender, pack_chunk_indexes

__all__ = ["ArchiveFullError", "ArchiveWriter"]

log = logging.getLogger(__name__)

_MAX_NAME_CLASHES = 100_000
_UINT32 = 2**32


#: Default bound of the bytes kept in memory while writes fail (compressed chunks).
MAX_UNWRITTEN_BYTES = 64 * 2**20
#: Default pause between attempts to write again after a failed write (s).
RETRY_S = 1.0


class ArchiveFullError(OSError):
    """The archive cannot take a message now: writes fail and ``max_unwritten_bytes`` already
    wait in memory. Nothing of the message was kept."""

    def __init__(self, path: Path, cause: OSError | None, unwritten: int) -> None:
        why = os.strerror(cause.errno) if cause is not None and cause.errno else str(cause)
        super().__init__(
            cause.errno if cause is not None and cause.errno else errno.ENOSPC,
            f"archive {path.name}: writes fail ({why}) and {unwritten} bytes already wait in "
            "memory; message not taken",
        )


class _FileTail:
    """The stream an ``mcap`` writer writes one file through: bytes wait in memory until
    :meth:`commit` hands them to the OS with ``pwrite`` at their own offsets. A commit that
    fails part-way leaves a prefix of the waiting bytes after the last complete commit — a torn
    tail, as a killed writer leaves, which the readers stop at — and the next commit writes
    the same bytes over it at the same offsets: the file never shrinks (readers map it) and
    never holds anything but what it would have held without the failure. ``flush`` does
    nothing (the archive writer commits)."""

    def __init__(self, path: Path) -> None:
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.written = 0  # bytes of complete commits on disk
        self.pending = bytearray()

    def write(self, data: bytes | bytearray | memoryview) -> int:
        self.pending += data
        return len(data)

    def tell(self) -> int:
        return self.written + len(self.pending)

    def flush(self) -> None:
        return None

    def commit(self, fsync: bool) -> None:
        """Write the waiting bytes; :class:`OSError` when not all of them could be."""
        data, done = memoryview(bytes(self.pending)), 0  # (a copy: pending may grow meanwhile)
        while done < len(data):
            done += os.pwrite(self.fd, data[done:], self.written + done)
        if fsync:
            os.fsync(self.fd)
        self.written += done
        self.pending.clear()

    def close(self) -> None:
        os.close(self.fd)


@dataclass(slots=True)
class _OpenFile:
    path: Path
    stream: _FileTail
    writer: Writer
    window: int
    channels: dict[str, int] = field(default_factory=dict)
    count: int = 0
    last_log_time_ns: int = 0
    #: Messages (and the last one's log time) written whole to the OS.
    durable_count: int = 0
    durable_log_time_ns: int = 0
    append: MessageAppender | None = None


class ArchiveWriter:
    """Append raw blocks to rotating MCAP files.

    ``rotate_seconds`` (s) and ``rotate_bytes`` bound each file; ``chunk_size``
    (bytes, uncompressed) bounds each zstd chunk; ``max_latency_s`` (s) bounds how
    long a written message may stay in memory before its chunk is written to the OS
    (``None`` disables the time bound: then a kill loses up to one chunk).
    ``max_unwritten_bytes`` and ``retry_s``: what is kept in memory while writes fail, and
    how often writing is tried again (module docstring, "Failed writes").
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
        max_unwritten_bytes: int = MAX_UNWRITTEN_BYTES,
        retry_s: float = RETRY_S,
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
        self.max_unwritten_bytes = max_unwritten_bytes
        self._retry_s = retry_s
        self._file: _OpenFile | None = None
        #: A finished file whose last bytes (summary, footer) are not on disk yet.
        self._closing: _OpenFile | None = None
        self._pending_since: float | None = None
        self._last_position: ArchivePosition | None = None
        self._tried_at = -float("inf")
        self.files_written: list[Path] = []
        self.out_of_order = 0
        #: The error of the last failed write while writes fail; None once one succeeds.
        self.failure: OSError | None = None
        #: Failed attempts to write (each attempt writes everything waiting).
        self.failed_writes = 0
        #: Messages refused (:class:`ArchiveFullError`) and lost at a close that failed.
        self.refused = 0
        self.lost_at_close = 0

    # -- public API

    def write(self, key: str, payload: bytes, log_time_ns: int) -> None:
        """Archive ``payload`` (raw, byte-identical) on channel ``key`` at ``log_time_ns``.

        ``log_time_ns`` is int ns since the Unix epoch (UTC); the ingest daemon uses the
        receive time. May rotate the file and write a chunk. While writes fail the message
        waits in memory (:attr:`failure` says so); :class:`ArchiveFullError` when there is no
        room left for it (it is not taken); :class:`OSError` when no file can be opened.
        """
        if log_time_ns < 0:
            raise ValueError(f"log_time_ns must be >= 0, got {log_time_ns}")
        self._make_room()
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
        """Write the open chunk and everything waiting to the OS; return the now-durable
        position. Raises the :class:`OSError` when that fails (then nothing after
        :attr:`durable_position` is on disk; what waits is written at a later attempt)."""
        self._commit(force=False)
        if self.failure is not None:
            raise self.failure
        return self.position

    def flush_if_due(self) -> bool:
        """Flush if the oldest unwritten message is older than ``max_latency_s`` or, while
        writes fail, when the next attempt is due; never raises a write error (see
        :attr:`failure`). True when it wrote."""
        if not self._due():
            return False
        self._commit(force=False)
        return self.failure is None

    @property
    def position(self) -> ArchivePosition | None:
        """Position just after the last message taken (on disk only after a flush that
        succeeded: :attr:`durable_position`)."""
        if self._file is None:
            return self._last_position
        f = self._file
        return ArchivePosition(f.path.name, f.count, f.last_log_time_ns)

    @property
    def durable_position(self) -> ArchivePosition | None:
        """Position just after the last message written whole to the OS."""
        f = self._closing or self._file
        if f is None:
            return self._last_position
        return ArchivePosition(f.path.name, f.durable_count, f.durable_log_time_ns)

    @property
    def unwritten_bytes(self) -> int:
        """Bytes waiting in memory for the OS (chunks closed but not written)."""
        files = (self._closing, self._file)
        return sum(len(f.stream.pending) for f in files if f is not None)

    @property
    def current_file(self) -> Path | None:
        """The file being written, if any."""
        return None if self._file is None else self._file.path

    def close(self) -> None:
        """Finish the current file (summary, indexes, footer). Idempotent. When writes still
        fail, the file is left readable to its last good chunk, the messages not written are
        counted (:attr:`lost_at_close`) and the :class:`OSError` is raised, saying so."""
        if self._file is not None:
            self._start_finish(self._file)
        if self._closing is not None:  # (still failing)
            raise self._abandon(self._closing)

    def __enter__(self) -> ArchiveWriter:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # -- internals

    def _due(self) -> bool:
        if self.failure is not None:
            return self._clock() - self._tried_at >= self._retry_s
        if self._max_latency_s is None or self._pending_since is None:
            return False
        return self._clock() - self._pending_since >= self._max_latency_s

    def _after_add(self, current: _OpenFile) -> None:
        if self._due() or (self.failure is None and current.stream.pending):
            self._commit(force=False)  # (pending bytes: mcap closed a full chunk)

    def _make_room(self) -> None:
        """Before a message is taken: write what waits when due; refuse the message
        (:class:`ArchiveFullError`) while a finished file waits to be written whole, or when
        ``max_unwritten_bytes`` wait."""
        if self.failure is None:
            return
        if self._due():
            self._commit(force=False)
        if self.failure is None:
            return
        unwritten = self.unwritten_bytes
        if self._closing is not None or unwritten >= self.max_unwritten_bytes:
            self.refused += 1
            path = (self._closing or self._file or _NoFile).path
            raise ArchiveFullError(path, self.failure, unwritten)

    def _commit(self, *, force: bool) -> None:
        """Hand everything waiting to the OS: a finished file's last bytes first (then it is
        closed), then the open file's (its open chunk closed first, so every message taken is
        in the bytes written); records a failure in :attr:`failure`."""
        if self.failure is not None and not force and not self._due():
            return
        self._tried_at = self._clock()
        try:
            if self._closing is not None:
                self._closing.stream.commit(self._fsync)
                self._closed(self._closing)
            if self._file is not None:
                f = self._file
                f.writer.flush()  # (into memory: the open chunk closed)
                f.stream.commit(self._fsync)
                f.durable_count, f.durable_log_time_ns = f.count, f.last_log_time_ns
        except OSError as exc:
            self._failed(exc)
            return
        self._pending_since = None
        self.failure = None

    def _failed(self, exc: OSError) -> None:
        """A failed attempt (the caller logs episodes: this writer may fail thousands of
        times in one)."""
        self.failed_writes += 1
        self.failure = exc

    def _note_out_of_order(self, key: str, log_time_ns: int, last_ns: int) -> None:
        if self.out_of_order == 0:
            log.warning("archive %s: log time goes back on %s (%d < %d ns); file order kept",
                        self.prefix, key, log_time_ns, last_ns)  # fmt: skip
        self.out_of_order += 1

    def _file_for(self, log_time_ns: int) -> _OpenFile:
        """The file to take a message at ``log_time_ns``: the current one, or a new one when
        its window ended or it is full — not while writes fail (a new file starts once the
        old one is whole on disk)."""
        window = log_time_ns // self._rotate_ns
        current = self._file
        if (
            current is not None
            and self.failure is None
            and (window != current.window or current.stream.written >= self._rotate_bytes)
        ):
            self._start_finish(current)
            self._file = current = None
            if self._closing is not None:  # (its last bytes could not be written)
                self.refused += 1
                raise ArchiveFullError(self._closing.path, self.failure, self.unwritten_bytes)
        if current is None:
            try:
                current = self._file = self._open(log_time_ns, window)
            except OSError as exc:  # (no file could be made: the message is not taken)
                self._failed(exc)
                self.refused += 1
                raise
        return current

    def _free_path(self, log_time_ns: int) -> Path:
        for clash in range(_MAX_NAME_CLASHES):
            path = self.directory / archive_file_name(self.prefix, log_time_ns, clash)
            if not path.exists():
                return path
        raise ArchiveError(f"no free file name for {self.prefix} at {log_time_ns} ns")

    def _open(self, log_time_ns: int, window: int) -> _OpenFile:
        path = self._free_path(log_time_ns)
        stream = _FileTail(path)
        writer = Writer(stream, chunk_size=self._chunk_size,  # type: ignore[arg-type]
                        compression=CompressionType.ZSTD)  # fmt: skip
        writer.start(profile=PROFILE, library=LIBRARY)
        writer.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, (wire.__doc__ or "").encode())
        opened = _OpenFile(path=path, stream=stream, writer=writer, window=window,
                           append=appender(writer, self._chunk_size))  # fmt: skip
        log.info("archive: opened %s", path)
        self._file = opened
        self._commit(force=False)  # (the header; on failure it waits with the rest)
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

    def _start_finish(self, current: _OpenFile) -> None:
        """Write the file's summary and footer (into memory) and commit them; until that
        succeeds the file waits in :attr:`_closing`."""
        self._last_position = ArchivePosition(
            current.path.name, current.count, current.last_log_time_ns
        )
        pack_chunk_indexes(current.writer)
        current.writer.finish()
        self._closing = current
        self._file = None
        self._commit(force=True)

    def _closed(self, current: _OpenFile) -> None:
        current.stream.close()
        self._closing = None
        self.files_written.append(current.path)
        log.info("archive: closed %s (%d messages)", current.path, current.count)

    def _abandon(self, current: _OpenFile) -> OSError:
        """Close a file whose last bytes cannot be written: unfinished, readable up to its last
        good chunk; the error saying so."""
        readable = current.durable_count
        self.lost_at_close += current.count - readable
        current.stream.close()
        self._closing = None
        self._last_position = ArchivePosition(current.path.name, readable, 0)
        cause = self.failure
        return OSError(
            cause.errno if cause is not None else errno.EIO,
            f"archive {current.path}: closed unfinished, writes fail ({cause}): "
            f"{current.count - readable} of its {current.count} messages were never written; "
            "it is readable up to its last good chunk ('millwatch archive recover' finishes it)",
        )


class _NoFile:
    path = Path("(no file)")
