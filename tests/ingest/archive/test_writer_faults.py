"""The archive writer on a disk that fills up and frees again (issue 26, "disk full under the
archive"): nothing taken is lost or reordered, the file is readable to its last good chunk at
every moment, its position on disk never counts a failed write, and what it cannot keep it
refuses without taking.

The disk is :class:`Disk`: ``os.pwrite`` as the kernel does it on a full file system — a
write is cut to the free bytes, the next one fails with ``ENOSPC`` — for the writer's module
only. The real thing (a full tmpfs under ``millwatch serve``) is
``tests/integration/test_write_faults.py``.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import pytest

from millwatch.ingest import keys, wire
from millwatch.ingest.archive import writer as writer_module
from millwatch.ingest.archive.batches import BatchReader
from millwatch.ingest.archive.files import list_archive_files
from millwatch.ingest.archive.reader import ArchiveReader, TailTolerantReader
from millwatch.ingest.archive.writer import ArchiveFullError, ArchiveWriter

T0 = 1_763_767_800_000_000_000
MS = 1_000_000
KEYS = [keys.build_key("s1", "m1", s) for s in ("motor_torque", "speed")]


class Disk:
    """Free bytes left for the archive's writes; ``None``: unlimited."""

    def __init__(self) -> None:
        self.free: int | None = None
        self.failures = 0

    def pwrite(self, fd: int, data: memoryview, offset: int) -> int:
        if self.free is None:
            return os.pwrite(fd, data, offset)
        if self.free == 0:
            self.failures += 1
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = os.pwrite(fd, data[: self.free], offset)
        self.free -= n
        return n


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def disk(monkeypatch: pytest.MonkeyPatch) -> Disk:
    d = Disk()

    class _Os:  # the writer module's ``os`` with a full-able pwrite
        def __getattr__(self, name: str) -> object:
            return d.pwrite if name == "pwrite" else getattr(os, name)

    monkeypatch.setattr(writer_module, "os", _Os())
    return d


def _payload(i: int) -> bytes:
    rng = np.random.default_rng(i)
    return wire.encode_block(rng.normal(size=100).astype(np.float32), T0 + i * 100 * MS, 1000.0,
                             i, wire.Unit.KILONEWTON_METRE)  # fmt: skip


def _writer(tmp_path: Path, clock: Clock, **kw: object) -> ArchiveWriter:
    return ArchiveWriter(tmp_path, "m1", chunk_size=4096, max_latency_s=0.1, clock=clock,
                         retry_s=1.0, **kw)  # type: ignore[arg-type]  # fmt: skip


def _put(w: ArchiveWriter, clock: Clock, i: int) -> None:
    clock.t += 0.05
    w.write(KEYS[i % 2], _payload(i), T0 + i * 100 * MS)


def _archived(tmp_path: Path) -> list[int]:
    return [wire.decode_block(b.payload).seq for b in ArchiveReader(tmp_path, "m1").blocks()]


def test_a_full_disk_delays_writes_and_loses_nothing(tmp_path, disk):
    clock = Clock()
    w = _writer(tmp_path, clock)
    for i in range(100):
        _put(w, clock, i)
    durable = w.flush()
    disk.free = 3000  # room for part of a chunk, then ENOSPC
    for i in range(100, 400):
        _put(w, clock, i)
    assert w.failure is not None and w.failure.errno == errno.ENOSPC
    durable_now = w.durable_position  # (what a checkpoint may rely on)
    assert durable is not None and durable_now is not None and durable_now.file == durable.file
    assert 100 <= durable_now.index < 400
    with pytest.raises(OSError):
        w.flush()
    on_disk = _archived(tmp_path)  # the good chunks, at least all the durable ones
    assert on_disk == list(range(len(on_disk))) and len(on_disk) >= durable_now.index
    disk.free = None
    clock.t += 1.0
    position = w.flush()
    assert w.failure is None and position == w.position == w.durable_position
    assert position is not None and position.index == 400
    w.close()
    assert _archived(tmp_path) == list(range(400))
    (path,) = list_archive_files(tmp_path, "m1")
    reader = TailTolerantReader(path)
    assert len(list(reader.messages())) == 400 and reader.finished and reader.error is None
    assert w.failed_writes >= 1 and w.refused == 0


