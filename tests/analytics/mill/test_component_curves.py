"""Per-component S-N curves and the Goodman correction in the live path, against a damage
recomputed independently of the analyzer: the stresses from the scene's channels by the formula,
cycles by the ``rainflow`` package (the residue as half cycles), the curves written out from
their sources (EN 1993-1-9 FAT 100 shear and FAT 160 normal, Diering 2011 App. D §3; the
Shigley line of Diering 2011 eqs. 14–16), Goodman as Diering 2011 §8.1 draws it, Miner's sum.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
import rainflow

from millwatch.analytics.contracts import SnapshotMismatch
from millwatch.analytics.drivetrain.mill_config import MillConfig, MillConfigError
from millwatch.analytics.mill.loads import LoadAnalysis
from millwatch.ingest.mill_files import load_mill_config
from tests.analytics.drivetrain.test_shaft_stress import analysed, scene_data, start_scene
from tests.analytics.scene_helpers import mill


def with_material(config: MillConfig, **material: Any) -> MillConfig:
    """A validated copy of ``config`` with ``[material]`` values replaced."""
    data = config.model_dump(mode="json", exclude_unset=True)
    data["material"] = {**data.get("material", {}), **material}
    return MillConfig.model_validate(data)


APP_D_3 = {
    "pinion_combined": {"mean_stress": "goodman"},
    "pinion_torsion": {"sn": {"name": "fat-shear"}},
    "pinion_bending": {"sn": {"name": "fat-normal"}},
}


def cycles(trace: np.ndarray) -> np.ndarray:
    """(range, mean, count) rows of ``trace`` by the ``rainflow`` package."""
    rows = [(r, m, n) for r, m, n, _, _ in rainflow.extract_cycles(trace) if r > 0]
    return np.array(rows)


def fat_shear_damage(c: np.ndarray) -> float:
    """FAT 100 shear: N = 2·10⁶ (100/Δτ)⁵, no damage below the cut-off at 10⁸ cycles."""
    cutoff = 100.0 * (2e6 / 1e8) ** 0.2
    n = 2e6 * (100.0 / c[:, 0]) ** 5
    return math.fsum((c[:, 2] / n)[c[:, 0] >= cutoff])


def fat_normal_damage(c: np.ndarray) -> float:
    """FAT 160 normal: m = 3 from 160 MPa at 2·10⁶ to the knee at 5·10⁶, m = 5 to the cut-off at
    10⁸ cycles, no damage below it."""
    knee = 160.0 * (2e6 / 5e6) ** (1 / 3)
    cutoff = knee * (5e6 / 1e8) ** 0.2
    s = c[:, 0]
    n = np.where(s >= knee, 2e6 * (160.0 / s) ** 3, 5e6 * (knee / s) ** 5)
    return math.fsum((c[:, 2] / n)[s >= cutoff])


def goodman_shigley_damage(c: np.ndarray, config: MillConfig) -> float:
    """Shigley (eqs. 14–16) on the Goodman-equivalent amplitude S_a/(1 − S_m/S_ut), S_m > 0."""
    m = config.material
    s_e = m.ka * m.kb * m.kc * m.kd * 0.5 * m.s_ut_mpa
    b = -math.log10(0.8 * m.s_ut_mpa / s_e) / 3.0
    k = math.log10((0.8 * m.s_ut_mpa) ** 2 / s_e)
    amp = c[:, 0] / 2.0 / (1.0 - np.maximum(c[:, 1], 0.0) / m.s_ut_mpa)
    n = 10.0 ** ((np.log10(amp) - k) / b)
    return math.fsum(c[:, 2] / n)


def independent(data: dict[str, np.ndarray], config: MillConfig) -> dict[str, float]:
    """Damage of the App. D §3 components of a single drive, from the channels."""
    sh = config.shafts
    kf_b, kf_t = sh.kt_bending, sh.kt_torsion  # notch sensitivity 1 in the shipped mill
    tau = 16.0 * data["pinion_torque"] * 1e-3 / (math.pi * sh.pinion_diameter_m**3)
    sigma = kf_b * data["pinion_bending"] * 0.5 + kf_t * tau  # θ = 45°
    tau_m = 16.0 * data["motor_torque"] * 1e-3 / (math.pi * sh.motor_diameter_m**3)
    return {
        "pinion_combined": goodman_shigley_damage(cycles(sigma), config),
        "pinion_torsion": fat_shear_damage(cycles(kf_t * tau)),
        "pinion_bending": fat_normal_damage(cycles(kf_b * data["pinion_bending"])),
        "motor_torsion": goodman_shigley_damage(cycles(kf_t * tau_m), config)
        if config.material.mean_correction("motor_torsion")
        else None,
    }


def test_per_component_curves_and_goodman_equal_the_independent_damage():
    cfg = with_material(mill("sag-5200-lrs"), components=APP_D_3)
    assert cfg.components == ["pinion_combined", "pinion_torsion", "motor_torsion",
                              "pinion_bending"]  # fmt: skip
    got, want = analysed(cfg), independent(scene_data(), cfg)
    for comp in ("pinion_combined", "pinion_torsion", "pinion_bending"):
        assert want[comp] > 0.0, comp
        assert got[comp] == pytest.approx(want[comp], rel=1e-12), comp


def test_goodman_raises_the_damage_of_a_positive_mean_and_a_curve_is_per_component():
    base = mill("sag-5200-lrs")
    plain = analysed(base)
    cfg = with_material(base, components=APP_D_3)
    got = analysed(cfg)
    assert got["pinion_combined"] > 1.05 * plain["pinion_combined"]  # mean torque > 0
    assert got["motor_torsion"] == plain["motor_torsion"]  # no table: the material's curve


def test_the_plane_angle_changes_the_combined_stress_only():
    base = mill("sag-5200-lrs")
    data = base.model_dump(mode="json", exclude_unset=True)
    data["shafts"] = {**data["shafts"], "plane_angle_deg": 30.0}
    cfg = MillConfig.model_validate(data)
    got, plain = analysed(cfg), analysed(base)
    assert got["pinion_torsion"] == plain["pinion_torsion"]
    assert got["pinion_combined"] != plain["pinion_combined"]
    sh, d = cfg.shafts, scene_data()
    tau = 16.0 * d["pinion_torque"] * 1e-3 / (math.pi * sh.pinion_diameter_m**3)
    two = math.radians(60.0)
    sigma = sh.kt_bending * d["pinion_bending"] * (0.5 + 0.5 * math.cos(two)) + (
        sh.kt_torsion * tau * math.sin(two)
    )
    plain_goodman = with_material(cfg, components={"pinion_combined": {}})
    want = goodman_shigley_damage(np.column_stack([cycles(sigma)[:, 0], np.zeros(
        len(cycles(sigma))), cycles(sigma)[:, 2]]), plain_goodman)  # fmt: skip
    assert got["pinion_combined"] == pytest.approx(want, rel=1e-12)


def test_a_snapshot_on_other_curves_is_refused_in_words():
    sc = start_scene()
    a = LoadAnalysis(mill("sag-5200-lrs"))
    a_data = scene_data()
    from millwatch.analytics.signal.frame_aligner import Frame

    a.feed(Frame(sc.t_ns(0), sc.fs, {k: v[:5000] for k, v in a_data.items()}))
    snap = a.snapshot()
    curves = with_material(mill("sag-5200-lrs"), components={
        "pinion_torsion": {"sn": {"name": "fat-shear"}}})  # fmt: skip
    with pytest.raises(SnapshotMismatch, match=r"pinion_torsion.s damage was computed on the "
                       "S-N curve 'Shigley'.*now gives 'FAT 100 shear'"):  # fmt: skip
        LoadAnalysis.restore(curves, snap)
    goodman = with_material(mill("sag-5200-lrs"), components={
        "pinion_combined": {"mean_stress": "goodman"}})  # fmt: skip
    with pytest.raises(SnapshotMismatch, match=r"mean-stress correction none.*Goodman"):
        LoadAnalysis.restore(goodman, snap)
    bending = with_material(mill("sag-5200-lrs"), components={"pinion_bending": {}})
    with pytest.raises(SnapshotMismatch, match="components motor_torsion, pinion_combined, "
                       "pinion_torsion, the configuration gives"):  # fmt: skip
        LoadAnalysis.restore(bending, snap)
    again = LoadAnalysis.restore(curves, LoadAnalysis(curves).snapshot())
    assert again.snapshot() == LoadAnalysis(curves).snapshot()


@pytest.mark.parametrize(
    ("table", "line", "words"),
    [
        ("material.components.pinion_shaft", "sn = { name = 'fat-shear' }",
         "material.components: unknown component kind(s) ['pinion_shaft']"),
        ("material.components.pinion_torsion", "mean_stress = 'gerber'",
         "material.components.pinion_torsion.mean_stress: Input should be 'none' or 'goodman'"),
        ("material.components.pinion_torsion", "sn = { name = 'fat-shear', params = { S_e = 1 } }",
         "unknown parameters for 'fat-shear': ['S_e']"),
        ("life", "miner_limit = 0", "life.miner_limit: must be > 0.0, got 0"),
        ("shafts", "plane_angle_deg = 90",
         'shafts.plane_angle_deg: must be an angle in degrees strictly between -90 and 90, '
         'or "critical", got 90'),
        ("simulation", "load_pct = 0", "simulation.load_pct: must be > 0.0, got 0"),
    ],
)  # fmt: skip
def test_a_bad_fatigue_setting_is_refused_naming_the_file_field_and_value(table, line, words):
    with pytest.raises(MillConfigError) as refused:
        load_mill_config(written(with_line(mill_text(), table, line)))
    said = str(refused.value)
    assert said.startswith(str(written.path)) and words in said, said


def test_scene_parameters_are_refused_for_a_real_mill():
    text = mill_text().replace("simulated = true", "simulated = false")
    with pytest.raises(MillConfigError, match="simulation: scene parameters are only for a "
                       "simulated mill"):  # fmt: skip
        load_mill_config(written(text))


def with_line(text: str, table: str, line: str) -> str:
    """``text`` with ``line`` in its ``[table]`` (added at the end when it has none)."""
    header = f"[{table}]\n"
    if header in text:
        return text.replace(header, header + line + "\n", 1)
    return f"{text}\n{header}{line}\n"


class _Written:
    """Writes a mill file to one temporary path (the error names it)."""

    def __init__(self) -> None:
        import tempfile
        from pathlib import Path

        self.path = Path(tempfile.mkdtemp(prefix="mill-")) / "my-mill.toml"

    def __call__(self, text: str) -> Any:
        self.path.write_text(text, encoding="utf-8")
        return self.path


written = _Written()


def mill_text() -> str:
    """The shipped single-drive rod mill's file (no [life] miner_limit, no components)."""
    from tests.analytics.scene_helpers import MILLS

    return (MILLS / "rod-1100-grid.toml").read_text(encoding="utf-8")


