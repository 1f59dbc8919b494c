"""MillConfig: seed numbers, derived kinematics, and errors that name the field."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from pydantic import ValidationError

from millwatch.analytics.drivetrain.mill_config import (
    DriveLayout,
    MillConfig,
    Starter,
    describe_validation_error,
)

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"


def _data(name: str = "sag-5200-lrs") -> dict:
    return tomllib.loads((MILLS / f"{name}.toml").read_text(encoding="utf-8"))


def _errors(data: dict) -> list[str]:
    with pytest.raises(ValidationError) as info:
        MillConfig.model_validate(data)
    return describe_validation_error(info.value)


def test_seed_621_worked_example() -> None:
    """Diering 2011 §6.2.1: 5200 kW, 995 rpm, 113/20 → 49.91 kN·m, 281.97 kN·m, 176 rpm."""
    cfg = MillConfig.from_toml_text((MILLS / "sag-5200-lrs.toml").read_text(encoding="utf-8"))
    assert cfg.motor_rated_torque_knm == pytest.approx(49.91, abs=0.005)
    assert cfg.pinion_rated_torque_knm == pytest.approx(281.97, abs=0.05)
    assert cfg.pinion_speed_rpm == pytest.approx(176.1, abs=0.05)
    assert cfg.mill_speed_rpm == pytest.approx(cfg.pinion_speed_rpm * 22 / 286)
    assert cfg.drive.layout is DriveLayout.SINGLE and cfg.drive.starter is Starter.LRS


def test_defaults_from_seeds() -> None:
    cfg = MillConfig.model_validate(_data())
    a = cfg.alarms
    assert (a.start_peak_warn_pct, a.start_peak_alarm_pct) == (None, None)  # the starter's
    assert (a.starts_per_month_warn, a.starts_per_month_alarm) == (5, 20)
    assert (a.oscillation_range_warn_pct, a.oscillation_range_alarm_pct) == (25.0, 45.0)
    assert (
        a.bending_amplitude_warn_mpa,
        a.bending_amplitude_alarm_mpa,
        a.bending_amplitude_critical_mpa,
    ) == (25.0, 43.0, 90.0)
    assert cfg.telemetry_bandwidth_hz == 250.0 and cfg.design_life_years == 20.0
    # the shipped sag mill's material is App. D §1's (S_e 190.41 MPa); the default is §8.1's
    assert cfg.material.endurance_limit_mpa == pytest.approx(190.41, abs=0.01)
    default = MillConfig.model_validate(_data() | {"material": {}})
    assert default.material.endurance_limit_mpa == pytest.approx(0.4575 * 490, rel=1e-3)  # eq. 4


def test_barring_limit_defaults_by_layout() -> None:
    data = _data()
    data["alarms"].pop("barring_peak_pct")
    assert MillConfig.model_validate(data).barring_peak_limit_pct == 185.0
    dual = _data("ball-dual-lrs")
    dual.pop("alarms")
    assert MillConfig.model_validate(dual).barring_peak_limit_pct == 314.0


def test_excitation_orders_and_bandwidth() -> None:
    cfg = MillConfig.model_validate(_data())
    orders = cfg.excitation_orders()
    assert orders["pinion_3x"] == 3.0  # Fedin & Vinogradov 2018 eq. 12
    assert orders["girth_mesh"] == 22.0
    assert orders["liner_passing"] == pytest.approx(30 * 22 / 286)
    freqs = cfg.excitation_frequencies_hz()
    assert freqs["motor_speed"] == pytest.approx(995 / 60)
    assert freqs["reducer_mesh_1"] == pytest.approx(995 / 60 * 20)
    assert not cfg.observable(freqs["reducer_mesh_1"])  # 331.7 Hz > 250 Hz
    assert cfg.observable(freqs["girth_mesh"])


def test_frozen() -> None:
    cfg = MillConfig.model_validate(_data())
    with pytest.raises(ValidationError):
        cfg.id = "other"  # type: ignore[misc]


@pytest.mark.parametrize(
    ("section", "field", "value", "expected"),
    [
        ("drive", "reducer_ratio", 0.0, "drive.reducer_ratio: must be > 0"),
        ("drive", "motor_power_kw", -5.0, "drive.motor_power_kw: must be > 0"),
        ("drive", "reducer_ration", 5.65, "drive.reducer_ration: unknown field (typo?)"),
        ("drive", "starter", "Diesel", "drive.starter: "),
        ("drive", "reducer_ratio", 6.5, "drive: reducer_stages give ratio"),
        ("shafts", "pinion_diameter_m", 0.0, "shafts.pinion_diameter_m: must be > 0"),
        (
            "alarms",
            "start_peak_warn_pct",
            400.0,
            "alarms: start_peak_warn_pct (400.0) must be below",
        ),
        ("material", "s_ut_mpa", 50.0, "material.s_ut_mpa: must be > 100"),
    ],
)
def test_bad_values_name_the_field(section: str, field: str, value: object, expected: str) -> None:
    data = _data()
    data[section][field] = value
    assert any(line.startswith(expected) for line in _errors(data)), _errors(data)


def test_bad_top_level_and_channel_values() -> None:
    data = _data()
    data["time_zone"] = "Mars/Olympus"
    data["tz"] = "UTC"
    data["channels"]["speed"]["kind"] = "tacho"
    data["channels"]["speed"]["units"] = "V"
    data["channels"]["motor_torque"]["gain"] = 0.0
    data["channels"]["pinion_torque"]["full_scale"] = [10.0, -10.0]
    lines = _errors(data)
    assert any(x.startswith("time_zone: unknown IANA time zone") for x in lines)
    assert "tz: unknown field (typo?)" in lines
    assert any(x.startswith("channels.speed: pulses_per_rev is required") for x in lines)
    assert "channels.motor_torque.gain: must be non-zero, got 0.0" in lines
    assert any(x.startswith("channels.pinion_torque: full_scale") for x in lines)


def test_a_bad_key_is_named_with_its_value_in_words() -> None:
    data = _data()
    data["channels"]["speed"]["key"] = "Speed rpm"
    assert _errors(data) == [
        "channels.speed.key: must be lower-case letters, digits, '_' and '-', in segments "
        "separated by '/', each starting with a letter or digit, got 'Speed rpm'"
    ]


def test_channels_sharing_a_key_are_named_with_the_key() -> None:
    data = _data()
    data["channels"]["speed"]["key"] = "motor_torque"
    assert _errors(data) == [
        "channels.motor_torque.key and channels.speed.key are both 'motor_torque': each "
        "channel needs a key of its own"
    ]


def test_dual_drive_channels_need_a_side() -> None:
    data = _data("ball-dual-lrs")
    data["channels"]["motor_torque_bs"].pop("side")
    assert any("needs side" in line for line in _errors(data))


def test_sn_model_validated() -> None:
    data = _data()
    data["material"]["sn"] = {"name": "shigly"}
    assert any(x.startswith("material.sn: unknown S-N model 'shigly'") for x in _errors(data))
    data["material"]["sn"] = {"name": "fat-normal", "params": {"fat": 125.0, "slope": 1.0}}
    assert any("unknown parameters for 'fat-normal': ['slope']" in x for x in _errors(data))
    data["material"]["sn"] = {"name": "fat-normal", "params": {"fat": 125.0}}
    assert MillConfig.model_validate(data).material.sn.resolved_params() == {"fat": 125.0}
    data["material"]["sn"] = {"name": "shigley-limit"}
    assert MillConfig.model_validate(data).material.sn.resolved_params() == {"S_e": None}


def test_rated_torque_formula() -> None:
    data = _data("rod-1100-grid")
    cfg = MillConfig.model_validate(data)
    assert cfg.motor_rated_torque_knm == pytest.approx(1100 / (2 * math.pi * 740 / 60))
    assert cfg.pinion_rated_torque_knm == pytest.approx(
        cfg.motor_rated_torque_knm * 71 / 17, rel=1e-6
    )
    assert cfg.sides == (None,)
    assert MillConfig.model_validate(_data("ball-dual-lrs")).sides == ("bs", "nbs")


def test_material_sn_curve_uses_the_material_marin_limit():
    from millwatch.analytics.drivetrain.mill_config import MaterialConfig

    material = MaterialConfig()
    curve = material.sn_curve()
    assert curve.S_D == pytest.approx(0.4575 * 490.0, rel=1e-3)  # Diering 2011 §8.1 eq. 4
    fat = MaterialConfig.model_validate({"sn": {"name": "fat-shear", "params": {"fat": 90}}})
    assert fat.sn_curve().S_D == 90
