"""Alarm rules from the field evidence, one per observed quantity, configured per mill.

A :class:`Rule` says when a quantity (:data:`millwatch.alarms.observations.QUANTITIES`) is abnormal
— one
threshold per severity, compared *strictly* (``>`` for ``above`` rules, ``<`` for ``below``) — how
it returns to normal, and what to tell the control room. :func:`build_rules` makes the rule book
of one mill from ``MillConfig.alarms`` — the ``[alarms]`` section of the mill file: Diering 2011's
thresholds and the knobs the sources say nothing about (deadbands, delays, data-quality limits,
resonance margin, life fractions, load-sharing limits), each a named, validated field.

Lifecycle knobs (:mod:`millwatch.alarms.engine` applies them):

* level rules: ``raise_delay_s`` — the value must stay beyond a level that long (on the
  observation clock) before the alarm is raised or escalated to it; ``clear_delay_s`` — it must
  stay at or inside the clear level (least severe threshold ∓ ``deadband``) that long before the
  condition returns to normal. A value hovering inside the deadband changes nothing.
* event rules: raise at once; the condition returns to normal after ``clean_events_to_clear``
  consecutive clean events (at or inside the clear level), after ``quiet_s_to_clear`` seconds
  without a recurrence (once acknowledged: ``acked_quiet_s_to_clear``), or — with
  ``clear_on_ack`` — when acknowledged.
* ``latched``: a condition that returns to normal before anyone acknowledged it keeps the alarm
  raised until acknowledged (the control room must see that it happened).

Rules and their defaults (fields of ``MillConfig.alarms``; *option*: not a source value).
Every alarm carries two texts (ISA-18.2 rationalisation; README "Alarms" is the master alarm
database):

* ``message`` — at most :data:`MESSAGE_MAX` characters as served (the ``SIMULATED DATA: ``
  prefix included), for a control-room list: what, the value against its limit (within the
  first 100 characters), where, the time of that value (site zone with its offset,
  :func:`millwatch.alarms.times.iso_local`), and one action. No document citations.
* ``advice`` — why it matters, what to check and the source (author and section), in plain
  words; the start-peak advice is the mill's starter's (:data:`START_ADVICE`).

=========================== ===================================== ====================== =======
rule                        levels                                clears                 source
=========================== ===================================== ====================== =======
start_peak (event)          starter type's mean + 2 / + 3         1 clean start, or 12 h Tab. 3–11,
                            std. dev., capped at the shaft's      after it once acked    §8.2
                            limit (E-LRS 131/151 %, LRS 310/348
                            %, Grid 1207/1539 %)
starts_per_month (level)    warning > 5, alarm > 20               on ack (then quiet at  §6.1.3,
                                                                  that level); latched   §6.2.8
oscillation_range (level)   warning > 25 %, alarm > 45 %          ≤ 23 % for 5 min       Tab. 14–15
bending_amplitude (level)   warning > 25, alarm > 43,             ≤ 23 MPa for 5 min     §8.1
                            critical > 90 MPa
barring_peak (event)        alarm > 185 % single / 314 % dual     1 clean session or ack Tab. 12–13
unexplained_peak (event)    warning on any reported peak          1 h without recurrence §6.2.7
resonance_margin (level)    warning < 10 % (*option*)             ≥ 12 % for 5 min       Fedin &
Vinogradov 2018
natural_frequency_shift     warning > 10 %, alarm > 20 % of the   1 clean start          §6.1.1,
(event)                     model's natural frequency (*option*)                         Fedin &
                                                                                         Vinogradov
remaining_life (level)      warning < 1.0×, alarm < 0.5× the      ≥ 1.05× for 5 min      §8.3
                            remaining design life (*option*)
stale_channel (level)       warning > 10 s (*option*)             data again             §5.1
spike_rate (level)          warning > 6/min (*option*)            ≤ 3/min for 5 min      §5.2.2
sequence_gaps (event)       warning > 0 blocks lost (*option*)    5 min without; latched §5.1
implausible_blocks (event)  warning > 0 (*option*)                5 min without; latched §5.1
archive_write_failures      alarm > 0 (*option*)                  3 clean reports;       DESIGN
(event)                                                           latched
store_write_failures        warning > 0 (*option*)                3 clean reports;       DESIGN
(event)                                                           latched
analysis_lag (level)        warning > 120 s (*option*)            ≤ 60 s                 §10.6
load_sharing (level)        warning > 25 %, alarm > 35 %          ≤ 23 % for 5 min       §6.2.2
                            (*option*)
report_delivery (event)     alarm > 0 failed attempts             1 delivery; latched    §10.6
=========================== ===================================== ====================== =======

Event rules re-annunciate: every offending event while the alarm is open updates the same
alarm (:mod:`millwatch.alarms.engine`).

Severity never steps down while an alarm is open: an alarm that reached ``alarm`` stays an
``alarm`` until it clears (stepping down would chatter between levels; the transitions keep the
history).
"""

