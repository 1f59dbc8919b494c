"""The monthly damage report's data: plain frozen dataclasses, one per section, and the
report itself (:class:`MonthlyReport`), with :func:`report_to_dict` for JSON.

Built from the store by :mod:`millwatch.reports.monthly.build` (the steady-state and harmonic
sections
by :mod:`millwatch.reports.monthly.trends`); rendered by :mod:`millwatch.reports.monthly_document`.
Units are in each field's docstring or name (``_ns`` UTC nanoseconds, ``_pct`` percent of rated
torque, ``_mpa`` MPa); damage is a Miner sum (dimensionless).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.cycle_matrix import sparse_matrix
from millwatch.reports.actions import Action, CarriedAction
from millwatch.reports.history import MonthTrend
from millwatch.reports.life import LifeReport
from millwatch.reports.month_summary import CumulativeDamage, ReportSummary
from millwatch.reports.plain import finite_or_none, plain

__all__ = [
    "Advice",
    "AlarmEntry",
    "ComponentDamage",
    "CycleSpectrum",
    "DataQuality",
    "DataSource",
    "Harmonics",
    "LineTrend",
    "MonthlyReport",
    "PeakSummary",
    "StartRow",
    "Starts",
    "Steady",
    "SteadyDay",
    "SteadyPoint",
    "WhatIfBasis",
    "WhatIfRow",
    "report_to_dict",
]


@dataclass(frozen=True, slots=True)
class DataSource:
    """Where the numbers come from: the store file and the span of results read."""

    store_path: str
    first_ns: int | None
    last_ns: int | None
    note: str = (
        "times of the first and last stored result (event, steady window, harmonic table) in "
        "the month; raw samples are kept in the MCAP archive, not in the store"
    )


@dataclass(frozen=True, slots=True)
class StartRow:
    """One switch-on: peaks in % of rated motor torque (max over drive sides); ``peak_pct``, the
    start's peak (the larger of switch-on and short-circuit), and its status against the
    start-peak levels (strictly above, as the ``start_peak`` alarm judges it)."""

    t_ns: int
    local_time: str
    failed: bool
    switch_on_pct: float | None
    short_circuit_pct: float | None
    pinion_switch_on_pct: float | None
    rise_10_90_ms: float | None
    accel_s: float | None
    status: str
    peak_pct: float | None = None


@dataclass(frozen=True, slots=True)
class Starts:
    """Starts of the month against the norm (§6.1.3) and the configured levels."""

    count: int
    failed: int
    stops: int
    trips: int
    norm: tuple[int, int]
    warn_above: int
    alarm_above: int
    status: str
    per_day: dict[str, int]
    peak_warn_pct: float
    peak_alarm_pct: float
    starts: list[StartRow]


@dataclass(frozen=True, slots=True)
class ComponentDamage:
    """Damage of one component: per day and phase, per phase, the month's total; the cost of
    a start as Diering 2011 App. D counts it (§8.3; :mod:`millwatch.analytics.mill.app_d`) from the
    start-stop records the month's stops closed (``start_stops`` of them)."""

    component: str
    per_day: dict[str, dict[str, float]]
    per_phase: dict[str, float]
    total: float
    damage_per_start: float | None
    start_stop_seconds: float | None
    run_damage_per_hour: float | None
    hours_of_running_per_start: float | None
    start_stops: int = 0


@dataclass(frozen=True, slots=True)
class CycleSpectrum:
    """The month's rainflow cycles of one component as a range–mean matrix (Fotopoulos 1983
    ch. 3), with what its S-N figure needs. Stresses in MPa as counted, after the stress
    factors (K_t or the fatigue factors the trace carries) and before any mean-stress
    correction; the edges are the mill file's (:mod:`millwatch.analytics.mill.cycle_matrix`), the
    counts
    in half cycles as sparse ``[[cell, half cycles], …]`` of the matrix with its under/overflow
    bins (:meth:`matrix`). ``sn_curve``: the component's curve
    (:meth:`~millwatch.analytics.fatigue.sn_curves.SNCurve.to_dict`); ``goodman_s_ut_mpa``: S_ut of
    its Goodman correction (None without one); ``miner_limit``: the damage taken as failure;
    ``days``: days of the month with a stored matrix."""

    component: str
    range_edges_mpa: list[float]
    mean_edges_mpa: list[float]
    cells: list[list[int]]
    cycles: float
    sn_curve: dict[str, Any]
    goodman_s_ut_mpa: float | None
    miner_limit: float
    days: int

    def matrix(self) -> RangeMeanMatrix:
        """The counts as a :class:`~millwatch.analytics.fatigue.matrices.RangeMeanMatrix` (a
        component with no stored matrix has no edges: check :attr:`cells` first)."""
        return sparse_matrix((self.range_edges_mpa, self.mean_edges_mpa), self.cells)


@dataclass(frozen=True, slots=True)
class WhatIfRow:
    """App. D scenario: starts per 4-week month → damage per month, life from new
    (``life_years``) and remaining life from the damage so far at the month's end
    (``remaining_years``) per component, the mill running ``running_fraction`` of the time
    outside its starts and stops (App. D's scenarios: 1)."""

    scenario: str
    starts_per_month: float
    damage_per_month: dict[str, float | None]
    life_years: dict[str, float | None]
    remaining_years: dict[str, float | None] = field(default_factory=dict)
    running_fraction: float = 1.0


