"""A gateway's spool on disk: every wire block, durable before it is published, by channel key
and wire sequence number, for hours.

Why a spool (issue 25): a gateway's zenoh cache (:mod:`millwatch.ingest.gateway`) dies with the
gateway process and holds minutes; a site's link can be down for hours, and a gateway PC restarts. A
SoMat eDAQ keeps its data on board and historians spool to disk (PI buffering, Ignition
store-and-forward); a millwatch gateway keeps a spool directory.

Files
-----
MCAP files named and ordered like the archive's (``spool_<YYYYmmddTHHMMSS>Z[-n].mcap``,
:mod:`millwatch.ingest.archive.files`), one MCAP channel per key, message data = the wire block
exactly as
published, log time = the wall time it was spooled (ns, UTC). Unlike the archive, a spool file is
written **unchunked**: each message record goes to the OS (``write(2)``) before :meth:`Spool.
append` returns, so a block is on disk before it is published and a SIGKILL loses nothing that
went out (the archive batches 100 ms into a zstd chunk instead; a chunk per block would cost a
chunk record, a message index and a chunk index each). Wire blocks of float samples hardly
compress, so little is lost by that (README "Benchmarks": spool bytes per channel-hour). A
writer killed mid-record leaves a torn tail:
:class:`~millwatch.ingest.archive.reader.TailTolerantReader`
reads such a file up to its last complete record, as it does the archive's.

Files rotate every ``rotate_seconds`` of wall time or ``rotate_bytes``, whichever comes first, so
retention drops whole old files.

Index
-----
Per file, per key: the set of wire sequence numbers it holds, as runs (:class:`SeqRuns`). A
finished file's index is kept beside it (``<file>.json``); on open, a file without one (the file
of a killed writer) is read once and gets one. So the index survives restarts and SIGKILLs, and
opening a spool of many hours reads only small JSON files.

Retention
---------
At open, at every rotation and every minute: the oldest files go first while the spool holds
more than ``max_bytes`` or their newest block was spooled more than ``hours`` ago (never the file
being written). What a dropped file held is added to the ledger (``dropped.json``: per key the
sequence numbers dropped, as runs, and the total), written *before* the file is removed, so a
recovery query for a range the spool no longer holds is answered with the exact count, and
:attr:`Spool.dropped_blocks` counts every block retention dropped over the spool's life.

One process owns a spool directory at a time (an exclusive ``flock`` on ``spool.lock``); a
second gateway on the same directory fails at once with :class:`SpoolError`. The methods are
thread-safe (the gateway appends while zenoh threads answer recovery queries).
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from millwatch.ingest import wire
from millwatch.ingest.archive.files import (
    LIBRARY,
    MESSAGE_ENCODING,
    PROFILE,
    SCHEMA_ENCODING,
    SCHEMA_NAME,
    ArchiveError,
    archive_file_name,
    list_archive_files,
)
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.spool.runs import SeqRuns

__all__ = [
    "DEFAULT_HOURS",
    "DEFAULT_MAX_MB",
    "PREFIX",
    "Spool",
    "SpoolError",
    "SpoolRead",
    "payload_seq",
]

log = logging.getLogger(__name__)

PREFIX = "spool"
#: Default retention (h of wall time): a day covers a weekend link outage's first day, a
#: gateway PC's reboot, a worker upgrade.
DEFAULT_HOURS = 24.0
#: Default size bound (MB = 10^6 bytes): a day of an 8-channel dual-drive mill at 1 kHz,
#: 100-sample float32 blocks (17 MB per channel-hour measured, README "Benchmarks").
DEFAULT_MAX_MB = 4000.0
#: Longest a spool file stays open (s of wall time) and its largest size (bytes); smaller
#: bounds follow from the retention (a tenth of it), so retention drops a tenth at a time.
MAX_ROTATE_S = 600.0
MAX_ROTATE_BYTES = 32 * 2**20
_MIN_ROTATE_BYTES = 64 * 2**10
_NS_PER_H = 3_600_000_000_000
_CHECK_NS = 60_000_000_000  # retention is looked at every minute (and at every rotation)
_LEDGER = "dropped.json"
_META = "gateway.json"
_LOCK = "spool.lock"
_LEDGER_FILES_KEPT = 32
_UINT32 = 2**32


class SpoolError(Exception):
    """A spool directory cannot be used (taken by another process, unreadable ledger)."""


def payload_seq(payload: bytes | bytearray | memoryview) -> int | None:
    """The wire ``seq`` of a payload that begins with a v1 block header (header only, no
    samples touched); None when it does not."""
    if len(payload) < wire.HEADER_SIZE:
        return None
    magic, version, _, _, _, seq, *_ = wire.HEADER.unpack_from(payload)
    if magic != wire.MAGIC or version != wire.FORMAT_VERSION:
        return None
    return int(seq)


@dataclass(frozen=True, slots=True)
class SpoolRead:
    """What a spool holds of one key's sequence range: ``blocks`` (payloads, in ``seq`` order)
    and ``dropped``, how many sequence numbers of the range retention removed (exact)."""

    blocks: list[bytes]
    dropped: int


@dataclass(slots=True)
class _FileIndex:
    """One spool file: its sequence numbers per key, size and spooled-time span (ns)."""

    path: Path
    runs: dict[str, SeqRuns] = field(default_factory=dict)
    first_ns: int = 0
    last_ns: int = 0
    messages: int = 0

    def add(self, key: str, seq: int | None, log_time_ns: int) -> None:
        if seq is not None:
            runs = self.runs.get(key)
            if runs is None:
                runs = self.runs[key] = SeqRuns()
            runs.add(seq)
        if self.messages == 0:
            self.first_ns = log_time_ns
        self.last_ns = max(self.last_ns, log_time_ns)
        self.messages += 1

    @property
    def sidecar(self) -> Path:
        return self.path.with_name(self.path.name + ".json")

    def save(self) -> None:
        body = {"first_ns": self.first_ns, "last_ns": self.last_ns, "messages": self.messages,
                "runs": {k: r.runs() for k, r in self.runs.items()}}  # fmt: skip
        _write_json(self.sidecar, body)

    @classmethod
    def load_or_scan(cls, path: Path) -> _FileIndex:
        """The file's index from its sidecar, else read from the file (and saved)."""
        index = cls(path)
        try:
            body = json.loads(index.sidecar.read_text(encoding="utf-8"))
            index.first_ns, index.last_ns = int(body["first_ns"]), int(body["last_ns"])
            index.messages = int(body["messages"])
            index.runs = {k: SeqRuns(r) for k, r in body["runs"].items()}
            return index
        except (OSError, ValueError, KeyError, TypeError):
            pass
        reader = TailTolerantReader(path)
        for msg in reader.messages():
            index.add(msg.key, payload_seq(msg.payload), msg.log_time_ns)
        if reader.error:
            log.warning("spool: %s read up to byte %d (%s): a writer killed mid-block",
                        path.name, reader.valid_bytes, reader.error)  # fmt: skip
        index.save()
        return index

    def size(self) -> int:
        try:
            return self.path.stat().st_size
        except FileNotFoundError:
            return 0


