"""Per-mill checkpoints: the turns spread over the interval, and a recovery from mills
checkpointed at different archive positions equals the uninterrupted run."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import pytest

from millwatch.analytics.drivetrain.mill_config import ChannelConfig, MillConfig
from millwatch.analytics.spectra.tracker import HarmonicTracker
from millwatch.ingest.archive.files import ArchivePosition
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.publisher import starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import decode_block
from millwatch.store.database import Store
from millwatch.worker.block_queue import BlockQueue, QueuedBlock
from millwatch.worker.checkpoints import CheckpointSchedule, MillHeldError, covers, earliest
from millwatch.worker.mill_job import MillJob
from millwatch.worker.recovery import recover
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
BASE = load_mill_config(MILL)
CONFIGS = {m: BASE.model_copy(update={"id": m}) for m in ("mill-a", "mill-b")}


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_turns_are_spread_over_the_interval_and_late_ones_do_not_pile_up() -> None:
    clock = FakeClock()
    schedule = CheckpointSchedule(["c", "a", "b", "d"], 60.0, clock)
    seen = []
    for _ in range(8):  # 2 minutes in 15 s steps
        clock.t += 15.0
        for part in schedule.due():
            seen.append((clock.t - 100.0, part))
            schedule.done(part)
    assert seen == [(15.0, "a"), (30.0, "b"), (45.0, "c"), (60.0, "d"),
                    (75.0, "a"), (90.0, "b"), (105.0, "c"), (120.0, "d")]  # fmt: skip
    clock.t += 600.0  # the worker was busy for 10 minutes: everyone is due, longest first
    assert schedule.due() == ["a", "b", "c", "d"]
    schedule.done("a")
    assert schedule.due() == ["b", "c", "d"]
    clock.t += 30.0
    assert "a" in schedule.due()  # half an interval later, not at once and not a burst


def test_a_dropped_part_gets_no_more_turns() -> None:
    """A held mill is dropped: it is never due again (a due mill that is never checkpointed
    would stay due, and every step would commit and flush the archive for it)."""
    clock = FakeClock()
    schedule = CheckpointSchedule(["a", "b"], 60.0, clock)
    schedule.drop("a")
    schedule.drop("unknown")  # nothing to drop: no error
    schedule.restart()
    clock.t += 60.0
    assert schedule.due() == ["b"]
    clock.t += 600.0
    assert schedule.due() == ["b"]


def test_interval_must_be_positive() -> None:
    with pytest.raises(ValueError, match="interval"):
        CheckpointSchedule(["a"], 0.0)


def test_covers_and_earliest_follow_archive_order() -> None:
    f1, f2 = "w_20261121T000000Z.mcap", "w_20261121T010000Z.mcap"
    at = ArchivePosition(f2, 5)
    assert covers(at, f1, 900)
    assert covers(at, f2, 4)
    assert not covers(at, f2, 5)
    assert not covers(None, f1, 0)
    assert covers(at, f2, [3, 4, 5, 6]).tolist() == [True, True, False, False]  # a batch at once
    assert earliest([at, ArchivePosition(f1, 7), ArchivePosition(f2, 1)]) == ArchivePosition(f1, 7)
    assert earliest([at, None]) is None and earliest([]) is None


def _mill_of(worker: Worker, key: str) -> str:
    """The mill ``key`` belongs to ("" for none)."""
    route = worker.route(key)
    return route[0] if route else ""


def _blocks() -> list[QueuedBlock]:
    """Both mills' start scenes, interleaved in time order as a gateway would send them."""
    out = []
    for seed, config in enumerate(CONFIGS.values()):
        scene = starting_now(get_scene("start-lrs", config, seed=seed + 5, duration_s=20.0))
        out += [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]
    return sorted(out, key=lambda b: b.recv_ns)


def _worker(store: Store, archive: ArchiveWriter | None) -> Worker:
    pipelines = {m: MillJob(c) for m, c in CONFIGS.items()}
    return Worker(CONFIGS, pipelines, store, archive, checkpoint_seconds=3600.0)  # type: ignore[arg-type]


def _damage(worker: Worker) -> dict[str, str]:
    out = {}
    for mill_id, pipeline in worker.pipelines.items():
        analyzer = pipeline.analyzer  # type: ignore[attr-defined]
        analyzer.flush()
        out[mill_id] = json.dumps(analyzer.report()["damage"], sort_keys=True)
    return out