def critical(config: MillConfig, step: float = 15.0) -> MillConfig:
    data = config.model_dump(mode="json", exclude_unset=True)
    data["shafts"] = {**data["shafts"], "plane_angle_deg": "critical",
                      "critical_plane_step_deg": step}  # fmt: skip
    return MillConfig.model_validate(data)


def combined_at(theta_deg: float, config: MillConfig) -> float:
    """Independent damage of the combined stress on the plane ``theta_deg`` (Shigley)."""
    sh, d = config.shafts, scene_data()
    tau = 16.0 * d["pinion_torque"] * 1e-3 / (math.pi * sh.pinion_diameter_m**3)
    two = math.radians(2.0 * theta_deg)
    sigma = sh.kt_bending * d["pinion_bending"] * (0.5 + 0.5 * math.cos(two)) + (
        sh.kt_torsion * tau * math.sin(two)
    )
    c = cycles(sigma)
    return goodman_shigley_damage(np.column_stack([c[:, 0], np.zeros(len(c)), c[:, 2]]), config)


def test_the_critical_plane_reports_the_plane_of_most_damage_on_its_grid():
    cfg = critical(mill("sag-5200-lrs"), step=15.0)
    assert cfg.shafts.stress_model().plane_angles_deg() == tuple(range(-75, 90, 15))
    sc, data = start_scene(), scene_data()
    a = LoadAnalysis(cfg)
    from millwatch.analytics.signal.frame_aligner import Frame

    for lo in range(0, sc.n_samples, 1000):
        hi = min(lo + 1000, sc.n_samples)
        a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
    row = a.report()["damage"]["pinion_combined"]
    theta = row["plane_angle_deg"]
    assert "critical plane" in row["stress_factors"]
    assert row["with_residue"] == pytest.approx(combined_at(theta, cfg), rel=1e-12)
    every = {t: combined_at(t, cfg) for t in range(-75, 90, 15)}
    assert every[theta] >= 0.99 * max(every.values())  # chosen on committed damage
    assert row["with_residue"] >= analysed(mill("sag-5200-lrs"))["pinion_combined"]
    assert set(a.report()["damage"]) == {"pinion_combined", "pinion_torsion", "motor_torsion"}