from __future__ import annotations

import string
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Literal

from millwatch.alarms.observations import QUANTITIES, Kind, Observation, local_month
from millwatch.alarms.times import iso_local
from millwatch.analytics.drivetrain.mill_config import MillConfig, Starter
from millwatch.analytics.drivetrain.start_limits import K_ALARM, K_WARNING

__all__ = ["MESSAGE_MAX", "Level", "Rule", "RuleBook", "Severity", "build_rules"]

MESSAGE_MAX = 200
"""Longest ``message`` as served, characters (issue 27: a control-room list shows it whole)."""


class Severity(StrEnum):
    """Alarm severities, least severe first."""

    WARNING = "warning"
    ALARM = "alarm"
    CRITICAL = "critical"

    @property
    def rank(self) -> int:
        return _RANK[self]


_RANK = {Severity.WARNING: 0, Severity.ALARM: 1, Severity.CRITICAL: 2}


@dataclass(frozen=True, slots=True)
class Level:
    """One severity of a rule: beyond ``threshold`` (strictly) it applies; ``action`` and
    ``advice`` override the rule's at this severity."""

    severity: Severity
    threshold: float
    action: str | None = None
    advice: str | None = None


class _Defaults(dict[str, Any]):
    """``str.format_map`` mapping: context keys missing from an observation (or None) show as
    ``?``."""

    def __missing__(self, key: str) -> str:
        return "?"


_SIGN = {"above": ">", "below": "<"}


