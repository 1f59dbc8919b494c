"""The parity test's comparison (``parity.py``) on small tables: it reports a value that
differs, a quantity missing or extra, a number a surface cannot give, and honours a stated
tolerance only within its bound."""

from __future__ import annotations

import math

from tests.integration.parity import (
    Figures,
    Mismatch,
    Tolerance,
    foxglove_figures,
    matrix,
    metrics_figures,
    mismatches,
    table,
    without_prior,
)

PRODUCER = Figures(
    "millwatch analyze --json",
    {"seconds/run": 129.141, "seconds/stopped": 28.442, "starts": 1,
     "steady/latest/motor_torque/range_pct": 19.3, "damage/pinion_combined/start": 2.0e-9},
    (".*",),
)  # fmt: skip


def surface(values: dict[str, float | None], *tolerances: tuple[str, Tolerance]) -> Figures:
    return Figures("s", values, (r"seconds/.*", "starts", r"steady/latest/.*"), tolerances)


def test_equal_figures_agree_and_unrendered_quantities_are_not_asked_for():
    same = {"seconds/run": 129.141, "seconds/stopped": 28.442, "starts": 1.0,
            "steady/latest/motor_torque/range_pct": 19.3}  # fmt: skip
    assert mismatches(PRODUCER, surface(same)) == []  # damage/... is not rendered by "s"


def test_a_different_missing_extra_or_unknown_value_is_reported_with_both_values():
    got = surface({"seconds/run": 64.117, "starts": 1.0, "seconds/stopped": None,
                   "steady/latest/motor_torque0/range_pct": 19.3})  # fmt: skip
    found = {m.quantity: (m.want, m.got) for m in mismatches(PRODUCER, got)}
    assert found == {
        "seconds/run": (129.141, 64.117),
        "seconds/stopped": (28.442, None),  # a Bad OPC UA status, say
        "steady/latest/motor_torque/range_pct": (19.3, None),  # not under the mill file's name
        "steady/latest/motor_torque0/range_pct": (None, 19.3),
    }
    text = table(mismatches(PRODUCER, got))
    assert "seconds/run" in text and "129.141" in text and "64.117" in text and "-65.024" in text


def test_a_tolerance_admits_only_within_its_bound_and_says_why():
    lag = Tolerance(absolute=0.004 + 1e-9, why="look-ahead")  # 28.442 - 28.438 > 0.004
    values = {"seconds/run": 129.141, "seconds/stopped": 28.438, "starts": 1,
              "steady/latest/motor_torque/range_pct": 19.3}  # fmt: skip
    close = surface(values, ("seconds/stopped", lag))
    assert mismatches(PRODUCER, close) == []
    far = replace_value(close, "seconds/stopped", 28.4)
    (m,) = mismatches(PRODUCER, far)
    assert (m.quantity, m.allowed) == ("seconds/stopped", lag)
    assert "tolerance ±0.004: look-ahead" in m.line()
    assert Tolerance(relative=1e-12).admits(1.0, 1.0 + 1e-13)
    assert not Tolerance(relative=1e-12).admits(1.0, 1.0 + 1e-11)
    assert not Tolerance().admits(0.1 + 0.2, 0.3)  # exact means exact


def test_nan_is_never_equal():
    got = surface({"seconds/run": math.nan, "seconds/stopped": 28.442, "starts": 1,
                   "steady/latest/motor_torque/range_pct": 19.3})  # fmt: skip
    assert [m.quantity for m in mismatches(PRODUCER, got)] == ["seconds/run"]


def replace_value(f: Figures, quantity: str, value: float) -> Figures:
    return Figures(f.surface, {**f.values, quantity: value}, f.covers, f.tolerances)


