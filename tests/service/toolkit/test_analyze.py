"""``millwatch.analyze``: the DataFrames carry the numbers ``millwatch analyze --json`` prints,
under the same names, for a real recording; cycles and matrices agree with the damage."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

import millwatch
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.fatigue.miner import DamageRecorder
from millwatch.analytics.mill.cycle_matrix import sparse_matrix
from millwatch.analytics.mill.results import StartEvent
from millwatch.cli.main import main
from millwatch.ingest.mill_files import load_mill_config
from millwatch.toolkit.tables import events_table
from millwatch.worker.offline_analysis import analyze_files
from tests.service.toolkit.conftest import MILL


@pytest.fixture(scope="module")
def result(start_recording) -> millwatch.AnalysisResult:
    return millwatch.analyze([str(start_recording)], mill=str(MILL), cycles=True)


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
    class StartWithMore(StartEvent):  # as another feature may add to the start record
        coupling_slip_deg: float | None = None

    start = result.report.starts[0]
    extended = StartWithMore(**start.model_dump(), coupling_slip_deg=1.5)
    table = events_table([extended])
    assert table.loc[0, "coupling_slip_deg"] == 1.5 and table.loc[0, "kind"] == "start"


def test_the_run_up_resonance_is_a_column_of_the_starts(result):
    starts = result.events[result.events["kind"] == "start"]
    assert list(starts["resonance_hz"]) == [s.resonance_hz for s in result.report.starts]
    assert "resonance_speed_pct" in starts and "model_natural_hz" in starts


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


def miner_sum(config: MillConfig, component: str, cycles: pd.DataFrame) -> float:
    """Miner's sum of ``cycles`` on the component's S-N curve and mean-stress correction, at
    stress factor 1 (the cycles' stress is after the factors already)."""
    material = config.material
    recorder = DamageRecorder(
        material.sn_curve(component), scale=1.0, mean_correction=material.mean_correction(component)
    )
    r, m, c = (cycles[k].to_numpy() for k in ("range", "mean", "count"))
    return math.fsum(recorder.damage_of(r, m, c))


@pytest.mark.parametrize("component", ["pinion_combined", "pinion_torsion", "motor_torsion"])
def test_cycles_are_what_the_damage_is_computed_from(result, component):
    """Miner's sum over the cycles, on the component's curve at factor 1 (their stress is
    after the factors already), is the committed damage."""
    cycles = result.cycles(component)
    assert list(cycles.columns) == ["range", "mean", "count", "t"]
    assert set(np.unique(cycles["count"])) <= {0.5, 1.0} and (cycles["range"] >= 0).all()
    damage = miner_sum(load_mill_config(MILL), component, cycles)
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
    with pytest.raises(ValueError, match=r"no component 'gearbox'.*pinion_combined"):
        result.matrix("gearbox")


def test_without_cycles_the_matrix_is_the_same_and_cycles_say_how(result, start_recording):
    light = millwatch.analyze([start_recording], mill=MILL, spectra=False)
    for comp in result.damage.index:
        assert light.matrix(comp).equals(result.matrix(comp))
    with pytest.raises(ValueError, match=r"analyze\(\.\.\., cycles=True\)"):
        light.cycles("pinion_combined")
    # states, events and damage do not depend on the spectra (as --no-spectra)
    assert light.damage.equals(result.damage) and light.events.equals(result.events)
    assert light.harmonics.empty


def test_a_recording_without_the_mill_is_named(start_recording):
    with pytest.raises(ValueError, match="no blocks of mill 'ball-dual-lrs'"):
        millwatch.analyze([start_recording], mill=MILL.parent / "ball-dual-lrs.toml")


def test_the_matrix_is_the_analyzers_own_daily_matrices_summed(result, start_recording):
    """The worker's per-day and per-phase matrices of the same analysis, added up, hold the
    same counts in the same cells (a record within the days they keep)."""
    config = load_mill_config(MILL)
    sink, _ = analyze_files([start_recording], [config])  # (no cycle log)
    analyzer = sink.analyzers[config.id]
    analyzer.report()  # (attributes the decided cycles, as the report does)
    own = analyzer.cycle_matrices_by_day()
    assert set(own) == set(result.damage.index)
    for comp, plain in own.items():
        edges = (plain["range_edges"], plain["mean_edges"])
        total = RangeMeanMatrix(*edges)
        for phases in plain["days"].values():
            for cells in phases.values():
                total = total + sparse_matrix(edges, cells)
        assert np.array_equal(result.matrix(comp).to_numpy(), total.half_cycles / 2.0), comp
        assert list(result.matrix(comp).index.left[1:]) == list(total.range_edges)


def test_on_the_critical_plane_the_cycles_are_those_of_the_plane_reported(tmp_path):
    """A dual drive searching the critical plane: each component's cycles are its reported
    plane's (their Miner sum is its committed damage), the matrix holds them all."""
    text = (MILL.parent / "ball-dual-lrs.toml").read_text(encoding="utf-8")
    mill = tmp_path / "critical.toml"
    mill.write_text(text.replace("plane_angle_deg = 45.0", 'plane_angle_deg = "critical"', 1))
    rec = tmp_path / "dual.mcap"
    assert main(["simulate", "--scene", "start-lrs", "--mill", str(mill), "--duration", "60s",
                 "--out", str(rec), "--no-progress"]) == 0  # fmt: skip
    result = millwatch.analyze([rec], mill=mill, cycles=True)
    config = load_mill_config(mill)
    assert result.report.damage["pinion_combined_bs"].plane_angle_deg is not None
    for comp in result.damage.index:
        cycles = result.cycles(comp)
        committed = result.damage_totals.loc[comp, "committed"]
        assert miner_sum(config, comp, cycles) == pytest.approx(committed, rel=1e-9)
        assert result.matrix(comp).to_numpy().sum() == cycles["count"].sum()


def test_the_plots_draw_the_record_as_analyze_plots_does(result):
    """Each plot method gives the figure ``analyze --plots`` writes, for the event asked for."""
    from millwatch.plots.campbell import ORDER_GID, RESONANCE_GID
    from millwatch.plots.events import EVENT_GID, event_marks

    start = result.report.starts[0]
    fig = result.plot_event(0)  # row 0 of .events: the start
    markers = [a for ax in fig.axes for a in ax.get_lines() if a.get_gid() == EVENT_GID]
    assert len(markers) == len(event_marks(start)) > 0
    gids = [a.get_gid() for ax in result.plot_campbell(0).axes for a in ax.get_lines()]
    assert ORDER_GID in gids
    assert gids.count(RESONANCE_GID) == (start.resonance_hz is not None)
    component = next(iter(result.damage.index))
    assert result.plot_matrix(component).axes
    assert result.plot_trend().axes
    with pytest.raises(ValueError, match="event 1 is a stop"):
        result.plot_campbell(1)
    with pytest.raises(ValueError, match="event 9 is not a start or stop"):
        result.plot_event(9)