@dataclass(frozen=True, slots=True)
class Rule:
    """One alarm rule; see the module docstring for the lifecycle knobs.

    ``headline`` is a ``str.format`` template over ``value`` (formatted with ``value_format``),
    ``limit`` (" (<severity> > <limit>)", right after the value), ``subject``, ``where``
    (" on <subject>" or "") and the observation's context (a None value counts as missing):
    what, the value against its limit and where, first; the message adds the time and
    ``action`` (one short imperative). ``advice``: the reasoning in plain words, a template
    over the same fields; ``source``: where the set points come from (author and section), put
    after the advice, never in the message. ``clauses``: ``(name, template, fallback)`` —
    ``{name}`` is ``template`` formatted when the context holds every field it names (not None),
    else ``fallback``, so an optional fact never reads "None Hz" or "? Hz"; ``criterion``
    replaces the generated "<severity> > <limit>" when the threshold itself means nothing to a
    reader. ``scale_key``: thresholds and deadband are multiplied by ``context[scale_key]``
    (default ``default_scale``).
    """

    name: str
    quantity: str
    levels: tuple[Level, ...]
    headline: str
    action: str
    advice: str
    source: str
    value_format: str
    direction: Literal["above", "below"] = "above"
    deadband: float = 0.0
    raise_delay_s: float = 0.0
    clear_delay_s: float = 0.0
    clean_events_to_clear: int | None = None
    quiet_s_to_clear: float | None = None
    acked_quiet_s_to_clear: float | None = None
    clear_on_ack: bool = False
    latched: bool = False
    criterion: str | None = None
    clauses: tuple[tuple[str, str, str], ...] = ()
    scale_key: str | None = None
    default_scale: float = 1.0

    @property
    def kind(self) -> Kind:
        return QUANTITIES[self.quantity].kind

    @property
    def unit(self) -> str:
        return QUANTITIES[self.quantity].unit

    def scale(self, obs: Observation) -> float:
        if self.scale_key is None:
            return 1.0
        value = obs.context.get(self.scale_key)
        return float(self.default_scale if value is None else value)

    def threshold(self, severity: Severity, obs: Observation) -> float:
        """The threshold of ``severity`` for this observation (scaled)."""
        return self.level(severity).threshold * self.scale(obs)

    def level(self, severity: Severity) -> Level:
        return next(lv for lv in self.levels if lv.severity == severity)

    def beyond(self, value: float, threshold: float) -> bool:
        return value > threshold if self.direction == "above" else value < threshold

    def exceeded(self, obs: Observation) -> list[Severity]:
        """Severities whose threshold ``obs.value`` is strictly beyond, least severe first."""
        k = self.scale(obs)
        return [lv.severity for lv in self.levels if self.beyond(obs.value, lv.threshold * k)]

    def clear_level(self, obs: Observation) -> float:
        """The least severe threshold pulled back by the deadband (hysteresis)."""
        k = self.scale(obs)
        sign = -1.0 if self.direction == "above" else 1.0
        return (self.levels[0].threshold + sign * self.deadband) * k

    def is_normal(self, obs: Observation) -> bool:
        """At or inside the clear level: counts towards returning to normal."""
        limit = self.clear_level(obs)
        return obs.value <= limit if self.direction == "above" else obs.value >= limit

    def fmt(self, value: float) -> str:
        return self.value_format.format(value)

    def _fields(self, obs: Observation, time_zone: str) -> _Defaults:
        fields = _Defaults({k: _short(v) for k, v in obs.context.items() if v is not None})
        subject = obs.subject
        fields.setdefault("month", local_month(obs.t_ns, time_zone))
        fields.update(
            time=iso_local(obs.t_ns, time_zone),
            value=self.fmt(obs.value),
            subject=subject or "the mill",
            where=f" on {subject}" if subject else "",
        )
        for name, template, fallback in self.clauses:
            needed = [f for _, f, _, _ in string.Formatter().parse(template) if f]
            known = all(f in fields for f in needed)
            fields[name] = template.format_map(fields) if known else fallback
        return fields

    def message(
        self, obs: Observation, severity: Severity, time_zone: str, raised_ns: int | None = None
    ) -> str:
        """The control-room sentence: what, value against limit, where, when, one action
        (module docstring; at most :data:`MESSAGE_MAX` characters with the simulated-data
        prefix). ``time`` is ``obs``'s (the value that raised, escalated or re-annunciated the
        alarm); ``raised_ns`` is accepted for the callers and not repeated (the alarm's
        ``raised_ns`` field holds it)."""
        fields = self._fields(obs, time_zone)
        criterion = self.criterion or (
            f"{severity} {_SIGN[self.direction]} {self.fmt(self.threshold(severity, obs))}"
        )
        fields["limit"] = f" ({criterion})"
        headline = self.headline.format_map(fields)
        action = self.level(severity).action or self.action
        return f"{headline} at {fields['time']}: {action}"

    def advice_for(self, obs: Observation, severity: Severity, time_zone: str = "UTC") -> str:
        """Why it matters and what to check, then the source (author and section)."""
        text = (self.level(severity).advice or self.advice).format_map(self._fields(obs, time_zone))
        return f"{text}. Source: {self.source}."


def _short(value: Any) -> Any:
    """Context numbers in messages: four significant digits."""
    return f"{value:.4g}" if isinstance(value, float) else value


@dataclass(frozen=True, slots=True)
class RuleBook:
    """The rules of one mill, by quantity, with the site's time zone for messages;
    ``simulated``: the mill's data come from the simulator (its alarms say so)."""

    mill_id: str
    time_zone: str
    rules: Mapping[str, Rule]
    simulated: bool = False

    def rule(self, name: str) -> Rule:
        """The rule called ``name`` (KeyError if none)."""
        for rule in self.rules.values():
            if rule.name == name:
                return rule
        raise KeyError(name)


def _levels(*pairs: tuple[Severity, float]) -> tuple[Level, ...]:
    return tuple(Level(sev, thr) for sev, thr in pairs)


