"""Replaying the archive with several processes (the mills split between them) leaves exactly
what a single-process replay leaves: stored rows, pipeline state, health; a failing job stops the
replay with an error that names its mills."""

from __future__ import annotations

import logging
import os
import shutil
import signal
from collections.abc import Callable
from pathlib import Path

import pytest

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.spectra.tracker import HarmonicTracker
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.store.database import Store
from millwatch.worker import parallel_replay
from millwatch.worker.mill_job import MillJob
from millwatch.worker.parallel_replay import ReplayJobError, replay_jobs, split_mills
from millwatch.worker.recovery import recover
from millwatch.worker.worker import Worker
from tests.service.worker.test_batch_lane import BASE, CONFIGS, _items, _state
from tests.service.worker.test_checkpoints import _damage_rows


class FailingPipeline(MillJob):
    """A pipeline whose analysis fails for ``mill-1`` (module level: a job process imports it)."""

    def finish(self):  # type: ignore[no-untyped-def]
        if self.config.id == "mill-1":
            raise RuntimeError("analysis broke on purpose")
        return super().finish()


class DyingPipeline(MillJob):
    """A pipeline whose process is killed (SIGKILL) in ``mill-2``'s analysis."""

    def finish(self):  # type: ignore[no-untyped-def]
        if self.config.id == "mill-2":
            os.kill(os.getpid(), signal.SIGKILL)
        return super().finish()


def _archive(directory: Path) -> ArchiveReader:
    with ArchiveWriter(directory, "w", chunk_size=8192) as archive:
        for item in _items():
            archive.write(item.key, item.payload, item.recv_ns)
    return ArchiveReader(directory, "w")


def _worker(store: Store, factory=MillJob) -> Worker:  # type: ignore[no-untyped-def]
    return Worker({c.id: c for c in CONFIGS}, {c.id: factory(c) for c in CONFIGS}, store, None)


@pytest.fixture
def always_parallel(monkeypatch: pytest.MonkeyPatch) -> None:
    """Job processes even for the small test archive."""
    monkeypatch.setattr(parallel_replay, "PARALLEL_MIN_BYTES", 0)


@pytest.mark.slow
@pytest.mark.usefixtures("always_parallel")
def test_parallel_replay_equals_one_process(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    reader = _archive(tmp_path / "a")
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "two.db") as s2:
        one, two = _worker(s1), _worker(s2)
        alarms_one: list = []
        alarms_two: list = []
        one.on_alarms, two.on_alarms = alarms_one.extend, alarms_two.extend
        n = recover(one, reader)
        with caplog.at_level(logging.INFO, logger="millwatch"):
            assert recover(two, reader, jobs=2, factory=MillJob) == n == len(_items())
        assert "replayed by 2 process(es)" in caplog.text
        assert _state(two, s2) == _state(one, s1)
        assert sorted(t.to_row()["alarm_id"] for t in alarms_two) == sorted(
            t.to_row()["alarm_id"] for t in alarms_one
        )
        for m in one.mills:  # the parent's pipelines hold the final state: they go on alike
            assert two.pipelines[m].snapshot() == one.pipelines[m].snapshot()
            assert two.health[m] == one.health[m]


@pytest.mark.slow
@pytest.mark.usefixtures("always_parallel")
def test_parallel_replay_after_checkpoints_skips_what_they_hold(tmp_path: Path) -> None:
    """Checkpoints at different archive positions per mill: every mill sees each of its blocks
    once, as in one process."""
    # mill-0 at the first position, mill-2 at the second
    reader = _checkpointed_archive(tmp_path, {1500: ["mill-0"], 4000: ["mill-2"]})
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "two.db") as s2:
        one, two = _worker(s1), _worker(s2)
        recover(one, reader)
        recover(two, reader, jobs=2, factory=MillJob)
        assert _state(two, s2) == _state(one, s1)


@pytest.mark.slow
@pytest.mark.usefixtures("always_parallel")
@pytest.mark.parametrize(
    ("factory", "error"),
    [
        (FailingPipeline, r"mill-1.*analysis broke on purpose"),  # an exception in the job
        (DyingPipeline, r"mill-2.*exited with code -9"),  # the job process SIGKILLed
    ],
)
def test_a_failing_or_killed_job_stops_the_replay_naming_its_mills(
    tmp_path: Path, factory: type[MillJob], error: str
) -> None:
    reader = _archive(tmp_path / "a")
    with Store(tmp_path / "mw.db") as store:
        worker = _worker(store, factory)
        with pytest.raises(ReplayJobError, match=error):
            recover(worker, reader, jobs=3, factory=factory)


def _checkpointed_archive(
    tmp_path: Path, at: dict[int, list[str] | None] | None = None
) -> ArchiveReader:
    """The test archive written by a live worker into ``one.db`` (copied to ``two.db``), which
    checkpoints the mills of ``at[k]`` (None: every mill) after block ``k``; by default every
    mill halfway (configuration of then)."""
    at = {3000: None} if at is None else at
    with ArchiveWriter(tmp_path / "a", "w", chunk_size=8192) as archive, Store(
        tmp_path / "one.db"
    ) as live_store:  # fmt: skip
        live = _worker(live_store)
        live.archive = archive
        for k, item in enumerate(_items()):
            live.handle(item)
            if k in at:
                live.checkpoint(at[k])
    shutil.copy(tmp_path / "one.db", tmp_path / "two.db")
    return ArchiveReader(tmp_path / "a", "w")


