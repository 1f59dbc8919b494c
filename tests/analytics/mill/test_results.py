"""The analyzer's typed results: every event and window the real analyzer emits on scenes with
each kind of event reads into its model and back unchanged (same keys, same order, same values),
so the typed boundary loses nothing; an unknown or missing key is an error."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.analytics.mill.results import (
    BarringEvent,
    StartEvent,
    SteadyWindowResult,
    StopEvent,
    parse_event,
)
from tests.analytics.scene_helpers import custom

EVENTS = [{"kind": "start", "at_s": 3.0}, {"kind": "trip", "at_s": 95.0},
          {"kind": "barring", "at_s": 130.0, "sweeps": 1},
          {"kind": "failed_start", "at_s": 240.0}]  # fmt: skip


@pytest.fixture(scope="module", params=["sag-5200-lrs", "ball-dual-lrs"])
def analysed(request: pytest.FixtureRequest) -> tuple[MillAnalyzer, list]:
    """A start, a trip, a barring session and a failed start, through the whole analyzer."""
    scene = custom(request.param, EVENTS, 300.0, seed=5)
    data = scene.render(0, scene.n_samples)
    analyzer, events = MillAnalyzer(scene.config), []
    for lo in range(0, scene.n_samples, 1000):
        for name, x in data.items():
            analyzer.add(name, scene.t_ns(lo), scene.fs, x[lo : lo + 1000])
        events += analyzer.process().events
    events += analyzer.flush().events
    return analyzer, events


def test_the_events_come_typed_and_equal_to_the_report(analysed):
    analyzer, events = analysed
    kinds = [type(e) for e in events]
    assert kinds.count(StartEvent) == 2 and StopEvent in kinds and BarringEvent in kinds
    assert [e.failed for e in events if isinstance(e, StartEvent)] == [False, True]
    report = analyzer.report()
    reported = [*report["starts"], *report["stops"], *report["barring"]]
    got = [e.to_json() for e in events]
    assert sorted(got, key=lambda e: e["t_ns"]) == sorted(reported, key=lambda e: e["t_ns"])


def test_every_reported_event_and_window_reads_back_unchanged(analysed):
    report = json.loads(json.dumps(analysed[0].report()))
    for data in [*report["starts"], *report["stops"], *report["barring"]]:
        back = parse_event(data).to_json()
        assert back == data and list(back) == list(data)  # the stored JSON text is the same
    assert report["steady_state"]
    for data in report["steady_state"]:
        assert SteadyWindowResult.model_validate(data).model_dump() == data


def test_a_key_the_model_does_not_know_or_misses_is_an_error(analysed):
    start = next(e for e in analysed[1] if isinstance(e, StartEvent)).to_json()
    with pytest.raises(ValidationError, match="switch_on_peak"):
        parse_event({**start, "switch_on_peak": 1.0})  # a renamed key
    missing = dict(start)
    del missing["alarm"]
    with pytest.raises(ValidationError, match="alarm"):
        parse_event(missing)