#: Start-peak texts per starter: short name for the message, and the advice (Diering 2011
#: §6.2.1–6.2.2, Tables 3–11: peak switch-on / short-circuit torque, % of motor rated torque;
#: §10.2 starter maintenance; §10.4 "Grid type starters [should] not [be] used for mill
#: applications").
START_ADVICE = {
    Starter.GRID: (
        "Grid",
        "A fixed grid resistor (Grid) starter puts very high peaks into the drivetrain: on "
        "average 542 % of rated torque at switch-on and 324 % at short circuit, twice an LRS. "
        "Diering recommends not using Grid starters on mills: plan the change to an LRS or "
        "E-LRS starter and keep the number of starts low until then",
    ),
    Starter.LRS: (
        "LRS",
        "A liquid resistance starter (LRS) normally peaks at about 233 % of rated torque at "
        "switch-on and 197 % at short circuit. A start well above that points to the starter: "
        "check the electrolyte density (verify with the strain gauges) and the start sequence",
    ),
    Starter.E_LRS: (
        "E-LRS",
        "An enhanced liquid resistance starter (E-LRS) normally peaks at only about 92 % of "
        "rated torque at switch-on and 119 % at short circuit. A peak this high means the "
        "starter is not working as designed: check its control, the electrolyte and the start "
        "sequence",
    ),
}


def _start_peak(config: MillConfig) -> Rule:
    """Start peak torque, % of motor rated torque, against the mill's starter type's set points
    (:meth:`MillConfig.start_peak_limits`: mean + 2 / + 3 standard deviations of Diering 2011
    Tables 3–11, capped at the motor shaft's absolute limit). Event; re-annunciates on every
    exceeding start; clears after ``clean_starts_to_clear`` clean starts (default 1), or, once
    acknowledged, ``start_peak_hold_s`` (12 h) after its last exceeding start: a mill left
    stopped after a bad start would otherwise keep a seen alarm standing for days (EEMUA 191
    stale alarms)."""
    a = config.alarms
    limits = config.start_peak_limits()
    starter, advice = START_ADVICE[config.drive.starter]
    levels = ((Severity.WARNING, limits.warning),) if limits.warning is not None else ()
    how = (
        f" The limits are this starter's normal peaks plus {K_WARNING:g} (warning) and "
        f"{K_ALARM:g} (alarm) standard deviations, at most {limits.shaft_limit:.0f} % (the torque "
        "the motor shaft stands fewer than 1,000 times, Diering 2011 §8.2)"
    )
    return Rule(
        "start_peak", "start_peak_pct",
        _levels(*levels, (Severity.ALARM, limits.alarm)),
        headline=f"Start peak {{value}}{{limit}}{{shaft}}, {starter} starter",
        clauses=(("shaft", " on the {side} motor shaft", " on the motor shaft"),),
        action="check the starter before the next start",
        advice=advice + "." + how,
        source=f"{limits.source} (§6.2.1–6.2.2), §8.2, §10.2, §10.4",
        value_format="{:.0f} %",
        deadband=a.start_peak_deadband_pct, clean_events_to_clear=a.clean_starts_to_clear,
        acked_quiet_s_to_clear=a.start_peak_hold_s,
    )  # fmt: skip


def _starts_per_month(config: MillConfig) -> Rule:
    """Starts in the local calendar month (Diering 2011 §6.1.3 supplier norm 3–5, §6.2.8 field
    average 20–22, §10.3 "recorded and scrutinized"). Level without delays (a count does not
    chatter); latched: a busy month must be acknowledged even after the count resets; clears
    on acknowledgement and stays quiet at that level for the rest of the month (a count stays
    high until the month ends: an alarm standing for weeks would be a stale alarm)."""
    a = config.alarms
    return Rule(
        "starts_per_month", "starts_this_month",
        _levels((Severity.WARNING, a.starts_per_month_warn),
                (Severity.ALARM, a.starts_per_month_alarm)),
        headline="{value} starts in the calendar month {month}{limit}",
        action="review why the mill stopped each time",
        advice="Every start loads the drivetrain with start-up peaks and adds fatigue damage. "
        "Suppliers expect 3 to 5 starts a month; the measured mills averaged 20 to 22. Record "
        "and scrutinize every stop",
        source="Diering 2011 §6.1.3, §6.2.8, §10.3", value_format="{:.0f}", latched=True,
        clear_on_ack=True,
    )  # fmt: skip


