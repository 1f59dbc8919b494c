"""Store = analyze: one scene through the real worker into a real SQLite store, and the same
blocks through a :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer` offline. After a clean
stop (the worker's final checkpoint) the store holds the analyzer's own seconds per phase (stopped
and the running before the first start included), damage and counted cycles per component and
phase; live, each checkpoint books the analysis so far. And remaining life is one computation:
the ``remaining_life`` alarm's value, ``/life``, the monthly report's rates and the
``millwatch_remaining_life_years`` gauge agree on the same data."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from millwatch.alarms.observations import Observation
from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.analytics.signal.fault_stage import FaultStage
from millwatch.analytics.spectra.settings import stagger_for
from millwatch.api.domain_metrics import domain_families
from millwatch.ingest import keys
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import StartEvent, StopEvent
from millwatch.ingest.wire import decode_block
from millwatch.reports.history import life_inputs
from millwatch.reports.life import compute_life
from millwatch.reports.monthly import build_monthly_report
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
#: Running when the record begins (no start event for it), a stop, rest, a start, running.
EVENTS = (StopEvent(at_s=80.0), StartEvent(at_s=140.0))
T0_NS = 1_709_596_800 * 10**9  # 2024-03-05T00:00Z
DURATION_S = 240.0


def _blocks() -> list[SceneBlock]:
    scene = get_scene("steady", CONFIG, seed=4, duration_s=DURATION_S, events=EVENTS,
                      t0_ns=T0_NS, initial_state="running")  # fmt: skip
    return list(scene_blocks(scene))


BLOCKS = _blocks()


def _offline(blocks: list[SceneBlock], *, flush: bool = False) -> MillAnalyzer:
    """The same blocks through an analyzer of its own, analysed as far as the worker's (with
    ``flush``: to the end of the record, as ``millwatch analyze`` does)."""
    routes = {keys.channel_key(CONFIG.site, CONFIG.id, ch.key): name
              for name, ch in CONFIG.channels.items()}  # fmt: skip
    analyzer = MillAnalyzer(CONFIG)
    for b in blocks:
        block = decode_block(b.payload)
        analyzer.add(routes[b.key], block.t0_ns, block.fs, block.samples)
    analyzer.process()
    if flush:
        analyzer.flush()
    return analyzer


def _feed(worker: Worker, blocks: list[SceneBlock]) -> None:
    for b in blocks:
        worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns))
    worker.commit()


def _stored_damage(store: Store) -> tuple[dict, dict]:
    damage: dict[tuple[str, str], list[float]] = defaultdict(list)
    cycles: dict[tuple[str, str], list[float]] = defaultdict(list)
    for r in store.damage(CONFIG.id):
        damage[(r.component, r.phase)].append(r.damage)
        cycles[(r.component, r.phase)].append(r.cycles)
    return ({k: math.fsum(v) for k, v in damage.items()},
            {k: math.fsum(v) for k, v in cycles.items()})  # fmt: skip


def _analyzed_damage(analyzer: MillAnalyzer) -> tuple[dict, dict]:
    damage: dict[tuple[str, str], list[float]] = defaultdict(list)
    cycles: dict[tuple[str, str], list[float]] = defaultdict(list)
    for comp, days in analyzer.damage_by_day().items():
        for phases in days.values():
            for phase, d in phases.items():
                damage[(comp, phase)].append(d)
    for comp, days in analyzer.cycles_by_day().items():
        for phases in days.values():
            for phase, c in phases.items():
                cycles[(comp, phase)].append(c)
    return ({k: math.fsum(v) for k, v in damage.items()},
            {k: math.fsum(v) for k, v in cycles.items()})  # fmt: skip


@pytest.fixture(scope="module")
def stopped(tmp_path_factory: pytest.TempPathFactory) -> SimpleNamespace:
    """The scene through the worker, then a clean stop (its final checkpoint)."""
    path = tmp_path_factory.mktemp("store_eq") / "mw.db"
    store = Store(path)
    job = MillJob(CONFIG)
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: job}, store, None,
                    checkpoint_seconds=3600.0)  # fmt: skip
    _feed(worker, BLOCKS)
    before_stop = _stored_damage(store)[0], store.phase_seconds(CONFIG.id)
    worker.checkpoint(final=True)  # what a clean stop (SIGTERM) does last
    yield SimpleNamespace(store=store, job=job, before_stop=before_stop)
    store.close()


def test_a_clean_stop_books_every_sample_as_analyze_does(stopped):
    """The final booking is of the record analysed to its end (the fault stage's look-ahead
    included), as ``millwatch analyze`` of the same blocks books it."""
    offline = _offline(BLOCKS, flush=True)
    assert offline.samples == DURATION_S * CONFIG.sample_rate_hz
    seconds = offline.report()["phase_seconds"]
    stored = stopped.store.phase_seconds(CONFIG.id)
    assert list(stored) == list(seconds)  # every phase, zeros included, in analyze's order
    assert {p for p, s in stored.items() if s > 0} == {"run", "stop", "stopped", "start"}
    for phase, s in seconds.items():
        assert stored[phase] == pytest.approx(s, rel=1e-12, abs=1e-12), phase
    assert math.fsum(stored.values()) == pytest.approx(DURATION_S, rel=1e-12)
    damage, cycles = _stored_damage(stopped.store)
    want_damage, want_cycles = _analyzed_damage(offline)
    assert damage == want_damage and cycles == want_cycles
    assert all(c > 0 for c in cycles.values()) and len(cycles) >= 3 * 4  # components × phases
    assert stopped.store.mill_span(CONFIG.id)[1] == offline.next_sample_ns


def test_the_final_booking_leaves_the_live_analysis_and_its_checkpoint_unflushed(stopped):
    """A restart continues from the checkpoint exactly: the worker's own analyzer (and so the
    snapshot the final checkpoint stored) still holds the look-ahead samples back."""
    unflushed = _offline(BLOCKS)
    assert stopped.job.analyzer.samples == unflushed.samples < DURATION_S * 1000
    ((_, state),) = stopped.store.latest_checkpoints().values()
    snap = state["pipelines"][CONFIG.id]["monitor"]
    assert MillAnalyzer.restore(CONFIG, snap).samples == unflushed.samples


def test_before_the_stop_the_last_interval_was_not_yet_booked(stopped):
    damage, _ = _stored_damage(stopped.store)
    stored = stopped.store.phase_seconds(CONFIG.id)
    # before the stop, the rows of the last damage interval (up to a minute) were not booked
    before, before_seconds = stopped.before_stop
    assert math.fsum(before_seconds.values()) < math.fsum(stored.values())
    assert math.fsum(before.values()) < math.fsum(damage.values())


def test_the_stored_running_includes_the_running_before_the_first_start(stopped):
    """The record begins running: those seconds are run seconds, though no start precedes."""
    starts = stopped.store.events(CONFIG.id, "start")
    assert len(starts) == 1 and starts[0].t_ns > T0_NS + 100 * 10**9
    run_after_start = (T0_NS + DURATION_S * 1e9 - starts[0].t_ns) / 1e9
    assert stopped.store.phase_seconds(CONFIG.id)["run"] > run_after_start + 30.0


def test_each_checkpoint_books_the_analysis_so_far(tmp_path):
    """Live, the worker books each mill with its checkpoint (every ``checkpoint_seconds``), so
    the store never lags the analyzer by more than that interval; between damage intervals
    it lagged by up to a minute of samples before."""
    with Store(tmp_path / "mw.db") as store:
        job = MillJob(CONFIG)
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: job}, store, None,
                        checkpoint_seconds=3600.0)  # fmt: skip
        step = len(CONFIG.channels) * 250  # 25 s of blocks a checkpoint
        lags = []
        for i in range(0, len(BLOCKS), step):
            _feed(worker, BLOCKS[i : i + step])
            lags.append(job.analyzer.next_sample_ns - (store.mill_span(CONFIG.id)[1] or T0_NS))
            worker.checkpoint([CONFIG.id])
            a = job.analyzer
            assert store.mill_span(CONFIG.id)[1] == a.next_sample_ns
            assert math.fsum(store.phase_seconds(CONFIG.id).values()) == pytest.approx(
                a.seconds_analysed, rel=1e-12)  # fmt: skip
            stored, _ = _stored_damage(store)
            assert stored == _analyzed_damage(a)[0]
        assert max(lags) > 10 * 10**9  # without the checkpoint's booking the store lagged


# ----------------------------------------------------------------------------- one life
def _interval_ending_at(samples: int) -> int:
    """A damage interval (samples) whose boundary falls on analysed sample ``samples``: the
    first comes after ``E + round(stagger·E)`` samples, the next ones every ``E``."""
    s = stagger_for(CONFIG.id)
    for k in range(1, 4):
        for e in range(samples // (k + 1) - 10, samples // k + 1):
            if e > 0 and e * k + round(s * e) == samples:
                return e
    raise AssertionError(f"no damage interval ends at sample {samples}")


def test_the_alarm_life_and_the_gauge_are_one_computation(tmp_path):
    """The ``remaining_life`` alarm observes what ``/life`` answers and the gauge exports, on
    the same data; the monthly report's life (as of the month's end, from the store alone)
    projects at the same rates. A ``first_N_days`` prior is applied in all of them."""
    config = CONFIG.model_copy(update={"life": CONFIG.life.model_copy(
        update={"min_monitoring_days": 0.001, "min_starts": 1})})  # fmt: skip
    assert config.life.prior_rate_days is not None  # the mill file's first_90_days prior
    fs = config.sample_rate_hz
    analysed = len(BLOCKS) // len(config.channels) * 100 - FaultStage(config).delay
    every = _interval_ending_at(analysed)
    job = MillJob(config, damage_every_s=every / fs, life_every_s=every / fs)
    observed: list[Observation] = []
    observe_all = job.alarms.observe_all

    def spy(observations: list[Observation]):  # type: ignore[no-untyped-def]
        observed.extend(o for o in observations if o.quantity == "remaining_life_years")
        return observe_all(observations)

    job.alarms.observe_all = spy  # type: ignore[method-assign]
    with Store(tmp_path / "mw.db") as store:
        worker = Worker({config.id: config}, {config.id: job}, store, None)
        _feed(worker, BLOCKS)
        worker.checkpoint()
        assert job.analyzer.samples == analysed
        status = worker.status(stale_after_s=1e9)[config.id]
        life = compute_life(life_inputs(store, config, T0_NS + 10**15, live=status.live_damage(),
                                        last_sample_ns=status.last_sample_ns))  # fmt: skip
        report = build_monthly_report(store, config, "2024-03").life
    assert life.status == "ok" and life.prior.method == "first_90_days"
    alarm = {o.context["component"]: o.value for o in observed if o.t_ns == observed[-1].t_ns}
    assert observed[-1].t_ns == status.last_sample_ns
    now = {c: x.remaining_life_years_min for c, x in life.components.items()}
    assert alarm == now and all(v is not None and v > 0 for v in alarm.values())
    gauge = next(m for m in domain_families([config.id], {config.id: status},
                                            lambda _: life)
                 if m.name == "millwatch_remaining_life_years")  # fmt: skip
    assert {s.labels["component"]: s.value for s in gauge.samples} == now
    for comp, c in life.components.items():
        rates = [p.rate_per_year for p in c.projections]
        assert [p.rate_per_year for p in report.components[comp].projections] == rates
        assert np.isfinite(rates[1]) and rates[1] > 0