def test_retries_wait_for_retry_s(tmp_path, disk):
    clock = Clock()
    w = _writer(tmp_path, clock)
    _put(w, clock, 0)
    w.flush()
    disk.free = 0
    for i in range(1, 200):  # 10 s of writes
        _put(w, clock, i)
    assert 5 <= disk.failures <= 12  # one attempt a second, not one a write
    disk.free = None
    clock.t += 1.0
    w.close()
    assert _archived(tmp_path) == list(range(200))


def test_beyond_the_memory_bound_messages_are_refused_not_taken(tmp_path, disk):
    clock = Clock()
    w = _writer(tmp_path, clock, max_unwritten_bytes=8000)
    _put(w, clock, 0)
    w.flush()
    disk.free = 0
    taken, refused = [0], []
    for i in range(1, 300):
        try:
            _put(w, clock, i)
        except ArchiveFullError as exc:
            assert exc.errno == errno.ENOSPC and "m1_" in str(exc)
            refused.append(i)
        else:
            taken.append(i)
    assert refused and taken == list(range(len(taken)))  # a prefix is kept, the rest refused
    assert w.position is not None and w.position.index == len(taken)
    assert w.refused == len(refused) and w.unwritten_bytes <= 8000 + 4096 + 1024
    disk.free = None
    clock.t += 1.0
    for i in refused:  # (as a re-fetch from the gateway's spool brings them)
        _put(w, clock, i)
    w.close()
    assert _archived(tmp_path) == list(range(300))


def test_a_close_while_the_disk_is_full_leaves_the_good_chunks_readable(tmp_path, disk):
    clock = Clock()
    w = _writer(tmp_path, clock)
    for i in range(50):
        _put(w, clock, i)
    w.flush()
    disk.free = 1000
    for i in range(50, 120):
        _put(w, clock, i)
    with pytest.raises(OSError, match="70 of its 120 messages were never written"):
        w.close()
    assert w.lost_at_close == 70
    (path,) = list_archive_files(tmp_path, "m1")
    for reader in (TailTolerantReader(path), BatchReader(path)):
        n = (
            sum(1 for _ in reader.messages())
            if isinstance(reader, TailTolerantReader)
            else sum(len(b) for b in reader.messages())
        )
        assert n == 50 and not reader.finished and reader.error is not None


def test_no_rotation_while_writes_fail(tmp_path, disk):
    clock = Clock()
    w = ArchiveWriter(tmp_path, "m1", rotate_seconds=1.0, chunk_size=4096, clock=clock)
    _put(w, clock, 0)
    w.flush()
    disk.free = 0
    for i in range(1, 40):  # 4 s of log time: three windows
        _put(w, clock, i)
    assert len(list(tmp_path.glob("*.mcap"))) == 1
    disk.free = None
    clock.t += 1.0
    for i in range(40, 60):
        _put(w, clock, i)
    w.close()
    assert len(list(tmp_path.glob("*.mcap"))) >= 2
    assert _archived(tmp_path) == list(range(60))


def test_a_file_whose_header_never_reached_the_disk_reads_as_empty(tmp_path, disk):
    clock = Clock()
    disk.free = 0
    w = _writer(tmp_path, clock)
    _put(w, clock, 0)  # taken into memory: the file exists, empty
    (path,) = list_archive_files(tmp_path, "m1")
    assert path.stat().st_size == 0
    assert _archived(tmp_path) == []
    assert sum(len(b) for b in BatchReader(path, empty_ok=True).messages()) == 0
    disk.free = None
    clock.t += 1.0
    w.close()
    assert _archived(tmp_path) == [0]
