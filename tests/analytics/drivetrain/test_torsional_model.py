"""Fedin & Vinogradov 2018 lumped torsional model: Table 2 frequencies, modes, warnings, dynamic
factor."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pydantic import ValidationError

from millwatch.analytics.drivetrain.kinematics import ExpectedLine
from millwatch.analytics.drivetrain.torsional_model import (
    SEED_001_MILLS,
    DynamicFactorMeter,
    TorsionalModel,
    TorsionalParams,
    dynamic_factor,
    pitch_radius_m,
    resonance_warnings,
)

MRG = SEED_001_MILLS["MRG 5500x7500"]
MSHTS = SEED_001_MILLS["MSHTS 5500x6500"]


def chain(p: TorsionalParams) -> TorsionalParams:
    return p.model_copy(update={"m": None, "c2": None, "r": None})


def eq10_matrices(p: TorsionalParams) -> tuple[np.ndarray, np.ndarray]:
    """K and M written out row by row from Fedin & Vinogradov 2018 eq. 10 (conservative signs), 4
    DOF."""
    g = p.c23 / p.r
    k = np.array(
        [
            [p.c01 + p.c12, -p.c12, 0.0, 0.0],
            [-p.c12, p.c12 + p.c23, -p.c23, -g],
            [0.0, -p.c23, p.c23, g],
            [0.0, -g, g, p.c2 + p.c23 / p.r**2],
        ]
    )
    return k, np.diag([p.I1, p.I2, p.I3, p.m])


def independent_hz(k: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Frequencies from the non-symmetric eigenproblem M⁻¹K (a different LAPACK path)."""
    w2 = np.linalg.eigvals(np.linalg.solve(m, k)).real
    return np.sort(np.sqrt(w2)) / (2 * math.pi)


@pytest.mark.parametrize(
    ("params", "expected"),
    [(MRG, [3.109, 8.402, 107.84]), (MSHTS, [1.240, 3.959, 104.09])],
)
def test_table_2_torsional_chain(params: TorsionalParams, expected: list[float]) -> None:
    model = TorsionalModel(chain(params))
    freqs = model.natural_frequencies_hz()
    assert freqs == pytest.approx(expected, rel=1e-3)
    k = np.array([[params.c01 + params.c12, -params.c12, 0], [-params.c12, params.c12 + params.c23,
                  -params.c23], [0, -params.c23, params.c23]])  # fmt: skip
    m = np.diag([params.I1, params.I2, params.I3])
    assert freqs == pytest.approx(independent_hz(k, m), rel=1e-9)


@pytest.mark.parametrize("params", [MRG, MSHTS])
def test_transverse_pinion_mass_against_eq10(params: TorsionalParams) -> None:
    model = TorsionalModel(params)
    k, m = eq10_matrices(params)
    assert np.allclose(model.stiffness_matrix(), k, rtol=1e-12)
    assert model.natural_frequencies_hz() == pytest.approx(independent_hz(k, m), rel=1e-9)


@pytest.mark.parametrize("params", [MRG, MSHTS])
def test_against_scipy_generalised_eigh(params: TorsionalParams) -> None:
    scipy_linalg = pytest.importorskip("scipy.linalg")
    k, m = eq10_matrices(params)
    w2 = scipy_linalg.eigh(k, m, eigvals_only=True)
    freqs = TorsionalModel(params).natural_frequencies_hz()
    assert freqs == pytest.approx(np.sqrt(w2) / (2 * math.pi), rel=1e-9)


def test_seed_mill_values() -> None:
    assert MRG.r == pytest.approx(0.3142, abs=1e-4)  # module 25 mm, 25 teeth, helix 6°
    assert pitch_radius_m(25.0, 46, 6.0) == pytest.approx(0.5782, abs=1e-4)
    assert TorsionalModel(MRG).natural_frequencies_hz() == pytest.approx(
        [3.107, 8.385, 98.77, 343.6], rel=1e-3
    )


def test_rigid_supports_recover_the_chain() -> None:
    stiff = MRG.model_copy(update={"c2": 1e18})
    freqs = TorsionalModel(stiff).natural_frequencies_hz()
    assert freqs[:3] == pytest.approx(TorsionalModel(chain(MRG)).natural_frequencies_hz(), rel=1e-4)


def test_modes_are_m_orthogonal_and_solve_the_eigenproblem() -> None:
    model = TorsionalModel(MRG)
    k, m = model.stiffness_matrix(), model.mass_matrix()
    modes = model.modes()
    shapes = np.array([[mo.shape[d] for d in model.dofs] for mo in modes]).T
    gram = shapes.T @ m @ shapes
    assert np.allclose(gram - np.diag(np.diag(gram)), 0.0, atol=1e-9 * np.abs(gram).max())
    for j, mo in enumerate(modes):
        w2 = (2 * math.pi * mo.frequency_hz) ** 2
        v = shapes[:, j]
        assert np.allclose(k @ v, w2 * m @ v, rtol=1e-8, atol=1e-8 * np.abs(k @ v).max())
        assert max(abs(x) for x in mo.shape.values()) == pytest.approx(1.0)
    assert json.loads(json.dumps(modes[0].to_dict()))["frequency_hz"] == modes[0].frequency_hz


