"""Reading the archive in batches: the same messages, positions and stopping rules as the
per-message reader; the fast message appender writes the bytes ``add_message`` writes."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import CompressionType, Writer

from millwatch.ingest import keys, wire
from millwatch.ingest.archive.batches import BatchReader, MessageBatch, archive_batches
from millwatch.ingest.archive.files import ArchivePosition
from millwatch.ingest.archive.mcap_append import appender, pack_chunk_indexes
from millwatch.ingest.archive.reader import ArchiveReader, TailTolerantReader
from millwatch.ingest.archive.writer import ArchiveWriter

T0 = 1_763_767_800_000_000_000
SIGNALS = ("motor_torque", "pinion_torque", "pinion_bending", "speed")
KEYS = [keys.build_key("s1", f"m{i % 3}", SIGNALS[i % 4]) for i in range(7)]


def _archive(directory: Path, count: int = 3000, seed: int = 0) -> list[Path]:
    rng = np.random.default_rng(seed)
    with ArchiveWriter(directory, "t", chunk_size=3000, rotate_seconds=50) as w:
        for k in range(count):
            w.write(
                KEYS[k % len(KEYS)], rng.bytes(int(rng.integers(0, 200))), T0 + 10**9 * (k // 20)
            )
    return sorted(directory.glob("t_*.mcap"))


def _per_message(path: Path) -> tuple[list, TailTolerantReader]:
    reader = TailTolerantReader(path)
    return [(m.key, m.log_time_ns, m.payload, m.index) for m in reader.messages()], reader


def _batched(path: Path) -> tuple[list, BatchReader]:
    reader = BatchReader(path)
    out = [
        (b.topics[int(b.channel[k])], int(b.log_time[k]), b.payload(k), int(b.index[k]))
        for b in reader.messages()
        for k in range(len(b))
    ]
    return out, reader


def _same(path: Path) -> None:
    (want, a), (got, b) = _per_message(path), _batched(path)
    assert got == want
    assert (b.error, b.finished, b.valid_bytes, b.torn_bytes, b.message_count) == (
        a.error, a.finished, a.valid_bytes, a.torn_bytes, a.message_count,
    )  # fmt: skip


def test_batches_hold_exactly_the_messages_of_the_per_message_reader(tmp_path: Path) -> None:
    files = _archive(tmp_path)
    assert len(files) == 3
    for path in files:
        _same(path)


@pytest.mark.parametrize("cut", [-7, -500, 0.5, 0.1, 100, 30, 9])
def test_torn_tails_stop_both_readers_at_the_same_record(tmp_path: Path, cut: float) -> None:
    data = _archive(tmp_path / "a")[1].read_bytes()
    end = int(len(data) * cut) if isinstance(cut, float) else (cut if cut > 0 else len(data) + cut)
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:end])
    _same(path)


@pytest.mark.parametrize("pos", [300, 2000, 5000, 20000, 60000])
def test_a_corrupt_chunk_stops_both_readers_alike(tmp_path: Path, pos: int) -> None:
    data = bytearray(_archive(tmp_path / "a")[0].read_bytes())
    data[pos] ^= 0x55
    path = tmp_path / "bad.mcap"
    path.write_bytes(bytes(data))
    _same(path)


def test_archive_batches_resume_after_a_position_like_the_block_reader(tmp_path: Path) -> None:
    files = _archive(tmp_path)
    for after in (None, ArchivePosition(files[1].name, 37), ArchivePosition(files[2].name, 0)):
        want = [(b.key, b.log_time_ns, b.payload, b.file, b.index)
                for b in ArchiveReader(tmp_path, "t").blocks(after=after)]  # fmt: skip
        batches = list(archive_batches(tmp_path, "t", after, min_messages=500))
        got = [(b.topics[int(b.channel[k])], int(b.log_time[k]), b.payload(k), b.file,
                int(b.index[k])) for b in batches for k in range(len(b))]  # fmt: skip
        assert got == want
        assert all(len(b) >= 500 for b in batches[:-1] if b.file == batches[-1].file)


def test_concat_and_select_keep_payloads(tmp_path: Path) -> None:
    batches = list(BatchReader(_archive(tmp_path)[0]).messages())
    both = MessageBatch.concat(batches[:3])
    flat = [b.payload(k) for b in batches[:3] for k in range(len(b))]
    assert [both.payload(k) for k in range(len(both))] == flat
    odd = both.select(both.index % 2 == 1)
    assert [odd.payload(k) for k in range(len(odd))] == flat[1::2]
    packed = odd.compact()
    assert [packed.payload(k) for k in range(len(packed))] == flat[1::2]
    assert packed.buf.shape[0] == sum(len(p) for p in flat[1::2]) < both.buf.shape[0]
    assert np.array_equal(packed.index, odd.index) and packed.file == odd.file


def _mcap_bytes(fast: bool, chunk_size: int) -> bytes:
    stream = io.BytesIO()
    writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType.ZSTD)
    writer.start(profile="p", library="l")
    writer.register_schema("s", "e", b"d")
    rng = np.random.default_rng(3)
    ids = [writer.register_channel(topic=f"t{i}", message_encoding="m", schema_id=1)
           for i in range(5)]  # fmt: skip
    fast_path = appender(writer, chunk_size) if fast else None
    for k in range(500):
        data = rng.bytes(int(rng.integers(0, 300)))
        t = T0 + int(rng.integers(-(10**6), 10**9))  # out-of-order times too
        if fast_path is not None:
            fast_path.append(ids[k % 5], k, t, data)
        else:
            writer.add_message(ids[k % 5], log_time=t, data=data, publish_time=t, sequence=k)
        if k == 250:
            writer.flush()
    if fast:
        pack_chunk_indexes(writer)
    writer.finish()
    return stream.getvalue()


@pytest.mark.parametrize("chunk_size", [1, 700, 64 * 1024])
def test_fast_appender_and_index_write_the_bytes_add_message_writes(chunk_size: int) -> None:
    assert _mcap_bytes(True, chunk_size) == _mcap_bytes(False, chunk_size)


def test_bulk_header_decoding_accepts_exactly_what_decode_block_accepts() -> None:
    rng = np.random.default_rng(1)
    payloads = []
    for k in range(3000):
        dtype = rng.choice([np.float32, np.float64, np.int16, np.int32])
        samples = (rng.random(int(rng.integers(0, 40))) * 100).astype(dtype)
        t0, fs = int(rng.integers(-(2**62), 2**62)), float(rng.choice([1000.0, 0.5]))
        seq, unit = int(rng.integers(0, 2**63)), wire.Unit(int(rng.integers(1, 6)))
        p = bytearray(wire.encode_block(samples, t0, fs, seq, unit))
        for _ in range(int(rng.integers(0, 3)) if k % 3 == 0 else 0):
            p[int(rng.integers(0, len(p)))] = int(rng.integers(0, 256))
        if k % 7 == 0:
            p = p[: int(rng.integers(0, len(p) + 1))]
        payloads.append(bytes(p))
    lengths = np.array([len(p) for p in payloads])
    offsets = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    head, ok = wire.decode_headers(np.frombuffer(b"".join(payloads), np.uint8), offsets, lengths)
    for k, p in enumerate(payloads):
        try:
            block = wire.decode_block(p)
        except wire.WireError:
            assert not ok[k]
            continue
        assert ok[k]
        assert (head["t0_ns"][k], int(head["seq"][k]), head["n"][k], head["fs"][k]) == (
            block.t0_ns, block.seq, len(block.samples), block.fs,
        )  # fmt: skip
    assert 0 < ok.sum() < len(payloads)
