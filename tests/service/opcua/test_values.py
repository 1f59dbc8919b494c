"""The points of a mill from the REST bodies: every path present, values as answered, unknowns
None (never a made-up number), units per channel kind."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from ingest.mill_files import load_mill_config
from service.opcua.values import Kind, mill_points

MILL = load_mill_config(Path(__file__).resolve().parents[3] / "deploy/mills/ball-dual-lrs.toml")

DETAIL = {
    "state": "running",
    "held_reason": None,
    "stale_channels": ["speed"],
    "status": {
        "last_sample_ns": 1_700_000_000_000_000_000,
        "open_alarms": 2,
        "latest_steady": {
            "t_ns": 1_700_000_000_500_000_000,
            "speed_pct": 99.5,
            "imbalance_pct": 3.25,
            "mean": {"pinion_torque_bs": 120.0},
            "range_per_rev": {"pinion_torque_bs": 30.0, "pinion_bending_bs": 42.0},
            "mean_pct": {"pinion_torque_bs": 80.0},
            "range_pct": {"pinion_torque_bs": 20.0},
        },
        "health": {
            "missing_blocks_total": 7,
            "channels": {"speed": {"lag_s": 0.25, "missing_blocks": 7, "stale": True}},
        },
    },
}
LIFE = {"components": {"pinion_combined_bs": {
    "damage": 1e-3, "remaining_life_years_min": None,
    "projections": [{"basis": "last_30_days", "rate_per_year": 2e-3}]}}}  # fmt: skip
STARTS = {"count": 4, "failed": 1, "count_status": "ok"}


def test_values_are_as_answered_and_unknowns_none():
    p = mill_points(MILL, DETAIL, LIFE, STARTS)
    assert p["State"].value == "running" and p["StaleChannels"].value == ["speed"]
    assert p["LastSampleTime"].value == datetime(2023, 11, 14, 22, 13, 20, tzinfo=UTC)
    assert (p["OpenAlarms"].value, p["StartsThisMonth"].value) == (2, 4)
    assert p["SteadyState/pinion_torque_bs/RangePct"].value == 20.0
    assert p["SteadyState/pinion_bending_bs/RangePerRev"].value == 42.0
    assert p["SteadyState/pinion_bending_bs/RangePct"].value is None
    assert p["Components/pinion_combined_bs/Damage"].value == 1e-3
    assert p["Components/pinion_combined_bs/RemainingLifeYears"].value is None
    assert p["Components/pinion_combined_bs/DamageRatePerYear"].value == 2e-3
    assert p["Components/pinion_combined_nbs/Damage"].value is None  # not in the answer
    assert p["Channels/speed/Stale"].value is True
    assert p["Channels/speed/MissingBlocks"].value == 7


def test_every_channel_and_component_has_its_points_with_units():
    p = mill_points(MILL, {}, None, None)
    for name, channel in MILL.channels.items():
        assert p[f"Channels/{name}/LagS"].unit == "s"
        if channel.kind in ("torque", "bending"):
            unit = p[f"SteadyState/{name}/Mean"].unit
            assert unit == {"torque": "kN·m", "bending": "MPa"}[channel.kind]
    assert all(v.value is None or v.kind is Kind.STRINGS for v in p.values())
    assert p["StaleChannels"].value == []