def test_the_critical_plane_continues_exactly_after_a_restore():
    cfg = critical(mill("sag-5200-lrs"), step=30.0)
    sc, data = start_scene(), scene_data()
    from millwatch.analytics.signal.frame_aligner import Frame

    def feed(a: LoadAnalysis, lo: int, hi: int) -> None:
        for b in range(lo, hi, 1000):
            e = min(b + 1000, hi)
            a.feed(Frame(sc.t_ns(b), sc.fs, {k: v[b:e] for k, v in data.items()}))

    whole = LoadAnalysis(cfg)
    feed(whole, 0, sc.n_samples)
    part = LoadAnalysis(cfg)
    feed(part, 0, 17000)
    resumed = LoadAnalysis.restore(cfg, part.snapshot())
    feed(resumed, 17000, sc.n_samples)
    assert resumed.report()["damage"] == whole.report()["damage"]
    with pytest.raises(SnapshotMismatch, match="on the critical plane"):
        LoadAnalysis.restore(mill("sag-5200-lrs"), part.snapshot())


def test_a_critical_plane_step_without_the_critical_plane_is_refused():
    data = mill("sag-5200-lrs").model_dump(mode="json", exclude_unset=True)
    data["shafts"] = {**data["shafts"], "critical_plane_step_deg": 10.0}
    with pytest.raises(ValueError, match="critical_plane_step_deg is only used with"):
        MillConfig.model_validate(data)
    with pytest.raises(ValueError, match="does not divide 180"):
        critical(mill("sag-5200-lrs"), step=7.0)


