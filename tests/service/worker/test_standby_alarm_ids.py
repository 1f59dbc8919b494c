"""A primary and its hot standby fed the same blocks raise the same alarm ids, also for the
wall-clock ``stale_channel`` alarm when the data ends (issue 30: "alarms once")."""

from __future__ import annotations

import tempfile
from pathlib import Path

from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
BLOCKS = list(scene_blocks(get_scene("start-lrs", CONFIG, seed=3, duration_s=12.0)))


def stale_alarm_ids(received_late_ns: int, ticks_ns: list[int]) -> set[str]:
    """The stale-channel alarm ids one worker raises: it receives the scene's blocks
    ``received_late_ns`` after they end (network jitter), then checks staleness at its own
    clock ``ticks_ns`` after the last block arrived (the data has ended)."""
    with tempfile.TemporaryDirectory() as d, Store(Path(d) / "mw.db") as store:
        last = BLOCKS[-1].t_end_ns + received_late_ns
        clock = [last]
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store,
                        None, clock=lambda: clock[0])  # fmt: skip
        for b in BLOCKS:
            worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns + received_late_ns))
        for tick in ticks_ns:
            clock[0] = last + tick
            worker.check_staleness(10.0)
        worker.commit()
        return {a.alarm_id for a in store.alarms() if a.rule == "stale_channel"}


def test_two_workers_with_different_clocks_raise_one_stale_channel_alarm_per_channel():
    # the primary looks twice a second from its start, the standby on its own phase, with its
    # blocks received 37 ms later: their silences cross 10 s at different wall times
    primary = stale_alarm_ids(3_000_000, [k * 500_000_000 for k in range(1, 26)])
    standby = stale_alarm_ids(40_000_000, [k * 500_000_000 + 271_000_000 for k in range(1, 26)])
    assert len(primary) == len(CONFIG.channels)  # one per silent channel
    assert primary == standby