def _oscillation(config: MillConfig) -> Rule:
    """Steady-state torque oscillation range, % of motor rated torque (Diering 2011 Tables 14–15:
    23.6 % average, 45.4 % max on single-drive motor shafts; §7.4, §10.5)."""
    a = config.alarms
    return Rule(
        "oscillation_range", "oscillation_range_pct",
        _levels((Severity.WARNING, a.oscillation_range_warn_pct),
                (Severity.ALARM, a.oscillation_range_alarm_pct)),
        headline="Torque oscillation range {value} of rated{limit}{where}",
        action="check the spectrum and gear wear",
        advice="The running torque swings more than on the measured mills (23.6 % average, "
        "45.4 % the highest). Look at the spectrum for the line that grew (gear mesh, liner "
        "passing, pinion speed) and inspect the gears for wear",
        source="Diering 2011 §6.2.4, Tables 14–15, §10.5", value_format="{:.0f} %",
        deadband=a.oscillation_deadband_pct, raise_delay_s=a.raise_delay_s,
        clear_delay_s=a.clear_delay_s,
    )  # fmt: skip


def _bending(config: MillConfig) -> Rule:
    """Pinion-shaft bending stress amplitude, MPa (Diering 2011 §8.1: < 25 MPa by experience, 43 MPa
    for a fatigue reserve factor of 2, > 90 MPa fails within weeks; §10.1 alignment)."""
    a = config.alarms
    levels = (
        Level(Severity.WARNING, a.bending_amplitude_warn_mpa),
        Level(Severity.ALARM, a.bending_amplitude_alarm_mpa),
        Level(Severity.CRITICAL, a.bending_amplitude_critical_mpa,
              "realign the drivetrain now",
              "At this bending amplitude pinion shafts have failed within weeks. Realign the "
              "whole drivetrain now (bearings, gear, foundation)"),
    )  # fmt: skip
    return Rule(
        "bending_amplitude", "bending_amplitude_mpa", levels,
        headline="Pinion bending amplitude {value}{limit}{where}",
        action="check the drivetrain alignment",
        advice="Bending fatigue of the pinion shaft depends on this amplitude: experience says "
        "keep it below 25 MPa, 43 MPa leaves a fatigue reserve factor of 2, above 90 MPa shafts "
        "fail within weeks. Check the alignment of the whole drivetrain (bearing and gear wear, "
        "foundation)",
        source="Diering 2011 §8.1, §10.1", value_format="{:.1f} MPa",
        deadband=a.bending_deadband_mpa, raise_delay_s=a.raise_delay_s,
        clear_delay_s=a.clear_delay_s,
    )  # fmt: skip


def _barring(config: MillConfig) -> Rule:
    """Barring peak torque above the drive's limit (Diering 2011 §6.2.3, Tables 12–13: 185 % single,
    314 % dual). Event; clears after one clean barring session or on acknowledgement."""
    a = config.alarms
    return Rule(
        "barring_peak", "barring_peak_pct",
        _levels((Severity.ALARM, config.barring_peak_limit_pct)),
        headline="Barring peak {value} of rated{limit}{where}",
        action="loosen the charge before a full start",
        advice="Barring needed more torque than the highest measured on such drives (185 % "
        "single drive, 314 % dual drive): the charge may have set during a long stop. Loosen it "
        "before a full start",
        source="Diering 2011 §6.2.3, Tables 12–13", value_format="{:.0f} %",
        deadband=a.barring_deadband_pct, clean_events_to_clear=1, clear_on_ack=True,
    )  # fmt: skip


def _unexplained_peak(config: MillConfig) -> Rule:
    """A spectral peak matching no expected excitation (Diering 2011 §6.2.7, Figure 36: 10–15 Hz
    peaks pointing to torsional resonance). Event: every reported peak offends (the harmonic
    tracker already applied its SNR and amplitude gates); clears after a quiet hour."""
    a = config.alarms
    return Rule(
        "unexplained_peak", "unexplained_peak_hz", _levels((Severity.WARNING, 0.0)),
        headline="Unexplained peak {value}{limit}{where}{natural}",
        clauses=(("natural", ", natural {nearest_natural_hz} Hz", ""),
                 ("model", "The nearest natural frequency of the drivetrain model is "
                  "{nearest_natural_hz} Hz", "The mill file has no torsional model to compare "
                  "it with")),
        action="compare with the drivetrain model",
        advice="A peak in the torque spectrum that no drivetrain speed or gear mesh explains "
        "can be a torsional resonance (peaks at 10 to 15 Hz on measured mills). {model}; "
        "inspect the drivetrain",
        source="Diering 2011 §6.2.7, Fedin & Vinogradov 2018", value_format="{:.2f} Hz",
        criterion="warning: no known excitation",
        quiet_s_to_clear=a.unexplained_peak_quiet_s,
    )  # fmt: skip


