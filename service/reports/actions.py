"""What drives a mill's damage, in words, and the actions it calls for, with their evidence.

Each rule is a pure function of a month's :class:`Evidence`; its threshold names its source:

=================  ==========================================================================
rule               fires when → action (source)
=================  ==========================================================================
``starts``         starts above the supplier norm of 3–5 a month → record and scrutinise every
                   stop and start, keep them to a minimum (Diering 2011 §6.1.3, §10.3)
``start_peaks``    a start peaked above the start-peak warning level (the starter type's mean +
                   2 SD, §6.2.1, Tables 3–11, §7.2), or 8 of 10 or more of the month's starts
                   above the starter type's field average → investigate the trips; check the
                   liquid starter's electrolyte density with strain gauges (§10.2; a Grid
                   starter: not recommended for mills, §10.4)
``bending``        steady bending amplitude above 25 MPa (experience), 43 MPa (fatigue reserve
                   factor 2 at rated torque) or 90 MPa (failure within weeks), Diering 2011
                   §8.1 → check the drivetrain alignment; realign the whole drivetrain after any
                   pinion adjustment (§6.2.6, §10.1)
``gear_error``     a line at 3× pinion speed of at least :data:`GEAR_ERROR_LINE_PCT` of rated
                   torque → inspect the gear mesh for kinematic error (Fedin & Vinogradov 2018
                   eq. 12: the kinematic error excites 3× the drive-gear rotation)
=================  ==========================================================================

:func:`recommend` runs them all; :func:`carry` sets last month's actions against this month's
(``done``: the condition is no longer seen; ``still open``; ``not checked``: this month was not
monitored). :func:`drivers` says what drives the damage (starts against running, bending against
torsion, which component). Pure: plain data in, frozen dataclasses out.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from millwatch.reports.numbers import sig

__all__ = [
    "BENDING_LEVELS_MPA",
    "GEAR_ERROR_LINE_PCT",
    "RULES",
    "STARTS_NORM",
    "Action",
    "CarriedAction",
    "Evidence",
    "carry",
    "drivers",
    "recommend",
]

STARTS_NORM = (3, 5)
"""Supplier norm of starts per month (Diering 2011 §6.1.3, §10.3)."""

BENDING_LEVELS_MPA = (25.0, 43.0, 90.0)
"""Pinion bending amplitude levels, MPa (Diering 2011 §8.1): keep below 25 (experience of
failures), 43 (fatigue reserve factor 2 at rated torque), above 90 failure within weeks."""

GEAR_ERROR_LINE_PCT = 2.0
"""A 3× pinion-speed line this large (% of rated torque, daily median) is worth a look at the
gear mesh. Our level, not a seed's: Fedin & Vinogradov 2018 reproduce the dynamic factor with a
0.2 mm kinematic error and give no torque level; Diering 2011 Table 14 puts whole steady
oscillation ranges at 16–24 % of rated on average."""


@dataclass(frozen=True, slots=True)
class Evidence:
    """What the rules read of one month (None: not measured). Peaks and levels in % of rated
    motor torque, bending amplitude MPa, line amplitude % of rated torque; ``typical_peak_pct``:
    the starter type's field average peak (``typical_peak_source``: its table)."""

    month: str
    monitored_days: float
    starts: int
    trips: int
    starter: str
    start_peaks_pct: Sequence[float]
    peak_warn_pct: float
    bending_amplitude_max_mpa: float | None
    gear_error_line_pct: float | None
    typical_peak_pct: float | None = None
    typical_peak_source: str = ""


@dataclass(frozen=True, slots=True)
class Action:
    """A recommended action: ``rule`` that fired, what to do, the evidence, the source, and
    ``urgent`` (above the level of failure or alarm)."""

    rule: str
    action: str
    evidence: str
    source: str
    urgent: bool = False


@dataclass(frozen=True, slots=True)
class CarriedAction:
    """Last month's action and where it stands: ``done``, ``still open`` or ``not checked``."""

    rule: str
    action: str
    status: str
    evidence_now: str


def _starts(e: Evidence) -> Action | None:
    lo, hi = STARTS_NORM
    if e.starts <= hi:
        return None
    times = f"{sig(e.starts / hi, 2)}–{sig(e.starts / lo, 2)}×"
    return Action(
        "starts",
        "Investigate why the mill stops; record and scrutinise every stop and start; keep "
        "starts to a minimum.",
        f"{e.starts} starts in {e.month}: {times} the norm of {lo}–{hi} a month.",
        "Diering 2011 §6.1.3, §10.3",
    )


HIGH_SHARE = 0.8
"""Share of a month's starts above the starter type's field average that points at the starter
(at least :data:`HIGH_SHARE_MIN_STARTS` starts): half of a healthy starter's starts lie above its
average, 8 of 10 or more by chance about one month in twenty (binomial tail)."""
HIGH_SHARE_MIN_STARTS = 10


def _start_peaks(e: Evidence) -> Action | None:
    n = len(e.start_peaks_pct)
    above = [p for p in e.start_peaks_pct if p > e.peak_warn_pct]
    typical = e.typical_peak_pct
    high = [] if typical is None else [p for p in e.start_peaks_pct if p > typical]
    mostly_high = n >= HIGH_SHARE_MIN_STARTS and len(high) >= HIGH_SHARE * n
    if not above and not mostly_high:
        return None
    said = [f"{len(above)} of {n} starts peaked above the warning level of "
            f"{sig(e.peak_warn_pct)} % of rated torque"]  # fmt: skip
    if typical is not None:
        src = f" ({e.typical_peak_source})" if e.typical_peak_source else ""
        said.append(f"{len(high)} of {n} above the {e.starter} field average of "
                    f"{sig(typical)} %{src}")  # fmt: skip
    said.append(f"highest {sig(max(e.start_peaks_pct))} %")
    if e.trips:
        said.append(f"{e.trips} trip{'s' if e.trips != 1 else ''}")
    evidence = "; ".join(said) + "."
    if e.starter == "Grid":
        return Action("start_peaks", "Replace the Grid starter: not recommended for mills.",
                      evidence, "Diering 2011 §10.2, §10.4")  # fmt: skip
    return Action(
        "start_peaks",
        "Investigate the trips and the starter; check the liquid starter's electrolyte density "
        "with strain-gauge measurements.",
        evidence,
        "Diering 2011 §6.2.1, §7.2, §10.2",
        urgent=len(above) == n and n > 1,
    )