def test_recovery_from_mills_checkpointed_at_different_positions(tmp_path) -> None:
    blocks = _blocks()
    cut_a, cut_b, crash = len(blocks) // 4, len(blocks) // 2, 3 * len(blocks) // 4
    with Store(tmp_path / "ref.db") as store:
        reference = _worker(store, None)
        for item in blocks:
            reference.handle(item)
        reference.commit()
        expected = _damage(reference)

    with Store(tmp_path / "mw.db") as store:
        archive = ArchiveWriter(tmp_path / "archive", "w")
        first = _worker(store, archive)
        for i, item in enumerate(blocks[:crash]):
            if i == cut_a:
                first.checkpoint(["mill-a"])
            if i == cut_b:
                first.checkpoint(["mill-b"])
            first.handle(item)
        archive.close()  # the crash: every handled block reached the archive
        assert first.checkpoints_written == 2 and first.checkpoint_bytes > 0
        positions = {m: p for m, (p, _) in store.latest_checkpoints().items()}
        assert positions["mill-a"]["index"] < positions["mill-b"]["index"]

        second = _worker(store, ArchiveWriter(tmp_path / "archive", "w"))
        replayed = recover(second, ArchiveReader(tmp_path / "archive", "w"))
        # from mill-a's position on, except mill-b's blocks that its own checkpoint holds
        held_by_b = sum(1 for b in blocks[cut_a:cut_b] if _mill_of(second, b.key) == "mill-b")
        assert replayed == crash - cut_a - held_by_b > 0
        for item in blocks[crash:]:
            second.handle(item)
        second.commit()
        assert _damage(second) == expected
        second.archive.close()  # type: ignore[union-attr]


def test_steps_checkpoint_one_mill_at_a_time_spread_over_the_interval(tmp_path) -> None:
    clock = FakeClock()
    with Store(tmp_path / "mw.db") as store:
        worker = _worker(store, None)
        worker._schedule = CheckpointSchedule(CONFIGS, 60.0, clock)
        queue = BlockQueue(10)
        written = []
        for _ in range(12):  # two minutes in 10 s steps
            clock.t += 10.0
            worker.step(queue, timeout_s=0.0)
            written.append(worker.checkpoints_written)
        assert written == [0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4]
        assert set(store.latest_checkpoints()) == set(CONFIGS)


def test_the_live_analyzer_keeps_few_windows_yet_every_one_is_stored(monkeypatch) -> None:
    monkeypatch.setattr("millwatch.worker.mill_job.WINDOWS_KEPT", 2)
    config = CONFIGS["mill-a"]
    scene = get_scene("steady", config, seed=2, duration_s=330.0)
    pipeline = MillJob(config)
    stored = []
    for b in scene_blocks(scene):
        pipeline.add_block(pipeline_channel(config, b.key), decode_block(b.payload))
        stored += [r for r in pipeline.finish().records if r[0] == "steady"]
    restored = MillJob(config)
    restored.restore(json.loads(json.dumps(pipeline.snapshot())))
    assert len(stored) == 5  # 60 s windows
    for p in (pipeline, restored):
        a = p.analyzer
        assert len(a.steady_windows) == 2 and a.steady_windows[-1]["t_ns"] == stored[-1][1]
        assert a._loads.keep_events < 100  # (the setting of keep_recent, in its stage)


def pipeline_channel(config, key: str) -> str:
    return next(n for n, c in config.channels.items() if key.endswith("/" + c.key))


# ---------------------------------------------------------------- configuration changed since
MILL_A = CONFIGS["mill-a"]
#: The operator's edit: motor 995 → 1000 rpm, so the pinion turns at 177.0 rpm, not 176.1, and
#: the harmonic tracker's segments have other bins than the checkpoint's.
FASTER = MILL_A.model_copy(
    update={"drive": MILL_A.drive.model_copy(update={"motor_speed_rpm": 1000.0})}
)


def _one_mill(store: Store, archive: ArchiveWriter | None, config: MillConfig) -> Worker:
    """A worker of mill-a alone, storing its daily damage every 5 s of samples."""
    pipelines = {config.id: MillJob(config, damage_every_s=5.0)}
    return Worker({config.id: config}, pipelines, store, archive, checkpoint_seconds=3600.0)  # type: ignore[arg-type]


def _mill_a_blocks() -> list[QueuedBlock]:
    scene = starting_now(get_scene("start-lrs", MILL_A, seed=5, duration_s=40.0))
    return [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]


def _crash_after_a_checkpoint(tmp_path: Path, store: Store, blocks: list[QueuedBlock]) -> int:
    """Run mill-a with its configuration of then, checkpoint at half the blocks, store the
    results up to three quarters and stop there; returns how many blocks were handled."""
    archive = ArchiveWriter(tmp_path / "archive", "w")
    first = _one_mill(store, archive, MILL_A)
    crash = 3 * len(blocks) // 4
    for i, item in enumerate(blocks[:crash]):
        if i == len(blocks) // 2:
            first.checkpoint()
        first.handle(item)
    first.commit()
    archive.close()
    return crash


