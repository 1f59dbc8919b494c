"""Forged blocks among a scene's real ones (issue 26): a worker analyses exactly what it analyses
of the clean scene, block by block and through the batch lane alike, counts each forged block by
reason, stores it as a data-quality event and raises the ``implausible_blocks`` alarm; every
number it keeps fits SQLite's int64."""

from __future__ import annotations

import json
import struct
import tempfile
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import HEADER, decode_block, encode_block
from millwatch.store.database import Store
from millwatch.worker.batch_lane import BatchLane, queued_batch
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.health import MAX_SEQ
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
GOOD = [
    QueuedBlock(b.key, b.payload, b.t_end_ns)
    for b in scene_blocks(get_scene("start-lrs", CONFIG, seed=5, duration_s=12.0))
]
YEAR_2100_NS = 4_102_444_800 * 10**9
_INT64 = 2**63 - 1


def _with(payload: bytes, *, seq: int | None = None, t0: int | None = None,
          fs: float | None = None) -> bytes:  # fmt: skip
    head = list(HEADER.unpack_from(payload))
    head[5] = head[5] if seq is None else seq
    head[3] = head[3] if t0 is None else t0
    head[4] = head[4] if fs is None else fs
    return HEADER.pack(*head) + payload[HEADER.size :]


#: Forged kind → (why it is implausible, the forged payload made from the last real block).
FORGERIES: dict[str, tuple[str, Callable[[bytes], bytes]]] = {
    "seq_2_63": ("seq_out_of_range", lambda p: _with(p, seq=2**63)),
    "seq_max": ("seq_out_of_range", lambda p: _with(p, seq=2**64 - 1)),
    "jump_100000": ("seq_ahead", lambda p: _with(p, seq=decode_block(p).seq + 100_000)),
    "jump_with_its_time": ("t0_ahead", lambda p: _with(
        p, seq=decode_block(p).seq + 100_000, t0=decode_block(p).t0_ns + 100_000 * 10**8)),
    "next_in_2100": ("t0_ahead", lambda p: _with(p, seq=decode_block(p).seq + 1,
                                                  t0=YEAR_2100_NS)),
    "next_at_1_mhz": ("sample_rate", lambda p: _with(p, seq=decode_block(p).seq + 1, fs=1e6)),
    "next_empty": ("empty", lambda p: encode_block(
        np.zeros(0, np.float32), decode_block(p).t0_ns, 1000.0, decode_block(p).seq + 1,
        decode_block(p).unit)),
}  # fmt: skip