def _resonance(config: MillConfig) -> Rule:
    """Excitation close to a torsional natural frequency (Fedin & Vinogradov 2018 torsional model;
    Diering 2011 §6.1.1 resonance near 90 % speed during acceleration). Level, lower is worse."""
    a = config.alarms
    return Rule(
        "resonance_margin", "resonance_margin",
        _levels((Severity.WARNING, a.resonance_margin_warn)),
        headline="Resonance margin {value}{limit}{where}{pair}",
        clauses=(("pair", " ({line} {frequency_hz} Hz, natural {natural_hz} Hz)", ""),),
        action="review the mill speed",
        advice="An excitation runs close to a torsional natural frequency of the drivetrain, "
        "which amplifies the torque oscillations. Review the mill speed and the drivetrain model",
        source="Fedin & Vinogradov 2018, Diering 2011 §6.1.1", value_format="{:.1%}",
        direction="below",
        deadband=a.resonance_margin_deadband, raise_delay_s=a.raise_delay_s,
        clear_delay_s=a.clear_delay_s,
    )  # fmt: skip


def _natural_frequency(config: MillConfig) -> Rule:
    """The torsional resonance crossed on a run-up (Diering 2011 §6.1.1) away from the
    drivetrain model's natural frequency (Fedin & Vinogradov 2018), % of it. The baseline is the
    model, not the mill's recent starts: a fixed baseline sees a slow loss of stiffness (coupling
    wear) as well as a step, where a rolling median of recent starts follows a slow drift and
    never alarms; a model that was off from the start shows as a shift on every start, which
    the advice names. Event; clears after ``clean_starts_to_clear`` clean starts."""
    a = config.alarms
    return Rule(
        "natural_frequency_shift", "natural_frequency_shift_pct",
        _levels((Severity.WARNING, a.natural_frequency_shift_warn_pct),
                (Severity.ALARM, a.natural_frequency_shift_alarm_pct)),
        headline="Natural frequency shift {value}{limit}{pair}{where}",
        clauses=(("pair", " ({resonance_hz} Hz vs model {natural_hz} Hz)", ""),),
        action="check coupling, shafts and gear mounting",
        advice="The torsional resonance crossed on this run-up lies {value} from the drivetrain "
        "model's natural frequency. A natural frequency moves with stiffness (a 10 % lower "
        "frequency is a fifth less stiffness): a worn or failed coupling element, a cracked "
        "shaft, loose gear or foundation bolts. If every start since the first shows the shift, "
        "the model (the mill file's [torsional] table) is off, not the drivetrain: correct it",
        source="Diering 2011 §6.1.1, Fedin & Vinogradov 2018 (limits: engineering defaults)",
        value_format="{:.1f} %",
        deadband=a.natural_frequency_shift_deadband_pct,
        clean_events_to_clear=a.clean_starts_to_clear,
    )  # fmt: skip


def _remaining_life(config: MillConfig) -> Rule:
    """Projected remaining life shorter than the remaining design life (Diering 2011 §8.2–8.3:
    bending range, start transients and start count drive damage). Level, lower is worse;
    thresholds are fractions of ``context['remaining_design_life_years']`` (default: the
    mill's ``design_life_years``)."""
    a = config.alarms
    return Rule(
        "remaining_life", "remaining_life_years",
        _levels((Severity.WARNING, a.life_warn_fraction), (Severity.ALARM, a.life_alarm_fraction)),
        headline="Remaining life {value}{limit} for {subject}",
        action="review the damage report",
        advice="At the current damage rate this component wears out before its design life "
        "ends. Bending range (alignment), start peaks and the number of starts drive the "
        "damage: the damage report shows which",
        source="Diering 2011 §8.2–8.3", value_format="{:.1f} years", direction="below",
        deadband=a.life_deadband_fraction, raise_delay_s=a.raise_delay_s,
        clear_delay_s=a.clear_delay_s, scale_key="remaining_design_life_years",
        default_scale=config.design_life_years,
    )  # fmt: skip


def _stale(config: MillConfig) -> Rule:
    """No data from a channel (Diering 2011 §5.1: telemetry links drop out). The value is already a
    duration, so no delays; clears as soon as data flows again."""
    a = config.alarms
    return Rule(
        "stale_channel", "stale_channel", _levels((Severity.WARNING, a.stale_after_s)),
        headline="No data{where} for {value}{limit}",
        action="check transmitter, gateway and network",
        advice="The channel sends nothing: the rotating telemetry transmitter, the gateway or "
        "the network link dropped out. Nothing is analysed for it until data flow again",
        source="Diering 2011 §5.1", value_format="{:.0f} s", deadband=a.stale_after_s * 0.5,
    )  # fmt: skip


