"""A store filled through the real pipeline (``Worker.handle`` → ``MillJob`` → SQLite) with
short simulated scenes in chosen months, for the month-end job and ``millwatch report`` tests.

Each (mill, month) segment is a 130 s LRS or Grid start/run/stop scene placed at a given UTC
time and analysed by its own worker (sequence numbers start afresh per scene), so the store holds
real events, damage rows, steady windows and harmonic tables in each month — kept short so a
test module builds it in a few seconds."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import UTC, datetime
from pathlib import Path

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.publisher import starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import StartEvent, StopEvent
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILLS_DIR = Path(__file__).resolve().parents[3] / "deploy" / "mills"


def mill(name: str, **update: object) -> MillConfig:
    """A deploy/mills configuration, optionally changed (e.g. another ``time_zone``)."""
    config = load_mill_config(MILLS_DIR / f"{name}.toml")
    return config.model_copy(update=update) if update else config


def utc_ns(text: str) -> int:
    """ns since the epoch of an ISO time in UTC (``2024-01-15T10:00``)."""
    return int(datetime.fromisoformat(text).replace(tzinfo=UTC).timestamp()) * 10**9


def fill(path: Path, segments: Iterable[tuple[MillConfig, str]], seed: int = 1) -> None:
    """Analyse one short start/run/stop scene per ``(config, UTC start time)`` into the store
    at ``path``, and record each mill's configuration as the service does."""
    with Store(path) as store:
        for i, (config, start) in enumerate(segments):
            store.put_mill(
                config.id,
                config.site,
                config.stored_form(),
                utc_ns(start),
            )
            scene = get_scene(
                "start-lrs",
                config,
                seed=seed + i,
                duration_s=130.0,
                events=(StartEvent(at_s=5.0), StopEvent(at_s=100.0)),
            )
            scene = starting_now(scene, utc_ns(start))
            worker = Worker(
                {config.id: config}, {config.id: MillJob(config, damage_every_s=10.0)}, store, None
            )
            for b in scene_blocks(scene):
                worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns))
            worker.commit()
