"""Suppression by design in the live pipeline: the shipped SAG mill's pipeline on the
simulator's ``start-grid`` scene (a start at 5 s, a stop at 150 s) with a low oscillation-range
warning, so that a running-mill alarm is open when the mill stops — the stop event suppresses it
(recorded, not annunciated), the start-peak alarm stays annunciated, and the mill's stopped state
is checkpointed with the engine."""

from __future__ import annotations

from functools import cache

from millwatch.alarms.lifecycle import Transition
from millwatch.worker.mill_job import MillJob
from tests.alarms.helpers import with_alarms
from tests.service.worker.test_resonance_alarm import SAG, run

LOW = with_alarms(SAG, oscillation_range_warn_pct=1.0, oscillation_range_alarm_pct=90.0,
                  raise_delay_s=0.0)  # fmt: skip


@cache
def grid_start() -> tuple[MillJob, list[Transition]]:
    return run(LOW, "start-grid", 220.0)


def test_a_running_mill_alarm_is_suppressed_at_the_stop():
    _, transitions = grid_start()
    osc = [t for t in transitions if t.alarm.rule == "oscillation_range"]
    raised = [t for t in osc if t.kind == "raised"]
    suppressed = [t for t in osc if t.kind == "suppressed"]
    assert raised and not any(t.alarm.suppressed for t in raised)
    # one per open alarm (motor and pinion torque), at the one stop, after the raises
    assert sorted(t.alarm_id for t in suppressed) == sorted(t.alarm_id for t in raised)
    assert len({t.t_ns for t in suppressed}) == 1
    assert suppressed[0].t_ns > max(t.t_ns for t in raised)
    assert all(t.alarm.suppressed and not t.alarm.annunciated for t in suppressed)
    assert "the mill stopped" in suppressed[0].message
    start = [t for t in transitions if t.alarm.rule == "start_peak"]
    assert start and not any(t.alarm.suppressed for t in start)


def test_the_stopped_state_is_checkpointed():
    job, _ = grid_start()
    snapshot = job.alarms.snapshot()
    assert snapshot["stopped"] == [SAG.id]
    twin = MillJob(LOW)
    twin.alarms.restore(snapshot)
    assert twin.alarms.snapshot()["stopped"] == [SAG.id]