@pytest.mark.parametrize("name", ["ball-dual-lrs", "rod-1100-grid", "sag-5200-lrs"])
def test_the_stored_form_of_a_shipped_mill_reloads_as_the_same_configuration(name):
    """The store keeps what the file set (``MillConfig.stored_form``, what the worker, the
    month-end job and ``millwatch history build`` write): the month-end reports and
    ``millwatch report`` validate it again, and a setting refused when set (``kt_bending``
    under App. D's ``single_kt``) must not come back as a written-out default."""
    config = mill(name)
    for c in (config, config.model_copy(update={"simulated": True})):
        assert MillConfig.model_validate(c.stored_form()) == c


def test_goodman_is_refused_where_the_full_scales_reach_the_ultimate_strength():
    """A cycle mean at S_ut has no Goodman life (the block would be refused mid-stream): the
    file is refused at load instead, naming the setting and the stress the full scales allow."""
    sag = mill("sag-5200-lrs")  # pinion_combined reaches 849 MPa within its full scales
    assert sag.stress_bounds()["pinion_combined"] == pytest.approx(848.8, abs=0.1)
    with_material(sag, components={"pinion_combined": {"mean_stress": "goodman"}})  # 850
    with pytest.raises(ValueError) as refused:
        with_material(sag, s_ut_mpa=800.0,
                      components={"pinion_combined": {"mean_stress": "goodman"}})  # fmt: skip
    assert ('material.components.pinion_combined.mean_stress = "goodman": within the '
            "channels' full scales pinion_combined reaches 849 MPa, not below S_ut = 800 MPa"
            in str(refused.value))  # fmt: skip
    with_material(sag, s_ut_mpa=800.0, components={"pinion_torsion": {"mean_stress": "goodman"}})


def test_app_d_on_the_critical_plane_costs_each_component_on_its_governing_plane():
    """App. D's portions are counted on every plane; the stop event's record and the start
    cost name components (not planes), the governing plane's, as the damage table does."""
    from millwatch.analytics.signal.frame_aligner import Frame
    from millwatch.ingest.sim.scenes import get_scene

    sc = get_scene("start-lrs", critical(mill("sag-5200-lrs"), step=30.0), seed=0)
    data = sc.render(0, sc.n_samples)
    a = LoadAnalysis(sc.config)
    events = []
    for lo in range(0, sc.n_samples, 1000):
        hi = min(lo + 1000, sc.n_samples)
        events += a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
    damage = a.report()["damage"]
    components = {"pinion_combined", "pinion_torsion", "motor_torsion"}
    assert set(damage) == components
    assert {c for c in damage if damage[c]["start_cost"]["method"] == "app_d"} == components
    stops = [e for e in events if e.get("event") == "stop"]
    assert stops, "the start-lrs scene ends with a stop"
    assert set(stops[-1]["app_d"]["components"]) == components