def _edited(edit: Callable[[MillConfig], MillConfig]) -> dict[str, MillConfig]:
    """Each mill's configuration after the operator's ``edit``."""
    return {c.id: edit(c) for c in CONFIGS}


def _faster(c: MillConfig) -> MillConfig:
    """Motor 995 → 1000 rpm: the pinion speed, hence the spectra's bins, change."""
    return c.model_copy(update={"drive": c.drive.model_copy(update={"motor_speed_rpm": 1000.0})})


@pytest.mark.slow
@pytest.mark.usefixtures("always_parallel")
def test_after_a_pinion_speed_change_jobs_restart_the_spectra_as_one_process_does(
    tmp_path: Path,
) -> None:
    reader = _checkpointed_archive(tmp_path)
    mills = _edited(_faster)
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "two.db") as s2:
        one, two = (Worker(mills, {m: MillJob(c) for m, c in mills.items()}, s, None)
                    for s in (s1, s2))  # fmt: skip
        recover(one, reader)
        recover(two, reader, jobs=2, factory=MillJob)
        assert _state(two, s2) == _state(one, s1)
        for m in mills:  # mill-1 and mill-2's stored by the job that replayed them
            events = s2.events(m, "data_quality")
            assert sum(e.data["problem"] == "spectra_restarted" for e in events) == 3
    for m, config in mills.items():
        harmonics = two.pipelines[m].analyzer._harmonics  # type: ignore[attr-defined]
        assert harmonics.bins == HarmonicTracker(config).bins != HarmonicTracker(BASE).bins
        assert harmonics.counters["running_samples"] > 0


@pytest.mark.slow
@pytest.mark.usefixtures("always_parallel")
def test_a_held_mill_fails_no_job_and_the_others_replay_as_in_one_process(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """mill-1's checkpoint cannot be restored (a channel removed since): it is held, in no job's
    group, its blocks observed by the worker's own lane and never analysed."""
    reader = _checkpointed_archive(tmp_path)

    def drop_bending(c: MillConfig) -> MillConfig:
        if c.id != "mill-1":
            return c
        kept = {n: ch for n, ch in c.channels.items() if n != "pinion_bending"}
        return c.model_copy(update={"channels": kept})

    mills = _edited(drop_bending)
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "two.db") as s2:
        one, two = (Worker(mills, {m: MillJob(c) for m, c in mills.items()}, s, None)
                    for s in (s1, s2))  # fmt: skip
        recover(one, reader)
        with caplog.at_level(logging.INFO, logger="millwatch"):
            recover(two, reader, jobs=3, factory=MillJob)
        assert "replaying the archive with 2 processes: mill-0; mill-2" in caplog.text
        assert list(two.held) == list(one.held) == ["mill-1"]
        assert two.held["mill-1"].startswith("mill mill-1: its checkpoint (at archive file")
        assert "channel(s) removed 'pinion_bending'" in two.held["mill-1"]
        assert two.held_blocks["mill-1"] == one.held_blocks["mill-1"] > 0
        assert two.pipelines["mill-1"].analyzer.samples == 0  # type: ignore[attr-defined]
        assert _state(two, s2) == _state(one, s1)


def test_job_count_follows_the_tail_the_mills_and_the_cores() -> None:
    big = 10 * parallel_replay.PARALLEL_MIN_BYTES
    assert replay_jobs(4, 50, big) == 4
    assert replay_jobs(4, 3, big) == 3  # at most one per mill
    assert replay_jobs(4, 50, parallel_replay.PARALLEL_MIN_BYTES - 1) == 1  # short tail
    assert 1 <= replay_jobs(0, 50, big) <= parallel_replay.available_cores()
    with pytest.raises(ValueError, match="recovery_jobs"):
        replay_jobs(-1, 50, big)


def test_mills_are_split_in_id_order_the_reader_taking_a_smaller_share() -> None:
    ids = [f"m{i:02d}" for i in range(50)]
    groups = split_mills(reversed(ids), 2)
    assert [len(g) for g in groups] == [24, 26]  # the reader also reads the archive
    assert [m for g in groups for m in g] == ids
    assert [len(g) for g in split_mills(ids, 4)] == [12, 13, 13, 12]
    assert split_mills(ids[:2], 2) == [["m00"], ["m01"]]
    assert split_mills(ids[:1], 3) == [["m00"]]


def test_configs_pickle_for_the_job_processes() -> None:
    import pickle

    assert pickle.loads(pickle.dumps(CONFIGS[0])) == CONFIGS[0]
    assert isinstance(CONFIGS[0], MillConfig)


@pytest.mark.slow
@pytest.mark.usefixtures("always_parallel")
def test_damaged_checkpoints_are_refused_alike_by_the_jobs(tmp_path: Path) -> None:
    """mill-1's newest checkpoint truncated (it falls back to its previous one) and both of
    mill-2's damaged (it replays the archive from its start): the jobs choose the same
    checkpoints as the worker, and the results equal one process's."""
    reader = _checkpointed_archive(tmp_path, {1500: None, 4000: None})
    for db in ("one.db", "two.db"):
        with Store(tmp_path / db) as store:
            _damage_rows(store, "mill-1", ["truncate"])
            _damage_rows(store, "mill-2", ["flip", "truncate"])
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "two.db") as s2:
        one, two = _worker(s1), _worker(s2)
        recover(one, reader)
        recover(two, reader, jobs=3, factory=MillJob)
        assert two.checkpoints_refused == one.checkpoints_refused == {"mill-1": 1, "mill-2": 2}
        here = [_state(w, s).replace(str(s.path), "<store>") for w, s in ((one, s1), (two, s2))]
        assert here[1] == here[0]