def test_metrics_text_is_read_per_mill_with_the_bending_range_from_its_amplitude():
    text = "\n".join([
        "# HELP millwatch_damage_ratio Miner damage",
        'millwatch_damage_ratio{component="pinion_combined",mill="m1"} 6.18e-08',
        'millwatch_damage_ratio{component="pinion_combined",mill="other"} 1.0',
        'millwatch_starts_this_month{mill="m1"} 1.0',
        'millwatch_oscillation_range_percent{channel="motor_torque",mill="m1"} 19.3',
        'millwatch_bending_amplitude_megapascals{channel="pinion_bending",mill="m1"} 8.2',
    ])  # fmt: skip
    got = metrics_figures(text, "m1", {"pinion_bending"})
    assert got.values == {
        "damage/pinion_combined/with_residue": 6.18e-08,
        "starts": 1.0,
        "steady/latest/motor_torque/range_pct": 19.3,
        "steady/latest/pinion_bending/range_per_rev": 16.4,
    }
    assert not got.renders("steady/latest/bending0/range_per_rev")


class _Value:
    def __init__(self, value: str) -> None:
        self.value = value


class _Damage:
    def __init__(self, committed: float, with_residue: float) -> None:
        self.committed, self.with_residue = committed, with_residue


def test_foxglove_phase_seconds_run_from_each_state_change_to_the_next_and_the_span_end():
    s = 1_000_000_000
    export = {
        "/m1/state": [("kv", 0, 0, _Value("running")), ("kv", 65 * s, 0, _Value("stopping")),
                      ("kv", 78 * s, 0, _Value("stopped"))],
        "/m1/damage/pinion_combined": [("d", 199 * s, 0, _Damage(1.0, 2.0)),
                                       ("d", 200 * s, 0, _Damage(1.5, 2.5))],
    }  # fmt: skip
    got = foxglove_figures(export, "m1").values
    assert (got["seconds/run"], got["seconds/stop"], got["seconds/stopped"]) == (65.0, 13.0, 122.0)
    assert got["seconds/start"] == 0.0 and got["starts"] == 0
    assert got["damage/pinion_combined/committed"] == 1.5


def test_the_matrix_shows_every_quantity_of_every_surface():
    text = matrix(PRODUCER, [surface({"seconds/run": 64.117})])
    lines = text.splitlines()
    assert lines[0].split() == ["quantity", "millwatch", "analyze", "--json", "s"]
    row = next(line for line in lines if line.startswith("seconds/run"))
    assert row.split() == ["seconds/run", "129.141", "64.117"]
    damage = next(line for line in lines if line.startswith("damage/"))
    assert damage.split()[-1] == "·"  # not rendered by that surface
    assert isinstance(Mismatch("s", "q", 1.0, None).line(), str)


def test_a_prior_shown_in_the_damage_is_taken_off_exact_to_the_rounding_of_the_sum():
    monitored = 1.3103052180184303e-09
    shown = Figures("OPC UA", {"damage/pinion_combined_bs/with_residue": 0.15 + monitored},
                    (r"damage/[^/]+/with_residue",))  # fmt: skip
    producer = Figures("analyze", {"damage/pinion_combined_bs/with_residue": monitored}, (".*",))
    assert mismatches(producer, shown) != []  # 0.15 of prior is not monitored damage
    got = without_prior(shown, {"pinion_combined_bs": 0.15})
    assert mismatches(producer, got) == []
    assert "prior damage 0.15" in got.tolerance("damage/pinion_combined_bs/with_residue").why
    assert without_prior(shown, {}) == shown  # no prior, nothing changed, no tolerance
    wrong = replace_value(got, "damage/pinion_combined_bs/with_residue", monitored * 1.01)
    assert mismatches(producer, wrong) != []


def test_tolerances_that_match_together_give_the_widest_bound_and_every_reason():
    f = surface({}, ("seconds/.*", Tolerance(absolute=0.004, why="a")),
                ("seconds/run", Tolerance(relative=1e-12, why="b")))  # fmt: skip
    t = f.tolerance("seconds/run")
    assert (t.absolute, t.relative, t.why) == (0.004, 1e-12, "a; b")
    assert f.tolerance("starts") == Tolerance()
