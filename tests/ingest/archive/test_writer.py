"""MCAP archive: byte-identical round trips, rotation, tail-tolerant reading, recovery.

Measurements (logged at INFO; run with ``-o log_cli=true --log-cli-level=INFO``):
SIGKILL loss per chunk size and write/read throughput.
"""

from __future__ import annotations

import logging
import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader

from millwatch.ingest import keys, wire
from millwatch.ingest.archive import files as archive
from millwatch.ingest.archive.files import ArchivePosition
from millwatch.ingest.archive.reader import ArchiveReader, TailTolerantReader
from millwatch.ingest.archive.recovery import recover_file
from millwatch.ingest.archive.writer import ArchiveWriter

log = logging.getLogger(__name__)
REPO = Path(__file__).resolve().parents[3]
T0 = 1_763_767_800_000_000_000  # 2025-11-21T23:30:00Z
MS = 1_000_000
KEYS = [keys.build_key("s1", "m1", s) for s in ("motor_torque", "pinion_torque", "speed")]


def _payload(i: int, n: int = 10) -> bytes:
    samples = np.full(n, i, np.float32)
    return wire.encode_block(samples, T0 + i * 10 * MS, 1000.0, i, wire.Unit.KILONEWTON_METRE)


def _write(
    writer: ArchiveWriter, count: int, step_ns: int = 10 * MS
) -> list[tuple[str, int, bytes]]:
    written = []
    for i in range(count):
        key = KEYS[i % len(KEYS)]
        item = (key, T0 + i * step_ns, _payload(i))
        writer.write(key, item[2], item[1])
        written.append(item)
    return written


def _read_all(directory: Path, prefix: str = "m1", **kw: object) -> list[tuple[str, int, bytes]]:
    return [
        (b.key, b.log_time_ns, b.payload) for b in ArchiveReader(directory, prefix).blocks(**kw)
    ]


def _standard_messages(path: Path) -> list[tuple[str, int, bytes]]:
    with open(path, "rb") as stream:
        return [
            (channel.topic, message.log_time, message.data)
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)
        ]


def test_round_trip_is_byte_identical_including_malformed_payloads(tmp_path: Path) -> None:
    junk = [(KEYS[0], T0 + 5, b""), (KEYS[1], T0 + 6, b"\x00garbage\xff" * 7)]
    with ArchiveWriter(tmp_path, "m1") as writer:
        written = _write(writer, 300)
        for key, t, payload in junk:
            writer.write(key, payload, t)
    assert _read_all(tmp_path) == [*written, *junk]
    blocks = list(ArchiveReader(tmp_path, "m1").blocks(pattern=KEYS[2]))
    assert blocks[0].decode().seq == 2
    with pytest.raises(wire.WireError):
        [b.decode() for b in ArchiveReader(tmp_path, "m1").blocks(pattern=KEYS[1])]


def test_file_is_self_describing_for_standard_tools(tmp_path: Path) -> None:
    with ArchiveWriter(tmp_path, "m1") as writer:
        written = _write(writer, 30)
    (path,) = ArchiveReader(tmp_path, "m1").files()
    assert path.name == "m1_20251121T233000Z.mcap"
    assert _standard_messages(path) == written
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    (schema,) = summary.schemas.values()
    assert schema.name == archive.SCHEMA_NAME and b"MWBK" in schema.data
    assert {c.message_encoding for c in summary.channels.values()} == {archive.MESSAGE_ENCODING}
    assert sorted(c.topic for c in summary.channels.values()) == sorted(KEYS)
    assert summary.statistics.message_count == 30


