"""The mill status as one typed model: the real worker's status survives the JSON of the remote
protocol and of REST unchanged, only what the worker set is sent, and a key the model does not
know where it needs one is an error, not a silent None."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import ValidationError

from millwatch.api.times import with_iso
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.remote.protocol import StatusAnswer, decode, encode
from millwatch.status import NO_STATUS, MillStatus
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import HELD, Worker

MILL = load_mill_config(Path(__file__).resolve().parents[2] / "deploy/mills/ball-dual-lrs.toml")


@pytest.fixture(scope="module")
def status(tmp_path_factory: pytest.TempPathFactory) -> MillStatus:
    """The worker's status of a dual-drive mill after ~80 s of steady running."""
    scene = get_scene("steady", MILL, seed=2, duration_s=80.0)
    with Store(tmp_path_factory.mktemp("status") / "mw.db") as store:
        worker = Worker({MILL.id: MILL}, {MILL.id: MillJob(MILL)}, store, None)
        for b in scene_blocks(scene):
            worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns))
        worker.commit()
        return worker.status(stale_after_s=10.0)[MILL.id]


def test_the_workers_status_is_typed_with_the_mill_files_names(status):
    assert status.state == "running" and 79_900 < (status.samples or 0) <= 80_000
    assert status.latest_steady is not None
    assert set(status.latest_steady.range_pct) == {
        n for n, c in MILL.channels.items() if c.kind == "torque"}  # fmt: skip
    assert set(status.damage) == set(MILL.components)
    assert all(d.with_residue == d.committed + d.pending_residue for d in status.damage.values())
    assert set(status.channel_health) == set(MILL.channels)


def test_the_remote_answer_reads_back_equal(status):
    sent = encode(StatusAnswer(status=status, worker={"name": "w1"}).to_json())
    back = StatusAnswer.model_validate(decode(sent))
    assert back.status == status and back.worker == {"name": "w1"}
    assert back.status.to_json() == status.to_json()


def test_the_api_s_iso_times_are_kept_beside_the_ns_ones(status):
    shown = with_iso(status.to_json())
    again = MillStatus.model_validate(shown)
    assert again.to_json() == shown  # REST: extra ISO keys survive the response model
    assert shown["last_sample"].startswith("2024-01-01T00:01:19.99")
    assert "t" in shown["latest_steady"] and "last_recv" in shown["health"]["channels"]["speed"]


def test_only_what_was_set_is_sent():
    assert NO_STATUS.to_json() == {}  # a mill its worker has not reported yet
    held = MillStatus(state=HELD, held_reason="its checkpoint cannot be restored")
    assert held.to_json() == {"state": HELD, "held_reason": "its checkpoint cannot be restored"}
    copy = held.model_copy(update={"stalled_reason": None})
    assert set(copy.to_json()) == {"state", "held_reason", "stalled_reason"}


def test_a_missing_or_mistyped_key_is_an_error_not_a_silent_none(status):
    data = json.loads(json.dumps(status.to_json()))
    del data["health"]["channels"]["speed"]["blocks"]
    with pytest.raises(ValidationError, match="blocks"):
        MillStatus.model_validate(data)
    data = json.loads(json.dumps(status.to_json()))
    data["latest_steady"]["range_pct"] = "high"
    with pytest.raises(ValidationError, match="range_pct"):
        MillStatus.model_validate(data)