def _forged(kinds: list[str], every: int = 3) -> tuple[list[QueuedBlock], Counter[str]]:
    """The scene with a forged block (kinds in turn) after every ``every``-th real one, on the
    same key, received with it; and the forged blocks by reason."""
    out: list[QueuedBlock] = []
    reasons: Counter[str] = Counter()
    for i, item in enumerate(GOOD):
        out.append(item)
        if i % every == every - 1:
            reason, forge = FORGERIES[kinds[(i // every) % len(kinds)]]
            out.append(QueuedBlock(item.key, forge(item.payload), item.recv_ns))
            reasons[reason] += 1
    return out, reasons


def _run(items: list[QueuedBlock], directory: Path, *, lane: bool) -> tuple[Worker, dict[str, Any]]:
    store = Store(directory / "mw.db")
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, None,
                    checkpoint_seconds=3600.0, clock=lambda: GOOD[-1].recv_ns)  # fmt: skip
    if lane:
        BatchLane(worker).handle(queued_batch(items))
    else:
        for item in items:
            worker.handle(item)
    worker.checkpoint(final=True)
    analyzer = worker.pipelines[CONFIG.id].analyzer  # type: ignore[attr-defined]
    return worker, json.loads(json.dumps(analyzer.report(), sort_keys=True, default=str))


@pytest.mark.parametrize("lane", [False, True], ids=["block_by_block", "batch_lane"])
def test_forged_blocks_change_nothing_analysed_and_are_counted_stored_and_alarmed(lane):
    forged, reasons = _forged(list(FORGERIES))
    with tempfile.TemporaryDirectory() as d:
        _, clean = _run(GOOD, Path(d) / "clean", lane=lane)
        worker, got = _run(forged, Path(d) / "forged", lane=lane)
        assert got == clean
        channels = worker.health[CONFIG.id].channels
        counted: Counter[str] = Counter()
        for h in channels.values():
            counted.update(h.implausible)
            assert (h.missing_blocks, h.gaps, h.repeats, h.clock_faults) == (0, 0, 0, 0)
            assert h.last_seq == len(GOOD) // len(channels) - 1
        assert counted == reasons
        events = worker.store.events(CONFIG.id, "data_quality")
        kinds = {(e.data["channel"], e.data["reason"]) for e in events}
        assert all(e.data["problem"] == "implausible_block" for e in events)
        assert kinds == {(c, r) for c in channels for r in reasons}  # first of each; < 60 s
        alarms = worker.store.alarms(mill_id=CONFIG.id)
        assert {(a.rule, a.subject) for a in alarms} == {("implausible_blocks", c)
                                                         for c in channels}  # fmt: skip
        _fits_int64(worker.store)


def _fits_int64(store: Store) -> None:
    """Every integer the store holds of the mill (rows and checkpoint JSON) fits int64."""
    _, state = store.latest_checkpoints()[CONFIG.id]
    stack: list[Any] = [state]
    for _ in range(10_000_000):  # bounded walk of the checkpoint's JSON tree
        if not stack:
            break
        v = stack.pop()
        if isinstance(v, dict):
            stack += v.values()
        elif isinstance(v, list):
            stack += v
        elif isinstance(v, int):
            assert -(2**63) <= v <= _INT64, v


def test_a_forged_first_block_of_a_channel_is_judged_by_the_clock_and_the_range():
    """No history: a year-2100 t0 or a sequence number beyond 2^53 is still implausible."""
    first = GOOD[0]
    with tempfile.TemporaryDirectory() as d:
        worker, got = _run([
            QueuedBlock(first.key, _with(first.payload, t0=YEAR_2100_NS), first.recv_ns),
            QueuedBlock(first.key, _with(first.payload, seq=MAX_SEQ + 1), first.recv_ns),
            *GOOD,
        ], Path(d), lane=False)  # fmt: skip
        _, clean = _run(GOOD, Path(d) / "clean", lane=False)
    assert got == clean
    h = worker.admission.health[CONFIG.id].channels[worker.route(first.key)[1]]  # type: ignore[index]
    assert h.implausible == {"t0_ahead": 1, "seq_out_of_range": 1}


def test_implausible_events_are_bounded_to_one_a_minute_per_channel_and_reason():
    item = GOOD[0]
    flood = [item] + [
        QueuedBlock(item.key, _with(item.payload, seq=2**63), item.recv_ns + k * 10**9)
        for k in range(180)  # three minutes of one forged block a second
    ]  # fmt: skip
    with tempfile.TemporaryDirectory() as d:
        worker, _ = _run(flood, Path(d), lane=False)
        events = worker.store.events(CONFIG.id, "data_quality")
    assert [e.data["blocks"] for e in events] == [1, 60, 60]
    assert all(e.data["seq"] == str(2**63) for e in events)


def test_a_block_holding_nan_and_inf_is_a_telemetry_fault_not_data():
    """Non-finite samples are counted and flagged as dropouts by the analysis (what it did
    before issue 26, kept): the damage equals the clean run's with those samples missing."""
    k = 40
    b = decode_block(GOOD[k].payload)
    bad = np.where(np.arange(b.samples.shape[0]) % 2 == 0, np.nan, np.inf).astype(b.samples.dtype)
    nan = QueuedBlock(GOOD[k].key, encode_block(bad, b.t0_ns, b.fs, b.seq, b.unit, b.dtype),
                      GOOD[k].recv_ns)  # fmt: skip
    with tempfile.TemporaryDirectory() as d:
        worker, got = _run([*GOOD[:k], nan, *GOOD[k + 1 :]], Path(d), lane=False)
    h = worker.health[CONFIG.id].channels[worker.route(nan.key)[1]]  # type: ignore[index]
    assert h.nonfinite_samples == b.samples.shape[0] and h.implausible == {}
    assert all(np.isfinite(v) for v in _numbers(got["damage"]))


def _numbers(value: Any) -> list[float]:
    if isinstance(value, dict):
        return [x for v in value.values() for x in _numbers(v)]
    if isinstance(value, list):
        return [x for v in value for x in _numbers(v)]
    return [float(value)] if isinstance(value, int | float) and not isinstance(value, bool) else []


def test_the_forgeries_are_what_they_say():
    p = GOOD[-1].payload
    assert struct.unpack_from("<Q", FORGERIES["seq_2_63"][1](p), 24)[0] == 2**63
    assert decode_block(FORGERIES["next_in_2100"][1](p)).t0_ns == YEAR_2100_NS
    assert decode_block(FORGERIES["next_empty"][1](p)).samples.shape == (0,)


def test_the_archiving_threads_positions_skip_a_forged_block():
    """What the spool recovery asks is judged by the archiving thread's positions
    (:class:`~millwatch.worker.archive_first.ArchivedSeqs`): a forged block is archived, but it
    never becomes a channel's last archived block, so the real blocks after it still reveal and
    fill their gaps."""
    from millwatch.worker.archive_first import ArchivedSeqs
    from millwatch.worker.health import MillHealth

    seqs = ArchivedSeqs.of({CONFIG.id: MillHealth.for_channels(list(CONFIG.channels))})
    from millwatch.ingest.keys import ChannelRoutes

    first = GOOD[0]
    route = ChannelRoutes([CONFIG]).route(first.key)
    seqs.note(route, first.payload, first.recv_ns)
    for kind in ("seq_2_63", "jump_100000", "next_in_2100"):
        seqs.note(route, FORGERIES[kind][1](first.payload), first.recv_ns)
    assert route is not None
    got = seqs[route[0]].channels[route[1]]
    assert (got.last_seq, got.last_t0_ns) == (0, decode_block(first.payload).t0_ns)
    nxt = next(g for g in GOOD[1:] if g.key == first.key)
    seqs.note(route, nxt.payload, nxt.recv_ns)
    assert got.last_seq == 1