def _spike_rate(config: MillConfig) -> Rule:
    """Telemetry interference spikes per minute (Diering 2011 §5.2.2: two-way radios and phones)."""
    a = config.alarms
    return Rule(
        "spike_rate", "spike_rate", _levels((Severity.WARNING, a.spike_rate_warn_per_min)),
        headline="Telemetry spikes {value}{limit}{where}",
        action="check the antenna and radios nearby",
        advice="Radio interference (two-way radios, phones) puts spikes into the telemetry. "
        "Flagged samples are left out of the analysis; check the telemetry antenna and radio "
        "sources near the mill",
        source="Diering 2011 §5.2.2", value_format="{:.1f} per minute",
        deadband=a.spike_rate_deadband_per_min, raise_delay_s=a.raise_delay_s,
        clear_delay_s=a.clear_delay_s,
    )  # fmt: skip


def _sequence_gaps(config: MillConfig) -> Rule:
    """Blocks of a channel lost for good (Diering 2011 §5.1 telemetry path; the wire format's
    sequence numbers): an event per unrecoverable loss, raised at the first one with its
    count (gaps the gateways' caches or spools fill are no loss). Latched: the data is gone,
    someone must see it; the condition clears after ``data_quality_quiet_s`` without a loss."""
    a = config.alarms
    return Rule(
        "sequence_gaps", "sequence_gaps", _levels((Severity.WARNING, a.sequence_gaps_warn_blocks)),
        headline="Data lost: {value}{seqs}{limit}{where}",
        action="check the gateway, its spool and its network",
        advice="Blocks of samples never arrived and no cache or spool of the gateway held them: "
        "the gateway was down when they fell due, or its spool's retention had dropped them "
        "(the mill's data-quality event of the span says which, and how many)",
        source="Diering 2011 §5.1", value_format="{:.0f} blocks",
        criterion="warning: any loss", clauses=(("seqs", " (seq {first_seq}–{last_seq})", ""),),
        quiet_s_to_clear=a.data_quality_quiet_s, latched=True,
    )  # fmt: skip


def _implausible(config: MillConfig) -> Rule:
    """Blocks dropped as implausible at admission (README "Admission"): a forged or broken
    sender on the mill's keys. Event, latched; clears after ``data_quality_quiet_s`` without
    one."""
    a = config.alarms
    return Rule(
        "implausible_blocks", "implausible_blocks", _levels((Severity.WARNING, 0.0)),
        headline="Implausible data dropped: {value}{limit} ({reason}){where}",
        action="check the gateway's clock and who may publish",
        advice="A sender on this mill's keys publishes sequence numbers or times that the "
        "channel's history and the clock rule out; the blocks are archived as evidence and not "
        "analysed. Check the gateway's clock and configuration, and who may publish on the "
        "mill's keys (zenoh access control, README Security)",
        source="Diering 2011 §5.1", value_format="{:.0f} blocks",
        criterion="warning: any",
        quiet_s_to_clear=a.data_quality_quiet_s, latched=True,
    )  # fmt: skip


def _archive(config: MillConfig) -> Rule:
    """Archive writes failing: raw data is being lost (the archive is the log; Diering 2011 §10.6
    long-term trending needs it). Event, latched; clears after clean reports."""
    a = config.alarms
    return Rule(
        "archive_write_failures", "archive_write_failures", _levels((Severity.ALARM, 0.0)),
        headline="Archive writes failed: {value}{limit}",
        action="check the archive disk",
        advice="Raw telemetry is not being archived, so it is lost for long-term trending and "
        "re-analysis. Check the archive disk (space, permissions, health)",
        source="Diering 2011 §10.6", value_format="{:.0f}",
        clean_events_to_clear=a.archive_clean_reports_to_clear, latched=True,
    )  # fmt: skip


