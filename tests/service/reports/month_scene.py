"""The simulated scene the report tests share: three LRS starts of the SAG mill on 1 January 2024
(a stop, a trip, a stop), analysed through the real worker into a real SQLite store, one block
left out (a sequence gap: a data-quality event). Fixtures in ``conftest.py`` build it once per
test session."""

from __future__ import annotations

from pathlib import Path

from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import StartEvent, StopEvent, TripEvent
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
MONTH = "2024-01"  # the scene starts at 2024-01-01T00:00Z = 02:00 in Johannesburg
EVENTS = (StartEvent(at_s=5.0), StopEvent(at_s=100.0), StartEvent(at_s=160.0),
          TripEvent(at_s=260.0), StartEvent(at_s=320.0), StopEvent(at_s=420.0))  # fmt: skip
DROPPED = 2001  # one block left out: a sequence gap, i.e. a data-quality event


def fill_store(path: Path) -> None:
    """Simulate the scene and analyse it into the store at ``path``."""
    scene = get_scene("start-lrs", CONFIG, seed=1, duration_s=470.0, events=EVENTS)
    blocks = [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]
    with Store(path) as s:
        pipeline = MillJob(CONFIG, damage_every_s=10.0)
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: pipeline}, s, None)
        for i, block in enumerate(blocks):
            if i != DROPPED:
                worker.handle(block)
        worker.commit()