@dataclass(frozen=True, slots=True)
class WhatIfBasis:
    """What the what-if table rests on, printed beside it: the start-stop records and run
    portions it was measured on, the month of 4 weeks, the measured rate and fraction."""

    method: str
    start_stops: int
    run_hours: float
    month_days: float
    measured_starts_per_month: float | None
    measured_running_fraction: float | None
    assumptions: list[str]


@dataclass(frozen=True, slots=True)
class SteadyPoint:
    """One steady-state window: oscillation range (% rated) and bending amplitude (MPa)."""

    t_ns: int
    range_pct: dict[str, float]
    bending_amplitude_mpa: dict[str, float]

    def __plain__(self) -> dict[str, Any]:
        return {"t_ns": self.t_ns, "range_pct": finite_or_none(self.range_pct),
                "bending_amplitude_mpa": finite_or_none(self.bending_amplitude_mpa)}  # fmt: skip


@dataclass(frozen=True, slots=True)
class SteadyDay:
    """Daily summary of the steady windows: mean and max per quantity and channel."""

    day: str
    windows: int
    range_pct_mean: dict[str, float]
    range_pct_max: dict[str, float]
    bending_amplitude_mean: dict[str, float]
    bending_amplitude_max: dict[str, float]


@dataclass(frozen=True, slots=True)
class Steady:
    """Steady-state trends with the configured levels (Tables 14–15, §8.1)."""

    windows: int
    points: list[SteadyPoint]
    days: list[SteadyDay]
    oscillation_warn_pct: float
    oscillation_alarm_pct: float
    bending_warn_mpa: float
    bending_alarm_mpa: float
    bending_critical_mpa: float


@dataclass(frozen=True, slots=True)
class LineTrend:
    """Daily median amplitude (% rated torque, or the channel's unit) of one detected line."""

    channel: str
    line: str
    expected_hz: float | None
    unit: str
    per_day: dict[str, float]


@dataclass(frozen=True, slots=True)
class PeakSummary:
    """An unexplained spectral peak (possible torsional resonance, §6.2.7), grouped by channel
    and 0.1 Hz; ``windows``: harmonic tables it was seen in."""

    channel: str
    frequency_hz: float
    windows: int
    max_amplitude: float
    unit: str
    max_amplitude_pct: float | None
    first_ns: int
    last_ns: int
    nearest_line: str | None
    nearest_natural_hz: float | None


@dataclass(frozen=True, slots=True)
class Harmonics:
    tables: int
    tables_sampled: int
    lines: list[LineTrend]
    peaks: list[PeakSummary]


@dataclass(frozen=True, slots=True)
class AlarmEntry:
    """An alarm active at some time in the month."""

    rule: str
    subject: str
    severity: str
    state: str
    raised_ns: int
    cleared_ns: int | None
    value: float | None
    threshold: float | None
    unit: str
    message: str


@dataclass(frozen=True, slots=True)
class DataQuality:
    """Data-quality events of the month (telemetry gaps, stale channels, …, §5.2.2)."""

    events: int
    by_problem: dict[str, int]
    by_channel: dict[str, int]
    first: list[dict[str, Any]]


@dataclass(frozen=True, slots=True)
class Advice:
    """Page 1's words (:mod:`millwatch.reports.actions`): what drives the damage (``drivers``,
    sentences), this month's recommended ``actions`` with their evidence and source, and last
    month's (``previous_month``) carried with their status (done, still open, not checked)."""

    drivers: list[str]
    actions: list[Action]
    previous_month: str
    carried: list[CarriedAction]


@dataclass(frozen=True, slots=True)
class MonthlyReport:
    """The monthly damage report (JSON via :func:`report_to_dict`)."""

    mill: str
    site: str
    time_zone: str
    month: str
    start_ns: int
    end_ns: int
    generated_ns: int
    source: DataSource
    rated_torque_knm: dict[str, float]
    design_life_years: float
    starts: Starts
    phase_seconds: dict[str, float]
    damage: list[ComponentDamage]
    what_if: list[WhatIfRow]
    steady: Steady
    harmonics: Harmonics
    alarms: list[AlarmEntry]
    data_quality: DataQuality
    simulated: bool
    summary: ReportSummary
    life: LifeReport
    cumulative: CumulativeDamage
    trend: list[MonthTrend]
    notes: list[str] = field(default_factory=list)
    what_if_basis: WhatIfBasis | None = None
    advice: Advice | None = None
    spectra: list[CycleSpectrum] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        """Nothing stored for the month."""
        return self.source.first_ns is None


def report_to_dict(report: MonthlyReport) -> dict[str, Any]:
    """JSON-ready plain data in field order, as :func:`dataclasses.asdict` would give but
    without its deep copies (a month holds tens of thousands of steady windows); non-finite
    floats become None, tuples lists."""
    out: dict[str, Any] = plain(report)
    return out | {"empty": report.empty}