def test_time_rotation_gives_standalone_utc_named_files(tmp_path: Path) -> None:
    with ArchiveWriter(tmp_path, "m1", rotate_seconds=1.0) as writer:
        written = _write(writer, 350)  # 3.5 s of log time
    files = ArchiveReader(tmp_path, "m1").files()
    assert [f.name for f in files] == [
        "m1_20251121T233000Z.mcap", "m1_20251121T233001Z.mcap",
        "m1_20251121T233002Z.mcap", "m1_20251121T233003Z.mcap",
    ]  # fmt: skip
    from_standard = []
    for path in files:
        with open(path, "rb") as stream:  # each file alone: schema + channels inside
            reader = NonSeekingReader(stream)
            from_standard += [(c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages()]
    assert from_standard == written == _read_all(tmp_path)


def test_size_rotation_and_name_clashes(tmp_path: Path) -> None:
    with ArchiveWriter(tmp_path, "m1", rotate_bytes=8_000, chunk_size=2_000) as writer:
        written = _write(writer, 400, step_ns=MS)  # 0.4 s: all files in the same second
    files = ArchiveReader(tmp_path, "m1").files()
    assert len(files) >= 3
    assert files[0].name == "m1_20251121T233000Z.mcap"
    assert files[1].name == "m1_20251121T233000Z-1.mcap"
    assert all(path.stat().st_size < 8_000 + 4_000 for path in files)
    assert _read_all(tmp_path) == written


def test_pattern_time_range_and_resume_from_position(tmp_path: Path) -> None:
    with ArchiveWriter(tmp_path, "m1", rotate_seconds=1.0) as writer:
        written = _write(writer, 300)
    window = (T0 + 500 * MS, T0 + 2100 * MS)
    expected = [w for w in written if w[0] == KEYS[1] and window[0] <= w[1] < window[1]]
    pattern = keys.mill_pattern("s1", "m1").replace("*", "pinion_torque")
    assert _read_all(tmp_path, pattern=pattern, start_ns=window[0], end_ns=window[1]) == expected
    assert len(_read_all(tmp_path, pattern=keys.site_pattern("s1"))) == 300
    assert _read_all(tmp_path, pattern=keys.replay_pattern()) == []
    blocks = list(ArchiveReader(tmp_path, "m1").blocks())
    checkpoint = ArchivePosition.from_dict(blocks[149].position.as_dict())
    assert _read_all(tmp_path, after=checkpoint) == written[150:]


def _unfinished_copy(tmp_path: Path, count: int) -> tuple[Path, list[tuple[str, int, bytes]]]:
    """A flushed but never-finished file, as a killed writer leaves it."""
    src_dir, dst_dir = tmp_path / "live", tmp_path / "crashed"
    dst_dir.mkdir()
    writer = ArchiveWriter(src_dir, "m1", chunk_size=1_000)
    written = _write(writer, count)
    writer.flush()
    path = shutil.copy(writer.current_file, dst_dir)
    writer.close()
    return Path(path), written


def test_unfinished_file_is_readable_and_recoverable(tmp_path: Path) -> None:
    path, written = _unfinished_copy(tmp_path, 200)
    with open(path, "rb") as stream, pytest.raises(Exception):  # noqa: B017 - any mcap error
        list(make_reader(stream).iter_messages())
    assert _read_all(path.parent) == written
    report = recover_file(path)
    assert not report.was_finished and report.messages == 200 and report.dropped_bytes == 0
    assert report.last_log_time_ns == written[-1][1]
    assert _standard_messages(path) == written
    again = recover_file(path)
    assert again.was_finished and again.dst is None and again.messages == 200


def test_torn_tails_lose_only_the_torn_records(tmp_path: Path) -> None:
    path, written = _unfinished_copy(tmp_path, 200)
    data = path.read_bytes()
    torn = tmp_path / "torn.mcap"
    counts = []
    for cut in range(8, len(data), max(1, len(data) // 60)):
        torn.write_bytes(data[:cut])
        reader = TailTolerantReader(torn)
        got = [(m.key, m.log_time_ns, m.payload) for m in reader.messages()]
        assert got == written[: len(got)]
        assert reader.valid_bytes + reader.torn_bytes == cut
        counts.append(len(got))
    assert counts == sorted(counts) and counts[-1] > 150
    report = recover_file(torn, tmp_path / "fixed.mcap")
    assert _standard_messages(tmp_path / "fixed.mcap") == written[: report.messages]


def _chunk_offsets(data: bytes) -> list[tuple[int, int]]:
    """(offset, body length) of the top-level chunk records of an MCAP byte string."""
    found, pos = [], 8
    for _ in range(100_000):
        if pos + 9 > len(data):
            break
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x06:
            found.append((pos, length))
        pos += 9 + length
    return found


def test_corrupt_chunk_stops_reading_without_raising(tmp_path: Path) -> None:
    path, _ = _unfinished_copy(tmp_path, 200)
    data = bytearray(path.read_bytes())
    chunks = _chunk_offsets(bytes(data))
    start, length = chunks[len(chunks) // 2]
    middle = start + 9 + length // 2  # inside the compressed records of a middle chunk
    data[middle : middle + 16] = b"\xa5" * 16
    path.write_bytes(bytes(data))
    reader = TailTolerantReader(path)
    got = list(reader.messages())
    assert 0 < len(got) < 200 and reader.error is not None


def test_latency_bound_flushes_without_new_traffic(tmp_path: Path) -> None:
    now = [0.0]
    writer = ArchiveWriter(tmp_path, "m1", max_latency_s=0.1, clock=lambda: now[0])
    writer.write(KEYS[0], _payload(0), T0)
    size = writer.current_file.stat().st_size
    assert not writer.flush_if_due()
    now[0] = 0.15
    assert writer.flush_if_due()
    assert writer.current_file.stat().st_size > size
    assert writer.position == ArchivePosition("m1_20251121T233000Z.mcap", 1, T0)
    writer.close()


def test_writer_rejects_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="prefix"):
        ArchiveWriter(tmp_path, "../evil")
    with pytest.raises(ValueError):
        ArchiveWriter(tmp_path, "m1", rotate_seconds=0)
    with ArchiveWriter(tmp_path, "m1") as writer, pytest.raises(ValueError):
        writer.write(KEYS[0], b"x", -1)


# ----------------------------------------------------------------- SIGKILL crash test

CHILD = """
import os, sys, time
import numpy as np
from millwatch.ingest import keys, wire
from millwatch.ingest.archive import writer as archive
directory, chunk_size, latency = sys.argv[1], int(sys.argv[2]), sys.argv[3]
names = [keys.build_key("s1", "m1", s) for s in ("motor_torque", "pinion_torque", "speed")]
writer = archive.ArchiveWriter(directory, "m1", chunk_size=chunk_size,
                               max_latency_s=None if latency == "none" else float(latency))
os.write(1, b"ready\\n")
for i in range(3000):  # bounded; the parent kills the child long before
    t = time.time_ns()
    for name in names:
        block = wire.encode_block(np.full(10, i, np.float32), t, 1000.0, i, wire.Unit.RPM)
        writer.write(name, block, t)
        os.write(1, (name + " " + str(t) + "\\n").encode())
    time.sleep(0.01)  # one 10-sample block per channel every 10 ms: 1 kHz real time
"""


def _readline(stream: object, timeout_s: float) -> bytes:
    ready, _, _ = select.select([stream], [], [], timeout_s)
    assert ready, "child did not become ready"
    return stream.readline()


def sigkill_loss_ms(
    directory: Path, chunk_size: int, latency: str, run_s: float
) -> dict[str, float]:
    """Run a paced writer, SIGKILL it after ``run_s`` s, recover; loss per key in ms."""
    env = os.environ | {"PYTHONPATH": str(REPO)}
    args = [sys.executable, "-c", CHILD, str(directory), str(chunk_size), latency]
    with subprocess.Popen(args, stdout=subprocess.PIPE, env=env, cwd=REPO) as child:
        try:
            assert _readline(child.stdout, 30.0) == b"ready\n"
            time.sleep(run_s)  # the run itself: real-time pace is the point of the test
            child.send_signal(signal.SIGKILL)
            out = child.communicate(timeout=10)[0]
        finally:
            child.kill()
    last_written: dict[str, int] = {}
    for line in out.decode().splitlines():
        key, t = line.split()
        last_written[key] = int(t)
    (path,) = ArchiveReader(directory, "m1").files()
    report = recover_file(path)
    recovered = report.last_log_time_by_key
    # a key with nothing recovered lost everything: reported as infinity
    return {k: (t - recovered[k]) / 1e6 if k in recovered else float("inf")
            for k, t in last_written.items()}  # fmt: skip


@pytest.mark.parametrize("chunk_size", [4 * 2**10, 64 * 2**10, 2**20])
def test_sigkilled_writer_loses_at_most_200_ms(tmp_path: Path, chunk_size: int) -> None:
    loss = sigkill_loss_ms(tmp_path, chunk_size, "0.1", run_s=1.0)
    log.info("SIGKILL loss, chunk %d B, max_latency 0.1 s: %s ms", chunk_size, loss)
    assert len(loss) == 3
    assert max(loss.values()) <= 200.0


# ----------------------------------------------------------------- throughput


def measure_throughput(directory: Path, n_blocks: int, n_samples: int) -> dict[str, float]:
    """Write then read ``n_blocks`` blocks of ``n_samples`` float32 samples."""
    rng = np.random.default_rng(1)  # noisy samples: realistic compression, not zeros
    unit = wire.Unit.MEGAPASCAL
    payloads = [
        wire.encode_block(rng.normal(size=n_samples).astype(np.float32), T0, 1e3, i, unit)
        for i in range(64)
    ]
    start = time.perf_counter()
    with ArchiveWriter(directory, "m1") as writer:
        for i in range(n_blocks):
            writer.write(KEYS[i % 3], payloads[i % 64], T0 + i * MS)
    write_s = time.perf_counter() - start
    start = time.perf_counter()
    count = sum(1 for _ in ArchiveReader(directory, "m1").blocks())
    read_s = time.perf_counter() - start
    assert count == n_blocks
    mb = n_blocks * len(payloads[0]) / 1e6
    disk = sum(p.stat().st_size for p in directory.glob("*.mcap")) / 1e6
    return {
        "payload_MB": mb, "disk_MB": disk, "write_MB_s": mb / write_s,
        "write_blocks_s": n_blocks / write_s, "read_MB_s": mb / read_s,
        "read_blocks_s": n_blocks / read_s,
    }  # fmt: skip


def test_throughput_is_well_above_live_rate(tmp_path: Path) -> None:
    result = measure_throughput(tmp_path, 20_000, 125)
    log.info("archive throughput (20k blocks x 125 float32): %s", result)
    assert result["write_blocks_s"] > 8_000 and result["read_blocks_s"] > 8_000


def _main() -> None:
    """Measurements for the report: ``.venv/bin/python -m tests.ingest.archive.test_writer``."""
    import tempfile

    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for chunk_size in (4 * 2**10, 64 * 2**10, 2**20):
        for latency in ("0.1", "none"):
            with tempfile.TemporaryDirectory() as tmp:
                loss = sigkill_loss_ms(Path(tmp), chunk_size, latency, run_s=3.0)
            log.info("chunk %7d B, max_latency %-4s s: loss %s ms", chunk_size, latency,
                     {k.rsplit("/", 1)[1]: round(v, 1) for k, v in loss.items()})  # fmt: skip
    for n_samples in (10, 125, 1000):
        with tempfile.TemporaryDirectory() as tmp:
            result = measure_throughput(Path(tmp), 50_000, n_samples)
        log.info("%4d samples/block: %s", n_samples, {k: round(v, 1) for k, v in result.items()})


if __name__ == "__main__":
    _main()
