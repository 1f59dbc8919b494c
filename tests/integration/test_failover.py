"""No single worker is a point of failure (issue 30), end to end with real processes on
127.0.0.1: a router, a gateway whose cache (10 min) outlasts every outage, a primary, its hot
standby and ``millwatch api`` (:mod:`tests.integration.standby`).

The primary is SIGKILLed and restarted after :data:`OUTAGE_S`; once it answers again, the standby
is SIGKILLed and restarted the same way. Throughout, ``GET /mills/{id}`` answers 200 from a
live worker with analysed data no staler than :data:`MAX_STALE_S`, and ``GET /alarms`` never
lists one alarm twice. An acknowledgement made while the primary is down reaches the primary's
store once it is back (reconciled from the standby). At the end both archives hold every
published block, both stores hold the same alarms (stale-channel ones raised when the data ended
included), the same acknowledgement at the same time, and the same damage.

The issue asks for outages of ~35 s; the suite uses :data:`OUTAGE_S` = 6 s to stay within its
time budget on a loaded 2-core machine (the recovery path is the same: the gateway cache
replays the outage either way). ``MILLWATCH_FAILOVER_OUTAGE_S=35`` runs the issue's length;
``tests/bench/bench_failover.py`` measures failover times with 35 s outages."""

from __future__ import annotations

import logging
import os
import re
import sqlite3
import time
from collections import Counter, defaultdict
from pathlib import Path

import httpx
import pytest

from millwatch.ingest.mill_files import load_mill_config
from tests.integration.live import MILL, MILL_FILE, Api, published, stored_results, wait
from tests.integration.standby import (
    API_KEY,
    PRIMARY,
    STALE_AFTER_S,
    STANDBY,
    StandbyPlant,
    Watch,
)

pytestmark = pytest.mark.slow
log = logging.getLogger(__name__)

CONFIG = load_mill_config(MILL_FILE)
OUTAGE_S = float(os.environ.get("MILLWATCH_FAILOVER_OUTAGE_S", "6"))
MAX_STALE_S = 3.0
#: How long a restarted worker may take to start, recover and take its mill back (a Python
#: start took up to 12 s on a busy 2-core machine; then the catch-up from the gateway cache).
TAKEOVER_S = 90.0


def _archived(directory: Path) -> dict[str, set[int]]:
    seqs: dict[str, set[int]] = defaultdict(set)
    for key, seq in published(directory):
        seqs[key.rsplit("/", 1)[1]].add(seq)
    return dict(seqs)


def _alarms(directory: Path) -> dict[str, tuple[str, str, int | None, str | None, int]]:
    """Stored alarms: id → (rule, state, acked_ns, acked_by, acknowledgements stored)."""
    with sqlite3.connect(f"file:{directory / 'mw.db'}?mode=ro", uri=True) as db:
        rows = db.execute(
            "SELECT a.alarm_id, a.rule, a.state, a.acked_ns, a.acked_by, "
            "(SELECT COUNT(*) FROM alarm_transitions t WHERE t.alarm_id = a.alarm_id "
            "AND t.kind = 'acknowledged') FROM alarms a"
        )
        return {r[0]: tuple(r[1:]) for r in rows.fetchall()}


def _outage(plant: StandbyPlant, name: str) -> float:
    """SIGKILL ``name``, wait :data:`OUTAGE_S`, restart it; the monotonic time of the kill."""
    t_kill = time.monotonic()
    plant.kill(name)
    time.sleep(OUTAGE_S)
    plant.start_worker(name)
    return t_kill


def _check_answers(watch: Watch, since: float, what: str) -> None:
    """Every answer since ``since`` was a 200 from a live worker, no staler than allowed."""
    samples = watch.since(since)
    assert len(samples) > OUTAGE_S * 3, f"{what}: only {len(samples)} answers"
    bad = [s for s in samples if s.code != 200 or s.state == "unreachable"
           or s.stale_s is None or s.stale_s > MAX_STALE_S]  # fmt: skip
    assert not bad, f"{what}: {len(bad)} of {len(samples)} answers bad, e.g. {bad[:5]}"
    workers = Counter(s.worker for s in samples)
    worst = max(s.stale_s or 0.0 for s in samples)
    log.info("%s: %d answers, by %s, stalest %.2f s", what, len(samples), dict(workers), worst)