def _write_json(path: Path, body: dict[str, Any]) -> None:
    """Write ``body`` to ``path`` atomically (a crash leaves the old file or the new one)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(body, separators=(",", ":")), encoding="utf-8")
    os.replace(tmp, path)


class _Ledger:
    """What retention dropped: per key the sequence numbers, the total, the last file names."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.runs: dict[str, SeqRuns] = {}
        self.total = 0
        self.files: list[str] = []
        if path.exists():
            try:
                body = json.loads(path.read_text(encoding="utf-8"))
                self.runs = {k: SeqRuns(r) for k, r in body["runs"].items()}
                self.total, self.files = int(body["dropped_blocks"]), list(body["files"])
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise SpoolError(f"spool ledger {path} is unreadable: {exc}") from exc

    def drop(self, index: _FileIndex) -> None:
        for key, runs in index.runs.items():
            self.runs.setdefault(key, SeqRuns()).update(runs)
        self.total += index.messages
        self.files = [*self.files, index.path.name][-_LEDGER_FILES_KEPT:]
        _write_json(self.path, {"dropped_blocks": self.total, "files": self.files,
                                "runs": {k: r.runs() for k, r in self.runs.items()}})  # fmt: skip


class _OpenFile:
    """The spool file being written: unchunked MCAP, each message handed to the OS at once."""

    def __init__(self, path: Path) -> None:
        self.index = _FileIndex(path)
        self.stream: IO[bytes] = open(path, "xb")  # noqa: SIM115 - closed in finish
        self.writer = Writer(self.stream, use_chunking=False, compression=CompressionType.NONE)
        self.writer.start(profile=PROFILE, library=LIBRARY + " (spool)")
        self.writer.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, (wire.__doc__ or "").encode())
        self.channels: dict[str, int] = {}
        self.stream.flush()

    def append(self, key: str, payload: bytes, seq: int | None, now_ns: int) -> None:
        channel = self.channels.get(key)
        if channel is None:
            channel = self.channels[key] = self.writer.register_channel(
                topic=key, message_encoding=MESSAGE_ENCODING, schema_id=1,
                metadata={"wire_version": str(wire.FORMAT_VERSION)},
            )  # fmt: skip
        self.writer.add_message(channel, log_time=now_ns, data=payload, publish_time=now_ns,
                                sequence=self.index.messages % _UINT32)  # fmt: skip
        self.stream.flush()  # to the OS before the block is published: a kill loses none
        self.index.add(key, seq, now_ns)

    def tell(self) -> int:
        return self.stream.tell()

    def finish(self) -> _FileIndex:
        self.writer.finish()
        self.stream.flush()
        self.stream.close()
        self.index.save()
        return self.index


