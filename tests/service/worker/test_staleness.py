"""No channel is declared absent while a restarted worker's recovery is still arriving (issue
25): silence counts from the worker's subscription and from receipt, not from the receive times
a checkpoint restored nor from when the analysis gets to a block; a channel that really stays
silent is still declared stale, and the others are released."""

from __future__ import annotations

import json
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
SCENE = get_scene("start-lrs", CONFIG, seed=3, duration_s=30.0)
BLOCKS = [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(SCENE)]
S = 10**9


class Clock:
    def __init__(self, t_ns: int) -> None:
        self.t_ns = t_ns

    def __call__(self) -> int:
        return self.t_ns


def _worker(store: Store, clock: Clock) -> Worker:
    return Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, None, clock=clock)


def _analysis(worker: Worker, store: Store) -> str:
    worker.commit()
    analyzer = worker.pipelines[CONFIG.id].analyzer  # type: ignore[attr-defined]
    analyzer.flush()
    events = [(e.kind, e.t_ns, e.data) for e in store.events(CONFIG.id)
              if e.kind != "data_quality"]  # fmt: skip
    return json.dumps({"report": analyzer.report(), "events": events}, sort_keys=True)


def _problems(store: Store) -> list[tuple[str, str]]:
    return [(e.data["channel"], e.data["problem"]) for e in store.events(CONFIG.id, "data_quality")]


def test_a_restarted_worker_waits_for_every_channels_recovered_history(tmp_path: Path) -> None:
    cut = len(BLOCKS) // 6  # the worker dies here; 35 s later it is back
    end_ns = BLOCKS[-1].recv_ns
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "two.db") as s2:
        reference = _worker(s1, Clock(end_ns))
        for item in BLOCKS:
            reference.handle(item)
        clock = Clock(BLOCKS[cut].recv_ns)
        worker = _worker(s2, clock)
        for item in BLOCKS[:cut]:  # (what its archive replay restores: receive times of then)
            worker.handle(item)
        clock.t_ns += 35 * S
        worker.awaiting_gateways([CONFIG.id])
        worker.check_staleness(10.0)  # not subscribed yet: nothing can have come
        worker.listening(CONFIG.id)
        # each channel's history in turn, the last one 8 s after the subscription
        history = sorted(BLOCKS[cut:], key=lambda b: b.key)
        per_channel = len(history) // len(CONFIG.channels)
        received: dict[str, int] = {}
        for k, item in enumerate(history):
            if k % per_channel == 0:
                clock.t_ns += 2 * S
                worker.check_staleness(10.0, received)
            received[item.key] = clock.t_ns
            worker.handle(QueuedBlock(item.key, item.payload, clock.t_ns))
        worker.check_staleness(10.0, received)
        worker.commit()
        assert _problems(s2) == []
        assert _analysis(worker, s2) == _analysis(reference, s1)


def test_received_blocks_keep_their_channel_fresh_and_a_silent_one_goes_stale(
    tmp_path: Path,
) -> None:
    with Store(tmp_path / "mw.db") as store:
        clock = Clock(BLOCKS[0].recv_ns)
        worker = _worker(store, clock)
        worker.listening(CONFIG.id)
        speed = next(k for k in {b.key for b in BLOCKS} if k.endswith("/speed"))
        for item in BLOCKS[:400]:
            if item.key != speed:
                worker.handle(QueuedBlock(item.key, item.payload, clock.t_ns))
        clock.t_ns += 11 * S
        # blocks of every channel but speed received 1 s ago, still queued (a backlog)
        received = {b.key: clock.t_ns - S for b in BLOCKS[:8] if b.key != speed}
        worker.check_staleness(10.0, received)
        worker.commit()
        assert _problems(store) == [("speed", "stale")]
        analyzer = worker.pipelines[CONFIG.id].analyzer  # type: ignore[attr-defined]
        assert analyzer.missing_blocks == 300 // 3  # released: speed as NaN
        alarms = {a.subject for a in worker.pipelines[CONFIG.id].alarms.open_alarms(CONFIG.id)
                  if a.rule == "stale_channel"}  # fmt: skip
        assert alarms == {"speed"}
