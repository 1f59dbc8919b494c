"""``millwatch.analyze``: the DataFrames carry the numbers ``millwatch analyze --json`` prints,
under the same names, for a real recording; cycles and matrices agree with the damage."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

import millwatch
from millwatch.analytics.fatigue.miner import DamageRecorder
from millwatch.analytics.mill.results import StartEvent
from millwatch.cli.main import main
from millwatch.ingest.mill_files import load_mill_config
from millwatch.toolkit.tables import events_table
from tests.service.toolkit.conftest import MILL


@pytest.fixture(scope="module")
def result(start_recording) -> millwatch.AnalysisResult:
    return millwatch.analyze([str(start_recording)], mill=str(MILL))


@pytest.fixture
def cli_json(start_recording, capsys) -> str:
    capsys.readouterr()
    assert main(["analyze", str(start_recording), "--mill", str(MILL), "--json",
                 "--no-progress"]) == 0  # fmt: skip
    return capsys.readouterr().out


def test_to_json_is_what_analyze_json_prints(result, cli_json):
    assert result.to_json() + "\n" == cli_json


def test_events_carry_the_json_numbers_in_time_order(result, cli_json):
    r = json.loads(cli_json)
    ev = result.events
    assert list(ev["kind"]) == ["start", "stop"] and ev["t"].is_monotonic_increasing
    assert str(ev["t"].dt.tz) == "UTC"
    (start,) = r["starts"]
    row = ev[ev["kind"] == "start"].iloc[0]
    assert row["t"] == pd.Timestamp(start["t_ns"], unit="ns", tz="UTC")
    for name in ("switch_on_peak_pct", "short_circuit_peak_pct", "rise_time_10_90_ms",
                 "accel_s", "oscillation_peak_pct", "end_t_ns", "sample"):  # fmt: skip
        assert row[name] == start[name], name
    (stop,) = r["stops"]
    row = ev[ev["kind"] == stop["kind"]].iloc[0]
    assert (row["rocking_peak_pct"], row["fall_ms"]) == (stop["rocking_peak_pct"], stop["fall_ms"])


def test_a_field_added_to_a_typed_record_becomes_a_column(result):
    class StartWithResonance(StartEvent):  # as another feature may add to the start record
        resonance_hz: float | None = None

    start = result.report.starts[0]
    extended = StartWithResonance(**start.model_dump(), resonance_hz=12.7)
    table = events_table([extended])
    assert table.loc[0, "resonance_hz"] == 12.7 and table.loc[0, "kind"] == "start"


def test_damage_is_the_json_damage_by_component_and_phase(result, cli_json):
    damage = json.loads(cli_json)["damage"]
    assert list(result.damage.index) == list(damage)
    for comp, d in damage.items():
        assert list(result.damage.columns) == list(d["phases"])
        for phase, value in d["phases"].items():
            assert result.damage.loc[comp, phase] == value, (comp, phase)
        for name in ("committed", "pending_residue", "with_residue"):
            assert result.damage_totals.loc[comp, name] == d[name]


def test_steady_windows_and_harmonics_are_the_json_ones(result, cli_json):
    r = json.loads(cli_json)
    assert len(result.steady) == len(r["steady_state"]) == 2
    for k, w in enumerate(r["steady_state"]):
        row = result.steady.iloc[k]
        assert row["t"] == pd.Timestamp(w["t_ns"], unit="ns", tz="UTC")
        assert row["t_end"] - row["t"] == pd.Timedelta(seconds=60)
        for ch, v in w["range_pct"].items():
            assert row[f"range_pct.{ch}"] == v
        assert row["range_per_rev.pinion_bending"] == w["range_per_rev"]["pinion_bending"]
    assert len(result.harmonics) == len(r["harmonics"])
    for k, h in enumerate(r["harmonics"]):
        row = result.harmonics.iloc[k]
        assert (row["channel"], row["name"], row["detected"]) == (
            h["channel"], h["name"], h["detected"])  # fmt: skip
        if h["frequency_hz"] is not None:
            assert row["frequency_hz"] == h["frequency_hz"]


@pytest.mark.parametrize("component", ["pinion_combined", "pinion_torsion", "motor_torsion"])
def test_cycles_are_what_the_damage_is_computed_from(result, component):
    """Miner's sum over the cycles, on the component's curve at factor 1 (their stress is
    after the factors already), is the committed damage."""
    cycles = result.cycles(component)
    assert list(cycles.columns) == ["range", "mean", "count", "t"]
    assert set(np.unique(cycles["count"])) <= {0.5, 1.0} and (cycles["range"] >= 0).all()
    config = load_mill_config(MILL)
    material = config.material
    recorder = DamageRecorder(
        material.sn_curve(component), scale=1.0, mean_correction=material.mean_correction(component)
    )
    r, m, c = (cycles[k].to_numpy() for k in ("range", "mean", "count"))
    damage = math.fsum(recorder.damage_of(r, m, c))
    assert damage == pytest.approx(result.damage_totals.loc[component, "committed"], rel=1e-9)
    t, report = cycles["t"], result.report
    assert str(t.dt.tz) == "UTC"
    assert pd.Timestamp(report.t0_ns, tz="UTC") <= t.min() <= t.max() < pd.Timestamp(
        report.t_end_ns, tz="UTC")  # fmt: skip


@pytest.mark.parametrize("component", ["pinion_combined", "pinion_torsion", "motor_torsion"])
def test_the_matrix_holds_every_cycle(result, component):
    cycles = result.cycles(component)
    matrix = result.matrix(component)
    assert matrix.to_numpy().sum() == cycles["count"].sum() > 100
    # the largest cycle lands in the bin of its range and mean
    big = cycles.loc[cycles["range"].idxmax()]
    r = matrix.index.get_indexer([big["range"]])[0]
    m = matrix.columns.get_indexer([big["mean"]])[0]
    assert matrix.iloc[r, m] >= big["count"]


def test_an_unknown_component_is_named(result):
    with pytest.raises(ValueError, match=r"no component 'gearbox'.*pinion_combined"):
        result.cycles("gearbox")


def test_a_recording_without_the_mill_is_named(start_recording):
    with pytest.raises(ValueError, match="no blocks of mill 'ball-dual-lrs'"):
        millwatch.analyze([start_recording], mill=MILL.parent / "ball-dual-lrs.toml")