class Spool:
    """A spool directory (see the module docstring). ``hours`` (wall time) and ``max_bytes``
    bound what it keeps; ``rotate_seconds`` / ``rotate_bytes`` default to a tenth of them
    (at most :data:`MAX_ROTATE_S` s, :data:`MAX_ROTATE_BYTES` bytes). ``clock``: wall time in
    ns (UTC). Use as a context manager, or call :meth:`close`."""

    def __init__(
        self,
        directory: str | Path,
        *,
        hours: float = DEFAULT_HOURS,
        max_bytes: int = round(DEFAULT_MAX_MB * 1e6),
        rotate_seconds: float | None = None,
        rotate_bytes: int | None = None,
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        if not hours > 0 or not max_bytes > 0:
            raise ValueError(f"spool retention must be > 0 (hours {hours}, bytes {max_bytes})")
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self._lock_file = self._take_lock()
        self.hours, self.max_bytes, self._clock = hours, max_bytes, clock
        self._rotate_ns = round((rotate_seconds or min(MAX_ROTATE_S, hours * 360.0)) * 1e9)
        self._rotate_bytes = rotate_bytes or max(
            _MIN_ROTATE_BYTES, min(MAX_ROTATE_BYTES, max_bytes // 10)
        )
        self._mutex = threading.RLock()
        self._decoded = _DecodedFile()
        self._next_check = 0
        self._ledger = _Ledger(self.directory / _LEDGER)
        self._files: list[_FileIndex] = self._load_files()
        self._open: _OpenFile | None = None
        self._last: dict[str, int] = {}
        for runs_by_key in [self._ledger.runs, *(f.runs for f in self._files)]:
            for key, runs in runs_by_key.items():
                last = -1 if runs.last is None else runs.last
                self._last[key] = max(self._last.get(key, -1), last)
        #: Called with each key the spool sees for the first time (a server declares its
        #: queryable); set before the first :meth:`append`.
        self.on_new_key: Callable[[str], None] | None = None
        self._apply_retention()

    # ------------------------------------------------------------------ opening
    def _take_lock(self) -> IO[str]:
        lock = open(self.directory / _LOCK, "a+")  # noqa: SIM115 - held until close
        try:
            fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as exc:
            lock.close()
            raise SpoolError(
                f"spool {self.directory} is in use by another gateway or forwarder: give each "
                "its own --spool directory"
            ) from exc
        return lock

    def _load_files(self) -> list[_FileIndex]:
        files = []
        dropped = set(self._ledger.files)
        for path in list_archive_files(self.directory, PREFIX):
            if path.name in dropped:  # dropped, ledger written, then killed before unlinking
                _unlink(path)
                continue
            try:
                files.append(_FileIndex.load_or_scan(path))
            except ArchiveError as exc:  # e.g. empty: killed before its header was written
                aside = path.with_name(path.name + ".unreadable")
                os.replace(path, aside)
                log.warning("spool: %s set aside as %s: %s", path.name, aside.name, exc)
        return files

    # ------------------------------------------------------------------ writing
    def append(self, key: str, payload: bytes) -> int | None:
        """Spool ``payload`` (a wire block, kept byte-identical) of channel ``key``; it is with
        the OS when this returns. Returns its wire ``seq`` (None: not a v1 block; spooled but
        not indexed, so no query can return it)."""
        seq = payload_seq(payload)
        with self._mutex:
            now = self._clock()
            current = self._current(now)
            current.append(key, bytes(payload), seq, now)
            if now >= self._next_check:
                self._apply_retention()
            new_key = key not in self._last
            if seq is not None and seq > self._last.get(key, -1):
                self._last[key] = seq
            elif new_key:
                self._last[key] = -1
        if new_key and self.on_new_key is not None:
            self.on_new_key(key)
        return seq

    def _current(self, now_ns: int) -> _OpenFile:
        current = self._open
        if current is not None and (
            now_ns - current.index.first_ns >= self._rotate_ns
            or current.tell() >= self._rotate_bytes
        ):
            current.finish()  # (its index is in _files since it opened)
            self._open = current = None
            self._apply_retention()
        if current is None:
            current = self._open = _OpenFile(self._free_path(now_ns))
            self._files.append(current.index)
        return current

    def _free_path(self, now_ns: int) -> Path:
        for clash in range(100_000):
            path = self.directory / archive_file_name(PREFIX, now_ns, clash)
            if not path.exists():
                return path
        raise SpoolError(f"no free spool file name in {self.directory}")

    # ------------------------------------------------------------------ retention
    def _apply_retention(self) -> None:
        """Drop the oldest files (never the open one) while over ``max_bytes`` or older than
        ``hours`` (see the module docstring)."""
        with self._mutex:
            now = self._clock()
            self._next_check = now + min(self._rotate_ns, _CHECK_NS)
            cutoff = now - round(self.hours * _NS_PER_H)
            total = sum(f.size() for f in self._files)
            open_index = None if self._open is None else self._open.index
            while self._files and self._files[0] is not open_index:
                oldest = self._files[0]
                if total <= self.max_bytes and oldest.last_ns >= cutoff:
                    return
                total -= oldest.size()
                self._drop(oldest)

    def _drop(self, index: _FileIndex) -> None:
        self._ledger.drop(index)
        self._files.remove(index)
        _unlink(index.path)
        _unlink(index.sidecar)
        log.info("spool: retention dropped %s (%d blocks; %d dropped in all)",
                 index.path.name, index.messages, self._ledger.total)  # fmt: skip

    # ------------------------------------------------------------------ reading
    def last_seq(self, key: str) -> int | None:
        """The highest wire ``seq`` ever spooled on ``key`` (also if since dropped); None if
        none — where a restarted gateway's numbering continues."""
        with self._mutex:
            last = self._last.get(key)
        return None if last is None or last < 0 else last

    def spooled_keys(self) -> list[str]:
        """Every key the spool has held blocks of."""
        with self._mutex:
            return sorted(self._last)

    @property
    def dropped_blocks(self) -> int:
        """Blocks retention dropped over the spool's life (all keys)."""
        return self._ledger.total

    def dropped(self, key: str, first: int | None = None, last: int | None = None) -> int:
        """Sequence numbers of ``key`` in ``first..last`` (inclusive) retention dropped."""
        with self._mutex:
            runs = self._ledger.runs.get(key)
            return 0 if runs is None else runs.count(first, last)

    def held(self, key: str) -> SeqRuns:
        """The sequence numbers of ``key`` the spool holds now."""
        out = SeqRuns()
        with self._mutex:
            for f in self._files:
                if key in f.runs:
                    out.update(f.runs[key])
        return out

    def read(self, key: str, first: int, last: int, limit: int | None = None) -> SpoolRead:
        """The blocks of ``key`` with ``first <= seq <= last`` it holds, in ``seq`` order (at
        most ``limit``: the lowest), and how many of the range retention dropped.

        Files are read without holding the spool, so a long read does not hold up the gateway's
        appends; a file that retention drops meanwhile makes it read again holding the spool
        (the answer stays exact: each number either returned or counted as dropped)."""
        with self._mutex:
            paths = self._paths(key, first, last)
            dropped = self.dropped(key, first, last)
        found = _read_files(paths, key, first, last, limit, self._decoded)
        if found is None:
            with self._mutex:
                paths = self._paths(key, first, last)
                dropped = self.dropped(key, first, last)
                found = _read_files(paths, key, first, last, limit, self._decoded) or {}
        seqs = sorted(found)[:limit]
        return SpoolRead([found[s] for s in seqs], dropped)

    def _paths(self, key: str, first: int, last: int) -> list[Path]:
        """The files holding blocks of ``key`` in ``first..last``, in spooling order."""
        return [
            f.path for f in self._files if key in f.runs and f.runs[key].intersects(first, last)
        ]

    def stats(self) -> dict[str, int]:
        """Files, bytes on disk, blocks held and blocks dropped by retention."""
        with self._mutex:
            return {"files": len(self._files), "bytes": sum(f.size() for f in self._files),
                    "blocks": sum(f.messages for f in self._files),
                    "dropped_blocks": self._ledger.total}  # fmt: skip

    # ------------------------------------------------------------------ gateway metadata
    def meta(self) -> dict[str, Any]:
        """What the gateway recorded about itself (:meth:`set_meta`), e.g. a scene's anchor."""
        path = self.directory / _META
        if not path.exists():
            return {}
        try:
            body: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise SpoolError(f"spool metadata {path} is unreadable: {exc}") from exc
        return body

    def set_meta(self, **values: Any) -> None:
        """Record JSON-able ``values`` beside the spool (atomically; merged with the old)."""
        _write_json(self.directory / _META, {**self.meta(), **values})

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Finish the open file (summary, footer, index). Idempotent."""
        with self._mutex:
            if self._open is not None:
                self._open.finish()
                self._open = None
            if not self._lock_file.closed:
                self._lock_file.close()

    def __enter__(self) -> Spool:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def _read_files(
    paths: list[Path], key: str, first: int, last: int, limit: int | None, cache: _DecodedFile
) -> dict[int, bytes] | None:
    """Blocks of ``key`` in ``first..last`` by seq from ``paths`` (in spooling order, which is
    seq order per key: stops once ``limit`` are found); None when a file has vanished."""
    found: dict[int, bytes] = {}
    for path in paths:
        try:
            blocks = cache.blocks(path, key)
        except FileNotFoundError:  # dropped by retention meanwhile
            return None
        if last - first < len(blocks):  # (a page of a long file: look the numbers up)
            for seq in range(first, last + 1):
                if seq in blocks:
                    found.setdefault(seq, blocks[seq])
        else:
            for seq, payload in blocks.items():
                if first <= seq <= last:
                    found.setdefault(seq, payload)
        if limit is not None and len(found) >= limit:
            break
    return found


class _DecodedFile:
    """The last spool file read, decoded by key and seq: a catch-up asks each channel for
    page after page of the same file, and each answer then costs its own blocks, not a scan
    of the whole file (``tests/bench/bench_catch_up.py``). A file that grew (the open one) is
    read again. Memory: one file's blocks (at most ``MAX_ROTATE_BYTES``)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._at: tuple[Path, int] | None = None
        self._by_key: dict[str, dict[int, bytes]] = {}

    def blocks(self, path: Path, key: str) -> dict[int, bytes]:
        """``key``'s blocks in ``path`` by seq (FileNotFoundError: the file is gone)."""
        at = (path, path.stat().st_size)
        with self._lock:
            if at != self._at:
                by_key: dict[str, dict[int, bytes]] = {}
                for msg in TailTolerantReader(path).messages():
                    seq = payload_seq(msg.payload)
                    if seq is not None:
                        by_key.setdefault(msg.key, {}).setdefault(seq, msg.payload)
                self._at, self._by_key = at, by_key
            return self._by_key.get(key, {})


def _unlink(path: Path) -> None:
    path.unlink(missing_ok=True)