def _bending(e: Evidence) -> Action | None:
    b = e.bending_amplitude_max_mpa
    experience, frf2, weeks = BENDING_LEVELS_MPA
    if b is None or b <= experience:
        return None
    if b > weeks:
        why, urgent = f"above {sig(weeks)} MPa, where failure is predicted within weeks", True
    elif b > frf2:
        why, urgent = f"above {sig(frf2)} MPa (fatigue reserve factor 2 at rated torque)", False
    else:
        why, urgent = f"above the {sig(experience)} MPa that experience says to keep under", False
    return Action(
        "bending",
        "Check the drivetrain alignment; realign the complete drivetrain after any pinion "
        "adjustment, and verify it with bending measurements.",
        f"Steady pinion bending amplitude up to {sig(b)} MPa: {why}.",
        "Diering 2011 §6.2.6, §8.1, §10.1",
        urgent=urgent,
    )


def _gear_error(e: Evidence) -> Action | None:
    a = e.gear_error_line_pct
    if a is None or a < GEAR_ERROR_LINE_PCT:
        return None
    return Action(
        "gear_error",
        "Inspect the pinion and girth gear mesh for kinematic error (tooth profile, runout).",
        f"A line at 3× pinion speed of {sig(a)} % of rated torque "
        f"(level {sig(GEAR_ERROR_LINE_PCT)} %).",
        "Fedin & Vinogradov 2018 eq. 12",
    )


RULES: tuple[Callable[[Evidence], Action | None], ...] = (
    _bending,
    _start_peaks,
    _starts,
    _gear_error,
)
"""The rules, in the order their actions are listed (urgent ones first after sorting)."""


def recommend(e: Evidence) -> list[Action]:
    """The actions this month's evidence calls for, urgent ones first (none for a month
    without monitoring: nothing was seen)."""
    if e.monitored_days <= 0:
        return []
    found = [a for rule in RULES if (a := rule(e)) is not None]
    return sorted(found, key=lambda a: not a.urgent)


def carry(
    previous: Sequence[Action], now: Sequence[Action], monitored_days: float
) -> list[CarriedAction]:
    """Last month's actions against this month: ``still open`` when the rule fires again,
    ``done`` when it does not, ``not checked`` when this month was not monitored."""
    fired = {a.rule: a for a in now}
    out = []
    for a in previous:
        if monitored_days <= 0:
            status, ev = "not checked", "this month was not monitored"
        elif a.rule in fired:
            status, ev = "still open", fired[a.rule].evidence
        else:
            status, ev = "done", "no longer seen this month"
        out.append(CarriedAction(a.rule, a.action, status, ev))
    return out


def drivers(
    per_component: Mapping[str, Mapping[str, float]],
    hours_per_start: Mapping[str, float | None],
    starts: int,
) -> list[str]:
    """What drives the damage, in words: which component, starts and stops against running,
    bending against torsion. ``per_component``: the month's damage by phase per component."""
    totals = {c: sum(p.values()) for c, p in per_component.items()}
    mill = sum(totals.values())
    if mill <= 0:
        return ["No damage counted this month."]
    top = max(totals, key=lambda c: totals[c])
    phases = per_component[top]
    ss = phases.get("start", 0.0) + phases.get("stop", 0.0)
    run = phases.get("run", 0.0)
    out = [f"{top} took the most damage: {sig(100 * totals[top] / mill)} % of the mill's."]
    hours = hours_per_start.get(top)
    cost = f"; one start costs {sig(hours)} hours of steady running" if hours else ""
    if ss >= run:
        out.append(f"Starts and stops drive it: {sig(100 * ss / totals[top])} % of its damage "
                   f"came from the {starts} starts and their stops{cost}.")  # fmt: skip
    else:
        out.append(f"Steady running drives it: {sig(100 * run / totals[top])} % of its damage; "
                   f"starts and stops {sig(100 * ss / totals[top])} %{cost}.")  # fmt: skip
    out += _bending_vs_torsion(totals)
    return out


def _bending_vs_torsion(totals: Mapping[str, float]) -> list[str]:
    """Bending against torsion on each pinion: the combined stress's damage over torsion's."""
    out = []
    for comp, combined in totals.items():
        if not comp.startswith("pinion_combined"):
            continue
        torsion = totals.get(comp.replace("pinion_combined", "pinion_torsion"), 0.0)
        if torsion <= 0:
            continue
        ratio = combined / torsion
        if ratio >= 2:
            out.append(f"Bending drives {comp}: its combined stress (bending and torsion) did "
                       f"{sig(ratio)}× the damage of torsion alone.")  # fmt: skip
        elif ratio <= 0.5:
            out.append(f"Torsion drives {comp}: torsion alone did {sig(1 / ratio)}× the damage "
                       "of the combined stress.")  # fmt: skip
        else:
            out.append(f"Bending and torsion weigh alike on {comp} (ratio {sig(ratio)}).")
    return out