def test_partial_transverse_parameters_are_refused() -> None:
    with pytest.raises(ValidationError, match="m, c2 and r"):
        TorsionalParams(I1=1, I2=1, I3=1, c01=1, c12=1, c23=1, m=10.0)


def test_resonance_warning_for_3x_drive_gear_near_the_second_mode() -> None:
    # Fedin & Vinogradov 2018 §2.1: MRG pinion at 150 rpm, 3× rotation = 7.5 Hz; mode 2 at 8.40 Hz
    freqs = TorsionalModel(chain(MRG)).natural_frequencies_hz()
    lines = [
        ExpectedLine("pinion_3x", "pinion_3x", "fundamental", 3.0, 7.5, True),
        ExpectedLine("girth_mesh", "girth_mesh", "fundamental", 25.0, 62.5, True),
        ExpectedLine("hidden", "hidden", "fundamental", 1.0, 8.4, False),
    ]
    warnings = resonance_warnings(freqs, lines, band=0.15)
    assert [(w.line, w.mode) for w in warnings] == [("pinion_3x", 2)]
    assert warnings[0].separation_pct == pytest.approx(100 * (7.5 - freqs[1]) / freqs[1])
    assert "8.40 Hz" in warnings[0].message()
    assert resonance_warnings(freqs, lines, band=0.05) == []


def test_forced_response_peaks_at_a_natural_frequency() -> None:
    model = TorsionalModel(chain(MRG))
    f2 = model.natural_frequencies_hz()[1]
    delta = 0.2e-3 / MRG.r  # Fedin & Vinogradov 2018: r·δφ = 0.2 mm
    shaft = [model.forced_response(f, delta)["shaft_torque_nm"] for f in (5.0, 7.5, f2)]
    assert shaft[0] < shaft[1] < shaft[2]
    lightly = TorsionalModel(chain(MRG).model_copy(update={"psi": 0.3}))
    assert lightly.forced_response(f2, delta)["shaft_torque_nm"] > shaft[2]


def test_dynamic_factor_eq13() -> None:
    t = np.linspace(0.0, 10.0, 10_001)
    # K_H = 1.58 of Fedin & Vinogradov 2018 Fig. 1a
    torque = 200.0 + 116.0 * np.sin(2 * math.pi * 7.5 * t)
    assert dynamic_factor(torque, nominal=200.0) == pytest.approx(1.58, abs=1e-4)
    assert dynamic_factor(torque) == pytest.approx(1.58, abs=1e-3)
    assert math.isnan(dynamic_factor(np.array([])))
    assert math.isnan(dynamic_factor(np.array([np.nan])))


def test_dynamic_factor_meter_streams_and_restores() -> None:
    rng = np.random.default_rng(4)
    x = 100.0 + rng.normal(0.0, 10.0, 5000)
    meter = DynamicFactorMeter()
    meter.feed(x[:1234])
    restored = DynamicFactorMeter.restore(json.loads(json.dumps(meter.snapshot())))
    for m in (meter, restored):
        m.feed(x[1234:])
        assert m.value == pytest.approx(dynamic_factor(x), rel=1e-12)
    assert math.isnan(DynamicFactorMeter().value)


# ---------------------------------------------------------------- a mill's model (mill file)
def test_the_shipped_mills_carry_a_model_in_words():
    from pathlib import Path

    from millwatch.analytics.drivetrain.torsional_model import (
        NO_MODEL_NOTE,
        design_resonances,
        natural_frequencies_of,
        torsional_note,
    )
    from millwatch.ingest.mill_files import load_mill_config

    mills = Path(__file__).resolve().parents[3] / "deploy" / "mills"
    for path in sorted(mills.glob("*.toml")):
        cfg = load_mill_config(path)
        natural = natural_frequencies_of(cfg)
        assert len(natural) == 4 and natural[0] > 1.0, path.name  # no rigid-body mode
        assert design_resonances(cfg) == [], path.name  # no expected line near a mode
        assert torsional_note(cfg).startswith("natural frequencies ")
    sag = load_mill_config(mills / "sag-5200-lrs.toml")
    wide = sag.model_copy(
        update={"alarms": sag.alarms.model_copy(update={"resonance_margin_warn": 0.35})}
    )
    near = design_resonances(wide)
    assert {"pinion_3x", "liner_passing"} <= {w.line for w in near}
    assert all(abs(w.separation_pct) <= 35.0 for w in near)
    assert [abs(w.separation_pct) for w in near] == sorted(abs(w.separation_pct) for w in near)
    assert "pinion_3x at 8.81 Hz is -30.5 % from natural frequency 12.67 Hz" in torsional_note(wide)
    bare = sag.model_copy(update={"torsional": None})
    assert natural_frequencies_of(bare) == () and torsional_note(bare) == NO_MODEL_NOTE