def _store(config: MillConfig) -> Rule:
    """Store writes failing (a full disk, the file gone): nothing is lost while the process
    runs — results wait in memory and are stored once it can be written, and the archive
    rebuilds them after a restart — but no checkpoint is written meanwhile, so a warning. The
    alarm itself is stored (and published) once the store takes writes again; ``/ready`` and
    ``millwatch_write_failing`` tell it live. Event, latched; clears after clean reports (as
    ``archive_write_failures``: ``archive_clean_reports_to_clear``)."""
    a = config.alarms
    return Rule(
        "store_write_failures", "store_write_failures", _levels((Severity.WARNING, 0.0)),
        headline="Store writes failed: {value}{limit}",
        action="check the store's disk and file",
        advice="Results and alarm transitions wait in memory and are stored in order once the "
        "store can be written again; no checkpoint is written meanwhile. Check the store's disk "
        "(space, permissions) and that its file is in place",
        source="Diering 2011 §10.6", value_format="{:.0f} store writes",
        clean_events_to_clear=a.archive_clean_reports_to_clear, latched=True,
    )  # fmt: skip


def _analysis_lag(config: MillConfig) -> Rule:
    """The analysis behind the archive (a burst, a CPU spike, a backlog): nothing is lost — the
    blocks are archived and read back — but results and alarms come late. The value is already
    a duration, so no delays; clears once the lag is back under half the threshold."""
    a = config.alarms
    return Rule(
        "analysis_lag", "analysis_lag", _levels((Severity.WARNING, a.analysis_lag_warn_s)),
        headline="Analysis {value} behind the data{limit}",
        action="give the worker more CPU",
        advice="Results and alarms come late; nothing is lost (every block is archived). If "
        "the lag keeps growing the worker is short of CPU: give it more, or move mills to "
        "another worker",
        source="Diering 2011 §10.6", value_format="{:.0f} s",
        deadband=a.analysis_lag_warn_s * 0.5,
    )  # fmt: skip


def _report_delivery(config: MillConfig) -> Rule:
    """A monthly report that could not be made or mailed after its retries (Diering 2011 §10.6:
    reports "automatically generated and distributed to site management"). Event per stage
    (files, mail), latched: the site must see it even once a later attempt succeeded."""
    return Rule(
        "report_delivery", "report_failures", _levels((Severity.ALARM, 0.0)),
        headline="Monthly report {month}: {stage} failed after {value}{limit}",
        action="fix the cause, then run 'millwatch report'",
        advice="The report did not reach site management: {error}. Fix the cause (reports "
        "directory: space, permissions; mail: SMTP host, credentials, recipients); the service "
        "tries again, or run 'millwatch report'",
        source="Diering 2011 §10.6", value_format="{:.0f} attempts",
        criterion="alarm: not delivered",
        clean_events_to_clear=1, latched=True,
    )  # fmt: skip


def _load_sharing(config: MillConfig) -> Rule:
    """Dual-drive load-sharing imbalance between barring and non-barring sides (Diering 2011 §6.2.2,
    Table 15 compares the sides; the limits are engineering defaults, not source values)."""
    a = config.alarms
    return Rule(
        "load_sharing", "load_sharing_imbalance_pct",
        _levels((Severity.WARNING, a.imbalance_warn_pct), (Severity.ALARM, a.imbalance_alarm_pct)),
        headline="Load-sharing imbalance {value}{limit} between the drives",
        action="check load-sharing control and pinions",
        advice="One motor carries more of the load than the other, which overloads its side. "
        "Check the drives' load-sharing control and the pinion alignment of both sides",
        source="Diering 2011 §6.2.2, Tables 7–8 (limits: engineering defaults)",
        value_format="{:.0f} %",
        deadband=a.imbalance_deadband_pct, raise_delay_s=a.raise_delay_s,
        clear_delay_s=a.clear_delay_s,
    )  # fmt: skip


_BUILDERS = (
    _start_peak, _starts_per_month, _oscillation, _bending, _barring, _unexplained_peak,
    _resonance, _natural_frequency, _remaining_life, _stale, _spike_rate, _sequence_gaps,
    _implausible, _archive, _store,
    _load_sharing, _report_delivery, _analysis_lag,
)  # fmt: skip


def build_rules(config: MillConfig) -> RuleBook:
    """The rule book of one mill: thresholds and options from ``config.alarms`` (the mill
    file's ``[alarms]`` section, validated there)."""
    rules = [build(config) for build in _BUILDERS]
    return RuleBook(
        config.id, config.time_zone, {r.quantity: r for r in rules}, simulated=config.simulated
    )
