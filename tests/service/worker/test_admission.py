"""One block admission for every path: the live worker (block by block, archiving), its archive
replay (the batch lane) and offline analysis (``millwatch analyze``'s code) admit and refuse
the same blocks of the same sequence — repeats, a gap, a clock fault, malformed payloads, a
foreign key — and count them alike."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.keys import build_key, to_replay
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import Block, DType, Unit, decode_block, encode_block
from millwatch.store.database import Store
from millwatch.worker.admission import BlockAdmission
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.health import ChannelHealth
from millwatch.worker.mill_job import MillJob
from millwatch.worker.offline_analysis import analyze_files
from millwatch.worker.recovery import recover
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
BASE = load_mill_config(MILL)
CONFIGS = [BASE.model_copy(update={"id": f"mill-{i}"}) for i in range(2)]
FOREIGN = build_key("elsewhere", "other-mill", "pinion_torque")


def _shifted(item: QueuedBlock, by_ns: int) -> QueuedBlock:
    """The same block with a t0 ``by_ns`` off its sequence number's time (a gateway clock)."""
    b = decode_block(item.payload)
    payload = encode_block(b.samples, b.t0_ns + by_ns, b.fs, b.seq, b.unit, b.dtype)
    return QueuedBlock(item.key, payload, item.recv_ns)


def _items() -> list[QueuedBlock]:
    """Two mills' interleaved blocks; mill-1's with a duplicate, an older repeat, a gap, a
    clock-fault episode of three blocks, a bad magic and a truncated payload; a foreign key
    every 101 blocks."""
    per_mill = []
    for i, config in enumerate(CONFIGS):
        scene = get_scene("start-lrs", config, seed=i, duration_s=30.0)
        blocks = scene_blocks(scene, block_samples=100, dtype=DType.FLOAT32)
        per_mill.append([QueuedBlock(b.key, b.payload, b.t_end_ns) for b in blocks])
    m1 = per_mill[1]
    m1[300] = QueuedBlock(m1[300].key, b"JUNK" * 20, m1[300].recv_ns)
    m1[301] = QueuedBlock(m1[301].key, m1[301].payload[:-3], m1[301].recv_ns)
    m1.insert(401, m1[400])  # the same block again: a duplicate
    m1.insert(600, m1[520])  # an older one: a replay
    del m1[700:708]  # two blocks of every channel lost: a gap
    for k in (900, 904, 908):  # one channel's t0 ten seconds off, three blocks running
        m1[k] = _shifted(m1[k], 10_000_000_000)
    out = []
    for k in range(max(len(b) for b in per_mill)):
        out += [blocks[k] for blocks in per_mill if k < len(blocks)]
        if k % 101 == 0:
            out.append(QueuedBlock(FOREIGN, b"whatever", out[-1].recv_ns))
    return out


def _counters(health: dict) -> str:
    return json.dumps({m: {c: h.counters() for c, h in mh.channels.items()}
                       for m, mh in health.items()}, sort_keys=True)  # fmt: skip


def _worker(store: Store) -> Worker:
    return Worker({c.id: c for c in CONFIGS}, {c.id: MillJob(c) for c in CONFIGS},
                  store, None)  # fmt: skip


