"""A flood of malformed and random payloads: the worker survives, counts them, archives them,
and the good blocks give exactly the results they give alone."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from millwatch.analytics.drivetrain.mill_config import LifeConfig, MillConfig
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.keys import build_key, channel_key
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
GOOD = [
    QueuedBlock(b.key, b.payload, b.t_end_ns)
    for b in scene_blocks(get_scene("start-lrs", CONFIG, seed=3, duration_s=12.0))
]
KEYS = [channel_key(CONFIG.site, CONFIG.id, c.key) for c in CONFIG.channels.values()]
FOREIGN = build_key("elsewhere", "other-mill", "pinion_torque")


def run(items: list[QueuedBlock], directory: Path) -> tuple[Worker, str]:
    with Store(directory / "mw.db") as store, ArchiveWriter(directory / "a", "w") as archive:
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store,
                        archive)  # fmt: skip
        for item in items:
            worker.handle(item)
        worker.commit()
        analyzer = worker.pipelines[CONFIG.id].analyzer
        analyzer.flush()
        return worker, json.dumps(analyzer.report()["damage"], sort_keys=True)


def mangle(payload: bytes, how: int, junk: bytes) -> bytes:
    """Malformed variants of a good block: bad magic, bad version, truncated, trailing bytes,
    or random bytes."""
    return [
        b"XXXX" + payload[4:],
        payload[:4] + b"\x09\x00" + payload[6:],
        payload[: max(0, len(payload) - 1 - len(junk))],
        payload + b"\x00" + junk,
        junk,
    ][how]


bad_block = st.tuples(st.integers(0, len(GOOD) - 1), st.integers(0, 4), st.binary(max_size=64),
                      st.sampled_from([*KEYS, FOREIGN]))  # fmt: skip

with tempfile.TemporaryDirectory() as _d:
    _, CLEAN = run(GOOD, Path(_d))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, len(GOOD)), bad_block), min_size=1, max_size=60))
def test_bad_payloads_are_counted_and_archived_and_change_nothing(flood):
    items = list(GOOD)
    for at, (src, how, junk, key) in sorted(flood, key=lambda f: -f[0]):
        items.insert(at, QueuedBlock(key, mangle(GOOD[src].payload, how, junk), 0))
    with tempfile.TemporaryDirectory() as d:
        worker, damage = run(items, Path(d))
        archived = sum(1 for _ in ArchiveReader(Path(d) / "a", "w").blocks())
    assert damage == CLEAN
    assert archived == len(items)  # everything is archived as received, bad blocks included
    errors = sum(
        sum(ch.decode_errors.values()) for ch in worker.health[CONFIG.id].channels.values()
    )
    foreign = sum(worker.unrouted.values())
    assert errors + foreign == len(flood)
    assert foreign == sum(1 for f in flood if f[1][3] == FOREIGN)


def test_a_repeated_block_is_ignored_not_counted_twice():
    items = list(GOOD)
    items.insert(40, GOOD[30])
    with tempfile.TemporaryDirectory() as d:
        worker, damage = run(items, Path(d))
    assert damage == CLEAN
    assert sum(ch.repeats for ch in worker.health[CONFIG.id].channels.values()) == 1


def test_sequence_gaps_and_stale_channels_become_data_quality_events():
    items = [it for i, it in enumerate(GOOD) if i not in (41, 50)]  # one block of two channels
    with tempfile.TemporaryDirectory() as d, Store(Path(d) / "mw.db") as store:
        clock = [GOOD[-1].recv_ns]  # (after the scene: no block is from the future)
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store,
                        None, clock=lambda: clock[0])  # fmt: skip
        for item in items:
            worker.handle(QueuedBlock(item.key, item.payload, clock[0]))
        worker.check_staleness(10.0)
        clock[0] += 11 * 10**9
        worker.check_staleness(10.0)
        worker.commit()
        events = store.events(CONFIG.id, "data_quality")
    gaps = [e for e in events if e.data["problem"] == "sequence_gap"]
    stale = [e for e in events if e.data["problem"] == "stale"]
    assert len(gaps) == 2 and all(e.data["missing_blocks"] == 1 for e in gaps)
    assert {e.data["channel"] for e in stale} == set(CONFIG.channels)
    raised = {a.subject for a in worker.pipelines[CONFIG.id].alarms.open_alarms(CONFIG.id)
              if a.rule == "stale_channel"}  # fmt: skip
    assert raised == set(CONFIG.channels)  # silent for 11 s > 10 s: a data-quality alarm


def test_archive_write_failures_raise_the_data_quality_alarm():
    class FullDisk:
        def write(self, *_args: object) -> None:
            raise OSError(28, "No space left on device")

        def flush_if_due(self) -> bool:
            return False

    with tempfile.TemporaryDirectory() as d, Store(Path(d) / "mw.db") as store:
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store,
                        FullDisk())  # fmt: skip
        for item in GOOD[:8]:
            worker.handle(item)
        worker.check_staleness(10.0)
        worker.commit()
        rules = {a.rule for a in store.alarms()}
    assert worker.archive_errors == 8
    assert "archive_write_failures" in rules


def _life_alarms(config: MillConfig) -> set[str]:
    scene = get_scene("steady", config, seed=1, duration_s=90.0)  # > the rule's 60 s delay
    items = [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]
    with tempfile.TemporaryDirectory() as d, Store(Path(d) / "mw.db") as store:
        pipeline = MillJob(config, damage_every_s=5.0, life_every_s=5.0)
        worker = Worker({config.id: config}, {config.id: pipeline}, store, None)
        for item in items:
            worker.handle(item)
        worker.commit()
        return {a.subject for a in store.alarms() if a.rule == "remaining_life"}


def test_a_mill_wearing_out_too_fast_raises_the_remaining_life_alarm():
    fast = CONFIG.model_copy(update={"design_life_years": 1e12})  # any damage is too fast
    no_minimum = fast.model_copy(update={"life": LifeConfig(min_monitoring_days=0, min_starts=0)})
    assert _life_alarms(no_minimum) == {"pinion_combined", "pinion_torsion", "motor_torsion"}
    assert _life_alarms(fast) == set()  # 90 s is below the 14 days a projection needs


def test_harmonic_tables_are_stored_thinned_and_compact():
    scene = get_scene("steady", CONFIG, seed=2, duration_s=400.0)
    items = [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]
    with tempfile.TemporaryDirectory() as d, Store(Path(d) / "mw.db") as store:
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, None)
        for item in items:
            worker.handle(item)
        worker.commit()
        tables = store.records(CONFIG.id, "harmonics")
    assert 1 <= len(tables) <= 2  # ~38 windows in 400 s of running; one stored per 5 min
    latest = tables[0][1]
    assert latest["lines"] and all(line["detected"] for line in latest["lines"])
    assert isinstance(latest["segments"], int)