def test_failover_to_the_hot_standby_and_back_loses_nothing(tmp_path):
    plant = StandbyPlant(tmp_path)
    watch = Watch(plant.url)
    try:
        plant.start()
        assert wait(plant.both_hold, 120.0, every_s=0.5), plant.procs.logs()
        assert wait(lambda: plant.answering() == PRIMARY, 30.0), plant.mill_workers()
        client = httpx.Client(base_url=plant.url, timeout=10.0)
        plant.restart_gateway(down_s=2.0)  # blocks lost: both workers raise sequence_gaps
        alarms = wait(lambda: client.get("/alarms").json()["alarms"], 60.0, every_s=0.5)
        assert alarms, plant.procs.logs()
        alarm_id = alarms[0]["alarm_id"]
        watch.start()

        # both workers hot before the first kill: after the gateway's restart each catches up
        # on its own (the lost span is asked of the gateway's spool first); a standby still
        # behind would answer as stale as it is (seen: 3.9-4.1 s in a run that killed the
        # primary at once)
        def hot(name: str) -> bool:
            last = plant.worker_status(name).get("last_sample_ns")
            return last is not None and time.time_ns() - last < MAX_STALE_S / 2 * 1e9

        assert wait(lambda: hot(PRIMARY) and hot(STANDBY), 90.0, every_s=0.5)
        t0 = time.monotonic()
        before = [s.stale_s for s in watch.samples if s.stale_s is not None]
        log.info("before any failover: stalest %.2f s over %d answers", max(before, default=0.0),
                 len(before))  # fmt: skip

        # the primary dies: the standby answers; an ack meanwhile reaches it alone
        t_kill = time.monotonic()
        plant.kill(PRIMARY)
        assert wait(lambda: plant.answering() == STANDBY, 10.0, every_s=0.05)
        r = client.post(f"/alarms/{alarm_id}/ack", json={"by": "night shift"},
                        headers={"X-API-Key": API_KEY})  # fmt: skip
        assert r.status_code == 200, r.text
        ready = httpx.get(plant.url + "/ready", timeout=10.0).json()
        assert ready["ready"] and ready["warnings"], ready  # answered, but no standby left
        lost = Api(plant.api_port).metrics()
        assert lost[f'millwatch_mill_redundancy_lost{{mill="{MILL}"}}'] == 1.0, lost
        time.sleep(max(0.0, OUTAGE_S - (time.monotonic() - t_kill)))
        plant.start_worker(PRIMARY)
        assert wait(lambda: plant.answering() == PRIMARY, TAKEOVER_S, every_s=0.5), (
            plant.procs.logs()
        )
        _check_answers(watch, t0, "primary down and back")

        # the standby dies and comes back: the primary answers throughout
        t1 = _outage(plant, STANDBY)
        assert wait(plant.both_hold, TAKEOVER_S, every_s=0.5), plant.procs.logs()
        _check_answers(watch, t1, "standby down and back")
        metrics = Api(plant.api_port).metrics()
        held = {k for k, v in metrics.items() if k.startswith("millwatch_mill_worker{") and v}
        assert len(held) == 2 and any('role="standby"' in k for k in held), held
        assert any('worker="primary"' in k and 'answering="1"' in k for k in held), held
        watch.stop()
        assert watch.alarm_lists, "no /alarms answer"
        twice = [ids for ids in watch.alarm_lists if len(ids) != len(set(ids))]
        assert not twice, twice[:3]

        # the data end: both raise the stale-channel alarms, then both analysed it all
        plant.stop_gateway()
        time.sleep(STALE_AFTER_S + 3.0)
        ends = lambda: {n: plant.worker_status(n).get("last_sample_ns") for n in plant.dirs}  # noqa: E731
        assert wait(lambda: len(set(ends().values())) == 1, 60.0, every_s=1.0), ends()

        def stale_stored(name: str) -> int:
            return sum(r[0] == "stale_channel" for r in _alarms(plant.dirs[name]).values())

        # both stores hold every channel's stale alarm (raised on each worker's own check and
        # committed in its next batch: a bounded wait, not a fixed sleep, on a loaded machine)
        assert wait(lambda: min(map(stale_stored, (PRIMARY, STANDBY))) >= len(CONFIG.channels),
                    30.0, every_s=0.5), ({n: stale_stored(n) for n in (PRIMARY, STANDBY)},
                                         plant.procs.logs())  # fmt: skip
        for name in (PRIMARY, STANDBY):
            assert plant.procs.stop(name) == 0, plant.procs.logs()
    finally:
        watch.stop()
        plant.stop_all()

    # every block the restarted gateway published (both outages came after its restart) is in
    # both archives; before it, the same blocks (the span it was down is lost to both)
    restarted = re.search(r"next sequence (\d+)", "\n".join(plant.procs.log_lines("gateway.1")))
    assert restarted is not None, plant.procs.logs()
    archives = {n: _archived(d) for n, d in plant.dirs.items()}
    assert set(archives[PRIMARY]) == set(CONFIG.channels)
    for channel, seqs in archives[PRIMARY].items():
        assert set(range(int(restarted[1]), max(seqs) + 1)) <= seqs, f"{channel}: a gap"
    assert archives[PRIMARY] == archives[STANDBY]
    assert stored_results(plant.dirs[PRIMARY], CONFIG) == stored_results(
        plant.dirs[STANDBY], CONFIG
    )
    stored = {n: _alarms(d) for n, d in plant.dirs.items()}
    assert stored[PRIMARY] == stored[STANDBY]  # the same ids, the same ack (time and who)
    assert stored[PRIMARY][alarm_id][3:] == ("night shift", 1)  # reconciled once
    # the data ended: one open stale-channel alarm per channel, the same in both stores
    stale = [a for a, (rule, state, *_) in stored[PRIMARY].items()
             if rule == "stale_channel" and state != "cleared"]  # fmt: skip
    assert sorted(a.split(":")[2] for a in stale) == sorted(CONFIG.channels), stored[PRIMARY]