def test_live_replayed_and_offline_paths_admit_and_count_the_same_blocks(tmp_path: Path) -> None:
    items = _items()
    with Store(tmp_path / "live.db") as s1, Store(tmp_path / "replay.db") as s2:
        live = Worker({c.id: c for c in CONFIGS}, {c.id: MillJob(c) for c in CONFIGS}, s1,
                      ArchiveWriter(tmp_path / "archive", "w", chunk_size=8192))  # fmt: skip
        for k, item in enumerate(items):
            live.handle(item)
            if k % 3000 == 2999:
                live.commit()
        live.commit()
        assert live.archive is not None
        live.archive.close()
        replayed = _worker(s2)
        assert recover(replayed, ArchiveReader(tmp_path / "archive", "w")) == len(items)
        files = sorted((tmp_path / "archive").glob("*.mcap"))
        offline, stats = analyze_files(files, CONFIGS)
        try:
            counters = _counters(live.health)
            assert _counters(replayed.health) == counters
            assert _counters(offline.admission.health) == counters
            assert dict(live.unrouted) == dict(replayed.unrouted) == dict(offline.admission.foreign)
            assert stats.foreign_blocks == sum(live.unrouted.values()) > 0
            for m in live.mills:  # the same blocks admitted: the same analysis
                analyzer = live.pipelines[m].analyzer  # type: ignore[attr-defined]
                analyzer.flush()  # (as the offline analysis ends)
                damage = json.dumps(analyzer.report()["damage"], sort_keys=True)
                assert json.dumps(offline.analyzers[m].report()["damage"], sort_keys=True) == damage
        finally:
            offline.close()
    channels = live.health["mill-1"].channels.values()
    assert sum(h.duplicates for h in channels) == 1
    assert sum(h.replays for h in channels) == 1
    assert sum(h.missing_blocks for h in channels) == 8 + 2  # (a malformed block's seq is lost)
    assert sum(h.clock_faults for h in channels) == 3
    assert live.admission.malformed() == stats.malformed_blocks == {"bad_magic": 1, "truncated": 1}
    assert live.health["mill-0"].channels["motor_torque"].repeats == 0


def test_replay_keys_are_their_channels_offline_and_foreign_live() -> None:
    key = build_key(BASE.site, "mill-0", "motor_torque")
    first = next(iter(scene_blocks(get_scene("start-lrs", CONFIGS[0], duration_s=1.0))))
    payload, recv = first.payload, first.t_end_ns
    replay_key = to_replay(key, "run1")
    live = BlockAdmission(CONFIGS)
    offline = BlockAdmission(CONFIGS, replayed=True, warn_foreign=False)
    assert live.admit(replay_key, payload, recv) is None
    assert live.foreign == {replay_key.rpartition("/")[0]: 1}  # (counted per prefix)
    got = offline.admit(replay_key, payload, recv)
    assert got is not None and (got.mill_id, got.channel) == ("mill-0", "motor_torque")
    assert offline.foreign_blocks == 0


@settings(max_examples=200, deadline=None)
@given(
    start=st.sampled_from([None, 9, 10]),
    jitter=st.lists(st.integers(-60, 60), min_size=1, max_size=6),
    seq_step=st.lists(st.sampled_from([1, 1, 1, 0, 2, 100_000]), min_size=6, max_size=6),
    ahead_s=st.lists(st.sampled_from([0, 0, 0, 59, 61, 7200]), min_size=6, max_size=6),
)
def test_a_run_is_regular_exactly_when_accepting_it_block_by_block_finds_nothing(
    start: int | None, jitter: list[int], seq_step: list[int], ahead_s: list[int]
) -> None:
    """The batch lane's test of a run (``follows_on``) is the admission rule: jitter of the
    t0 (in % of a block), sequence steps (a +100,000 jump among them) and how far each block
    reaches ahead of its receive time (the default limit: 60 s) drawn at random."""
    step = 100_000_000  # 100 samples at 1 kHz
    health = ChannelHealth()
    if start is not None:  # the channel's last accepted block: seq 10 at t0 = 0
        health.accept(Block(np.zeros(100), 0, 1000.0, 10, Unit.RPM, DType.FLOAT64), step)
    seq = 11 + np.cumsum([0, *seq_step[: len(jitter) - 1]]) - (start == 9)
    t0 = (seq - 10) * step + np.array(jitter) * step // 100
    recv = t0 + step - np.array(ahead_s[: len(jitter)]) * 10**9
    regular = health.follows_on(seq.astype(np.uint64), t0.astype(np.int64), step, recv)
    verdicts = []
    for s, t, r in zip(seq.tolist(), t0.tolist(), recv.tolist(), strict=True):
        got = health.accept(Block(np.zeros(100), t, 1000.0, s, Unit.RPM, DType.FLOAT64), r)
        verdicts.append(got.verdict in ("first", "next") and got.clock_fault is None
                        and not health.in_clock_fault)  # fmt: skip
    assert regular == all(verdicts)