def test_recovery_after_a_pinion_speed_change_keeps_damage_and_restarts_spectra(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    blocks = _mill_a_blocks()
    with Store(tmp_path / "ref.db") as store:
        reference = _one_mill(store, None, MILL_A)
        for item in blocks:
            reference.handle(item)
        reference.commit()
        uninterrupted = store.damage("mill-a")

    with Store(tmp_path / "mw.db") as store:
        crash = _crash_after_a_checkpoint(tmp_path, store, blocks)
        at_crash = store.damage("mill-a")
        assert sum(r.damage for r in at_crash) > 0.0

        second = _one_mill(store, None, FASTER)
        with caplog.at_level(logging.WARNING, logger="millwatch.analytics.mill.analyzer"):
            assert recover(second, ArchiveReader(tmp_path / "archive", "w")) > 0
        assert "mill 'mill-a'" in caplog.text and "spectra restart" in caplog.text
        # the day's damage was not overwritten by a partial total from a fresh analyzer
        assert store.damage("mill-a") == at_crash
        for item in blocks[crash:]:  # and the mill goes on being analysed
            second.handle(item)
        second.commit()
        assert store.damage("mill-a") == uninterrupted
        restarts = store.events("mill-a", "data_quality")

    # visible beyond the log: one data-quality event per tracked channel, at the checkpoint
    assert sorted(e.subject for e in restarts) == [
        "motor_torque:spectra_restarted", "pinion_bending:spectra_restarted",
        "pinion_torque:spectra_restarted",
    ]  # fmt: skip
    assert len({e.t_ns for e in restarts}) == 1
    assert blocks[0].recv_ns < restarts[0].t_ns < blocks[crash].recv_ns
    assert "11083 bins in the snapshot" in restarts[0].data["reason"]
    analyzer = second.pipelines["mill-a"].analyzer  # type: ignore[attr-defined]
    assert analyzer.samples == reference.pipelines["mill-a"].analyzer.samples  # type: ignore[attr-defined]
    tracker = analyzer._harmonics  # (its geometry: a stage's own business, read by the test)
    assert tracker.bins == HarmonicTracker(FASTER).bins != HarmonicTracker(MILL_A).bins
    assert tracker.counters["running_samples"] > 0


WITHOUT_BENDING = MILL_A.model_copy(
    update={"channels": {n: c for n, c in MILL_A.channels.items() if n != "pinion_bending"}}
)
#: A channel added to the configuration: the snapshot's aligner frames only its own channels.
SPARE = ChannelConfig(key="tacho", kind="tacho", units="V", pulses_per_rev=1)
WITH_TACHO = MILL_A.model_copy(update={"channels": {**MILL_A.channels, "tacho": SPARE}})


@pytest.mark.parametrize(
    ("edited", "cause"),
    [
        (WITHOUT_BENDING, "mill 'mill-a': channel(s) removed 'pinion_bending'"),
        (WITH_TACHO, "mill 'mill-a': channel(s) added 'tacho'"),
    ],
)
def test_a_checkpoint_that_cannot_be_restored_holds_the_mill_naming_it_and_the_way_out(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, edited: MillConfig, cause: str
) -> None:
    blocks = _mill_a_blocks()
    with Store(tmp_path / "mw.db") as store:
        _crash_after_a_checkpoint(tmp_path, store, blocks)
        ((position, _),) = store.latest_checkpoints().values()
        second = _one_mill(store, None, edited)
        with caplog.at_level(logging.ERROR, logger="millwatch.worker.worker"):
            assert recover(second, ArchiveReader(tmp_path / "archive", "w")) == 0  # all held
    text = second.held["mill-a"]
    assert text.startswith(
        f"mill mill-a: its checkpoint (at archive file {position['file']}, message "
        f"{position['index']}, logged 20"
    )
    assert f"cannot be restored: {cause} in the configuration since the snapshot" in text
    assert "revert the change and start the worker again" in text
    [record] = caplog.records  # logged once, naming the consequence
    assert record.levelno == logging.ERROR and record.getMessage().startswith(text)
    assert "mill mill-a is held: its blocks are archived but not analysed" in record.getMessage()
    assert second.status(10.0)["mill-a"].state == "held"
    # its alarm engine was not restored: an acknowledgement is refused, saying why
    request = second.request_ack("mill-a", "mill-a:start_peak:-:1", "op")
    second.step(BlockQueue(10), timeout_s=0.0)
    with pytest.raises(MillHeldError, match=r"^mill mill-a is not analysed \(held\)"):
        request.done.result(timeout=1.0)


# ---------------------------------------------------------------- a held mill loses nothing
def _two_mills(
    store: Store, archive: ArchiveWriter | None, mill_a: MillConfig = MILL_A, **kw: Any
) -> Worker:
    """mill-a (as configured by ``mill_a``) and mill-b, daily damage stored every 5 s."""
    configs = {"mill-a": mill_a, "mill-b": CONFIGS["mill-b"]}
    pipelines = {m: MillJob(c, damage_every_s=5.0) for m, c in configs.items()}
    return Worker(configs, pipelines, store, archive, checkpoint_seconds=3600.0, **kw)  # type: ignore[arg-type]


def _results(store: Store) -> dict[str, Any]:
    """Each mill's stored damage and events, but the stale/fresh data-quality events: those are
    wall-clock facts of one run (the worker's clock), not derived from the samples."""
    return {
        m: (store.damage(m), [(e.kind, e.t_ns, e.subject, e.data) for e in store.events(m)
                              if e.data.get("problem") not in ("stale", "fresh")])
        for m in ("mill-a", "mill-b")
    }  # fmt: skip


def _checkpoint_rows(store: Store, mill_id: str) -> list[tuple[Any, ...]]:
    sql = "SELECT * FROM checkpoint_parts WHERE part = ? ORDER BY id"
    return [tuple(r) for r in store._query(sql, (mill_id,))]


def test_a_held_mill_is_archived_not_analysed_never_checkpointed_and_loses_nothing(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A restart after mill-a lost a channel from its configuration: the worker starts, mill-b
    is analysed as if nothing happened, mill-a's blocks are archived and its health observed but
    its pipeline gets nothing and its checkpoint stays; once the edit is reverted, the next start
    restores that checkpoint, replays what mill-a missed, and the results are the uninterrupted
    run's."""
    blocks = _blocks()
    n = len(blocks)
    cut_a, cut_b, crash, stop = n // 4, n // 2, 5 * n // 8, 3 * n // 4
    with Store(tmp_path / "ref.db") as store:
        reference = _two_mills(store, None)
        for item in blocks:
            reference.handle(item)
        reference.commit()
        uninterrupted = _results(store)

    archive = tmp_path / "archive"
    with Store(tmp_path / "mw.db") as store:
        first = _two_mills(store, ArchiveWriter(archive, "w"))
        for i, item in enumerate(blocks[:crash]):
            if i in (cut_a, cut_b):  # mill-a checkpointed before mill-b
                first.checkpoint(["mill-a" if i == cut_a else "mill-b"])
            first.handle(item)
        first.commit()
        first.archive.close()  # type: ignore[union-attr]
        kept = _checkpoint_rows(store, "mill-a")

        now = [blocks[-1].recv_ns + 3600 * 10**9]  # an hour later
        second = _two_mills(store, ArchiveWriter(archive, "w"), WITHOUT_BENDING,
                            clock=lambda: now[0])  # fmt: skip
        with caplog.at_level(logging.ERROR, logger="millwatch.worker.worker"):
            replayed = recover(second, ArchiveReader(archive, "w"))
        assert list(second.held) == ["mill-a"] and len(caplog.records) == 1
        # from mill-b's position: the held mill does not pull the replay back to its own
        assert replayed == crash - cut_b
        for item in blocks[crash:stop]:  # live
            second.handle(item)
        now[0] += 11 * 10**9  # silent for 11 s since the restart: every channel stale
        second.check_staleness(10.0)
        second.checkpoint()
        second.archive.close()  # type: ignore[union-attr]
        analyzer = second.pipelines["mill-a"].analyzer  # type: ignore[attr-defined]
        assert analyzer.samples == 0 and analyzer.backlog == 0  # its pipeline got nothing
        mill_a = [b for b in blocks[cut_b:stop] if _mill_of(second, b.key) == "mill-a"]
        assert second.held_blocks["mill-a"] == len(mill_a) > 0
        held = second.status(10.0)["mill-a"]
        assert held.state == "held" and held.held_reason == second.held["mill-a"]
        torque = held.channel_health["motor_torque"]
        assert torque.blocks == len(mill_a) // 3  # motor, pinion torque, speed (no bending)
        # no alarm observations reached the held mill's fresh engine; mill-b's did
        assert {a.mill_id for a in store.alarms() if a.rule == "stale_channel"} == {"mill-b"}
        assert second.checkpoints_written == 1  # mill-b's only
        assert _checkpoint_rows(store, "mill-a") == kept  # byte for byte
        archived = [b.payload for b in ArchiveReader(archive, "w").blocks()]
        assert archived == [b.payload for b in blocks[:stop]]  # the held mill's blocks too

        third = _two_mills(store, ArchiveWriter(archive, "w"))  # the edit reverted
        recover(third, ArchiveReader(archive, "w"))
        assert third.held == {}
        for item in blocks[stop:]:
            third.handle(item)
        third.commit()
        third.archive.close()  # type: ignore[union-attr]
        assert _results(store) == uninterrupted


# ---------------------------------------------------------------- a damaged checkpoint
def _damage_rows(store: Store, mill_id: str, how: list[str]) -> None:
    """Damage mill's kept checkpoints, newest first: "truncate" cuts the stored text,
    "flip" flips one bit of a digit (a number changed, the JSON still valid), "" leaves it."""
    sql = "SELECT id, state_json FROM checkpoint_parts WHERE part = ? ORDER BY id DESC"
    for (row_id, text), kind in zip(store._query(sql, (mill_id,)), how, strict=False):
        if kind == "truncate":
            text = text[: len(text) // 2]
        elif kind == "flip":
            at = text.index('": 1', len(text) // 2) + 3  # a number's digit 1 → 0
            text = text[:at] + chr(ord(text[at]) ^ 1) + text[at + 1 :]
        with store.transaction() as db:
            db.execute("UPDATE checkpoint_parts SET state_json = ? WHERE id = ?", (text, row_id))


@pytest.mark.parametrize(
    ("how", "starts_from"),
    [
        (["truncate"], "its previous checkpoint, written 20"),
        (["flip"], "its previous checkpoint, written 20"),
        (["flip", "truncate"], "the start of the archive (none of its kept checkpoints is intact)"),
    ],
)
def test_a_damaged_checkpoint_is_refused_and_the_mill_falls_back_losing_nothing(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, how: list[str], starts_from: str
) -> None:
    """mill-a's newest checkpoint (or both kept) damaged: the recovery refuses it naming the
    mill, the checkpoint and the store, mill-a starts from its previous checkpoint (or the
    archive's start), mill-b from its own, and the results are the uninterrupted run's."""
    blocks = _blocks()
    cuts = {len(blocks) // 4: "mill-a", len(blocks) // 3: "mill-b", len(blocks) // 2: "mill-a"}
    crash = 3 * len(blocks) // 4
    with Store(tmp_path / "ref.db") as store:
        reference = _worker(store, None)
        for item in blocks:
            reference.handle(item)
        reference.commit()
        expected = _damage(reference)

    with Store(tmp_path / "mw.db") as store:
        first = _worker(store, ArchiveWriter(tmp_path / "archive", "w"))
        for i, item in enumerate(blocks[:crash]):
            if i in cuts:
                first.checkpoint([cuts[i]])
            first.handle(item)
        first.archive.close()  # type: ignore[union-attr]
        _damage_rows(store, "mill-a", how)

        second = _worker(store, ArchiveWriter(tmp_path / "archive", "w"))
        with caplog.at_level(logging.ERROR, logger="millwatch.worker.worker"):
            replayed = recover(second, ArchiveReader(tmp_path / "archive", "w"))
        start = min(cuts) if len(how) == 1 else 0
        of_b = sum(
            1 for b in blocks[start : len(blocks) // 3] if _mill_of(second, b.key) == "mill-b"
        )
        assert replayed == crash - start - of_b
        for item in blocks[crash:]:
            second.handle(item)
        second.commit()
        assert _damage(second) == expected
        assert second.held == {} and second.checkpoints_refused == {"mill-a": len(how)}
        events = [e.data for e in store.events("mill-a", "data_quality")]
        second.archive.close()  # type: ignore[union-attr]
    messages = [r.getMessage() for r in caplog.records]
    assert len(messages) == len(how)
    reasons = {"flip": "its SHA-256 checksum does not match", "truncate": "it is truncated: "}
    for text, kind in zip(messages, how, strict=True):  # newest first
        assert text.startswith("mill mill-a: its checkpoint #")
        assert f"is refused: {reasons[kind]}" in text
        assert f"in store {tmp_path / 'mw.db'} is refused: " in text
        assert f"The mill starts from {starts_from}" in text
    assert [e["problem"] for e in events] == ["checkpoint_refused"] * len(how)
    assert all(e["store"] == str(tmp_path / "mw.db") for e in events)
