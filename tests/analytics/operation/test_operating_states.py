"""Operating-state machine against simulator truth; split-anywhere and snapshot/restore."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from millwatch.analytics.operation.operating_states import OperatingState as S
from millwatch.analytics.operation.operating_states import OperatingStateMachine
from tests.analytics.scene_helpers import custom, scene, state_inputs

FS = 1000.0


def transitions(sc, cuts=None):
    s, q = state_inputs(sc, sc.render(0, sc.n_samples))
    m = OperatingStateMachine(FS)
    bounds = [0, *sorted(cuts or []), len(s)]
    out = []
    for a, b in itertools.pairwise(bounds):
        out += m.feed(s[a:b], q[a:b])
    return [(t.sample, t.state) for t in out]


@pytest.mark.parametrize("mill_name", ["sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"])
@pytest.mark.parametrize("name", ["start-lrs", "start-grid", "start-elrs"])
def test_start_run_stop_on_single_and_dual_drives(mill_name, name):
    sc = scene(name, mill_name, seed=3, duration_s=185.0)
    tr = transitions(sc)
    assert [st for _, st in tr] == [S.STOPPED, S.STARTING, S.RUNNING, S.STOPPING, S.STOPPED]
    start, stop = sc.truth.starts[0], sc.truth.stops[0]
    assert 0 <= tr[1][0] - start.sample <= 20  # energised within the switch-on front
    assert 0 <= tr[3][0] - stop.sample <= 100  # the switch-off torque drop
    assert tr[2][0] > start.sample + round(start.accel_s * FS)  # after the short circuit


def test_barring_session_is_not_a_start():
    sc = scene("barring", "ball-dual-lrs", seed=1)
    tr = transitions(sc)
    assert [st for _, st in tr] == [S.STOPPED, S.BARRING, S.STOPPED]
    b = sc.truth.barrings[0]
    assert abs(tr[1][0] - b.sample) <= 100
    assert abs(tr[2][0] - round((b.end_t_ns - sc.t0_ns) / 1e6)) <= 1500


def test_failed_start_goes_to_stopping_then_stopped():
    sc = custom("sag-5200-lrs", [{"kind": "failed_start", "at_s": 2.0,
                                  "trip_speed_fraction": 0.4}], 60.0)  # fmt: skip
    assert [st for _, st in transitions(sc)] == [S.STOPPED, S.STARTING, S.STOPPING, S.STOPPED]


def test_dropouts_are_unknown_and_running_resumes():
    sc = scene("telemetry-faults", seed=0)
    tr = transitions(sc)
    assert [st for _, st in tr] == [S.RUNNING, S.UNKNOWN, S.RUNNING, S.UNKNOWN, S.RUNNING]
    assert [t for t, _ in tr[1:]] == [60000, 60500, 150000, 152000]


def test_short_spikes_on_a_stopped_mill_do_not_energise():
    m = OperatingStateMachine(FS)
    q = np.zeros(5000)
    q[1000:1020] = 6.0  # a 20-sample telemetry spike of 600 % (Diering 2011 §5.2.2)
    tr = m.feed(np.zeros(5000), q)
    assert [t.state for t in tr] == [S.STOPPED]


@pytest.mark.parametrize("data", [np.empty(0), np.zeros(10), np.full(10, np.nan)])
def test_degenerate_inputs_never_raise(data):
    m = OperatingStateMachine(FS)
    tr = m.feed(data, data)
    assert all(t.state in (S.UNKNOWN, S.STOPPED) for t in tr)


def test_split_anywhere_and_snapshot_restore_are_exact():
    events = [{"kind": "start", "at_s": 2.0}, {"kind": "trip", "at_s": 60.0},
              {"kind": "barring", "at_s": 100.0, "sweeps": 1}]  # fmt: skip
    sc = custom("ball-dual-lrs", events, 200.0)
    whole = transitions(sc)
    rng = np.random.default_rng(5)
    for _ in range(3):
        cuts = sorted(rng.choice(sc.n_samples, 40, replace=False).tolist())
        assert transitions(sc, cuts) == whole
    s, q = state_inputs(sc, sc.render(0, sc.n_samples))
    for cut in (2_010, 30_000, 61_000, 101_500):
        m = OperatingStateMachine(FS)
        first = m.feed(s[:cut], q[:cut])
        m2 = OperatingStateMachine.restore(json.loads(json.dumps(m.snapshot())))
        rest = m2.feed(s[cut:], q[cut:])
        assert [(t.sample, t.state) for t in first + rest] == whole
