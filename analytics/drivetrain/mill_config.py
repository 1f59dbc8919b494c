"""Mill configuration: one validated, frozen description of a grinding-mill drivetrain.

A mill is described by one TOML file (README "Conventions"); this module holds the pydantic v2
model and its derived kinematics. It is pure: :meth:`MillConfig.from_toml_text` parses text, the
file is read by :func:`millwatch.ingest.mill_files.load_mill_config`.

Sources of the defaults (README "References"):

* rated torque ``T_rated = P / (2π n / 60)``; pinion rated torque = ``T_rated × reducer ratio``
  (Diering 2011 §6.2.1: 5200 kW, 995 rpm, 113/20 → 49.91 kN·m and 281.97 kN·m),
* telemetry bandwidth 0–250 Hz, 1 kHz per channel (Diering 2011 §5.1.2–5.1.3),
* shaft diameters 0.2 m / 0.31 m (Diering 2011 §5.2.3),
* 820M17, S_ut = 980 MPa, Marin factors 0.68/0.75/0.897/1.0, K_t = 2.2 at the keyway
  (Diering 2011 §8.1); K_t = 2 on the torque trace and the FAT 160/100 curves (Diering 2011 App. D),
* alarm thresholds: start peak per starter type, mean + 2/3 standard deviations of its peaks,
  capped at the motor shaft's absolute limit (Diering 2011 Tables 3–11, §8.2;
  :mod:`millwatch.analytics.drivetrain.start_limits`);
  starts/month 5 (supplier norm 3–5, §6.1.3) and 20 (field average 20–22, §6.2.8);
  steady-state oscillation range 25/45 % (Table 14: 23.6 % average, 45.4 % max);
  bending amplitude 25/43/90 MPa (§8.1); barring peak 185 % single / 314 % dual (Tables 12–13),
* excitation orders: mill, pinion, liner passing (20–35 liners), motor, pinion/girth mesh and
  reducer mesh (Diering 2011 §6.1.2) and 3× drive-gear rotation (Fedin & Vinogradov 2018 eq. 12,
  ``p_p = 3ω₁``).

Errors: a :class:`pydantic.ValidationError` converts to one line per problem with
:func:`describe_validation_error`, e.g. ``drive.reducer_ratio: must be > 0``.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
import zoneinfo
from datetime import date
from enum import StrEnum
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from millwatch.analytics.drivetrain.shaft_stress import ShaftStressModel, StressConcentration
from millwatch.analytics.drivetrain.start_limits import (
    StartPeakLimits,
    shaft_limit_pct,
    start_peak_limits,
)
from millwatch.analytics.drivetrain.torsional_params import TorsionalParams
from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve
from millwatch.analytics.fatigue.sn_models import (
    SN_MODEL_PARAMETERS,
    SNModelParameters,
    build_sn_curve,
)

__all__ = [
    "COMPONENT_KINDS",
    "FATIGUE_KINDS",
    "AlarmThresholds",
    "ChannelConfig",
    "ComponentFatigue",
    "DriveConfig",
    "DriveLayout",
    "LifeConfig",
    "MaterialConfig",
    "MillConfig",
    "MillConfigError",
    "SNModel",
    "ShaftConfig",
    "SimulationConfig",
    "Starter",
    "describe_validation_error",
]

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Teeth = Annotated[int, Field(ge=5, le=1000)]
Fraction = Annotated[float, Field(gt=0, le=1)]


class MillConfigError(ValueError):
    """A mill configuration that cannot be used; ``problems`` holds one line per bad field."""

    def __init__(self, source: str, problems: list[str]) -> None:
        self.source = source
        self.problems = problems
        super().__init__(f"{source}: " + "; ".join(problems))


class _Frozen(BaseModel):
    """Base: frozen, unknown fields are errors (a typo names the field)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class DriveLayout(StrEnum):
    """Single or dual pinion drive (Diering 2011 §5, Table 2)."""

    SINGLE = "single"
    DUAL = "dual"


class Starter(StrEnum):
    """Soft-start device (Diering 2011 §6.2.1): fixed grid resistor, liquid resistance, enhanced
    LRS."""

    GRID = "Grid"
    LRS = "LRS"
    E_LRS = "E-LRS"


class DriveConfig(_Frozen):
    """Drivetrain kinematics. Power and rated speed are per motor (one motor per pinion)."""

    layout: DriveLayout
    starter: Starter
    motor_power_kw: Positive
    motor_speed_rpm: Positive
    reducer_ratio: Positive = Field(description="motor speed / pinion speed, e.g. 113/20")
    reducer_stages: tuple[tuple[Teeth, Teeth], ...] = Field(
        min_length=1, description="(driver teeth, driven teeth) per stage, motor side first"
    )
    pinion_teeth: Teeth
    girth_teeth: Teeth
    liner_count: Annotated[int, Field(ge=1, le=200)]

    @model_validator(mode="after")
    def _stages_match_ratio(self) -> DriveConfig:
        ratio = math.prod(driven / driver for driver, driven in self.reducer_stages)
        if abs(ratio / self.reducer_ratio - 1.0) > 0.01:
            raise ValueError(
                f"reducer_stages give ratio {ratio:.4f}, reducer_ratio is {self.reducer_ratio:.4f}"
            )
        if self.girth_teeth <= self.pinion_teeth:
            raise ValueError("girth_teeth must exceed pinion_teeth")
        return self


class ShaftConfig(_Frozen):
    """Shaft diameters (m) at the gauges, stress-concentration factors (Diering 2011 §5.2.3, §8.1).

    ``kt_bending``/``kt_torsion``: theoretical factors K_t of pinion bending and of torsion;
    ``notch_sensitivity`` q turns each into K_f = 1 + q(K_t − 1) (Diering 2011 §8.1 eq. 5);
    ``stress_concentration``: ``"per_load"`` (each load its own K_f in the combined stress,
    Diering 2011 §8.1–8.2) or ``"single_kt"`` (App. D: the torsion K_f on the whole combined
    trace; then ``kt_bending`` is unused and refused).
    :mod:`millwatch.analytics.drivetrain.shaft_stress` applies them."""

    motor_diameter_m: Positive = 0.2
    pinion_diameter_m: Positive = 0.31
    kt_bending: Annotated[float, Field(ge=1.0, le=10.0)] = 2.2
    kt_torsion: Annotated[float, Field(ge=1.0, le=10.0)] = 2.0
    notch_sensitivity: Annotated[float, Field(ge=0, le=1)] = 1.0
    stress_concentration: StressConcentration = "per_load"
    plane_angle_deg: float | Literal["critical"] = Field(
        default=45.0,
        description="θ of the combined stress (Diering 2011 §8.2 eq. 12), degrees: 45 as the "
        'thesis found at the torque peaks and App. D uses; "critical": the θ of the grid '
        "(critical_plane_step_deg) with the most damage",
    )
    critical_plane_step_deg: Annotated[float, Field(ge=1, le=45, allow_inf_nan=False)] | None = (
        Field(
            default=None,
            description='Grid step of plane_angle_deg = "critical", degrees (None: 15): θ = '
            "−90 + k·step, strictly between −90 and 90; must divide 180",
        )
    )

    @field_validator("plane_angle_deg", mode="before")
    @classmethod
    def _plane(cls, value: Any) -> Any:
        """An angle strictly between −90° and 90°, or ``"critical"``: one message either way."""
        if value == "critical":
            return value
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        if not (ok and -90.0 < float(value) < 90.0):
            raise ValueError(
                'must be an angle in degrees strictly between -90 and 90, or "critical"'
            )
        return float(value)

    @model_validator(mode="after")
    def _bending_factor_used(self) -> ShaftConfig:
        if self.stress_concentration == "single_kt" and "kt_bending" in self.model_fields_set:
            raise ValueError(
                'kt_bending is not used with stress_concentration = "single_kt" (App. D puts '
                "the torsion factor kt_torsion on the whole combined stress): remove it, or use "
                '"per_load"'
            )
        self._critical_step_used()
        return self

    def _critical_step_used(self) -> None:
        """``critical_plane_step_deg`` only with the critical plane, and a step dividing 180."""
        if self.critical_plane_step_deg is None:
            return
        if self.plane_angle_deg != "critical":
            raise ValueError(
                f'critical_plane_step_deg is only used with plane_angle_deg = "critical" '
                f"(plane_angle_deg is {self.plane_angle_deg!r}): remove it, or search the "
                "critical plane"
            )
        n = 180.0 / self.critical_plane_step_deg
        if abs(n - round(n)) > 1e-9:
            raise ValueError(
                f"critical_plane_step_deg {self.critical_plane_step_deg:g} does not divide 180° "
                "(e.g. 5, 10, 15, 30)"
            )

    def stress_model(self) -> ShaftStressModel:
        """The fatigue factors and combined stress of these shafts."""
        critical = self.plane_angle_deg == "critical"
        return ShaftStressModel.from_factors(
            self.kt_bending,
            self.kt_torsion,
            self.notch_sensitivity,
            self.stress_concentration,
            theta=math.radians(45.0 if critical else float(self.plane_angle_deg)),
            critical_step_deg=(self.critical_plane_step_deg or 15.0) if critical else None,
        )


class SNModel(_Frozen):
    """S-N model by name (:data:`millwatch.analytics.fatigue.sn_models.SN_MODEL_PARAMETERS`) with
    overrides."""

    name: str = "shigley"
    params: dict[str, Finite] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _known(self) -> SNModel:
        if self.name not in SN_MODEL_PARAMETERS:
            known = ", ".join(SN_MODEL_PARAMETERS)
            raise ValueError(f"unknown S-N model {self.name!r}; known: {known}")
        unknown = sorted(set(self.params) - set(SN_MODEL_PARAMETERS[self.name]))
        if unknown:
            raise ValueError(f"unknown parameters for {self.name!r}: {unknown}")
        return self

    def resolved_params(self) -> dict[str, float | None]:
        """The model's parameters: the model's defaults (None: derive from the
        material) updated by ``params``."""
        return {**SN_MODEL_PARAMETERS[self.name], **self.params}


#: Component kinds a ``[material.components.<kind>]`` table may name: the analysed components
#: (:data:`COMPONENT_KINDS`) and ``pinion_bending``, the bending stress alone (K_f,b·σ_b), which
#: is analysed only when the mill file gives it a table (Diering 2011 App. D §3: bending on the
#: normal-stress curve, torsion on the shear-stress curve).
FATIGUE_KINDS = ("pinion_combined", "pinion_torsion", "motor_torsion", "pinion_bending")


class ComponentFatigue(_Frozen):
    """One component kind's fatigue model (``[material.components.<kind>]``): its S-N curve
    (``sn``; None: the material's ``[material.sn]``) and mean-stress correction
    (``mean_stress``: ``"none"``, or ``"goodman"`` — S_eq = S/(1 − S_m/S_ut) with the material's
    S_ut, Diering 2011 §8.1 Figure 37;
    :class:`~millwatch.analytics.fatigue.sn_curves.GoodmanCorrection`)."""

    sn: SNModel | None = None
    mean_stress: Literal["none", "goodman"] = "none"


#: Material fields removed because nothing read them (a file that sets one is refused, saying why).
_REMOVED_MATERIAL = {
    "elastic_modulus_gpa": "channels are calibrated by their own gain and offset",
    "poisson_ratio": "channels are calibrated by their own gain and offset",
}


class MaterialConfig(_Frozen):
    """Shaft material (stress in MPa) and S-N model (Diering 2011 §8.1)."""

    name: str = "820M17"
    s_ut_mpa: Annotated[float, Field(gt=100, le=3000)] = 980.0
    ka: Fraction = 0.68
    kb: Fraction = 0.75
    kc: Fraction = 0.897
    kd: Fraction = 1.0
    sn: SNModel = Field(default_factory=SNModel)
    components: dict[str, ComponentFatigue] = Field(
        default_factory=dict,
        description="Per component kind: its own S-N curve and mean-stress correction "
        "(kinds: pinion_combined, pinion_torsion, motor_torsion, pinion_bending)",
    )

    @field_validator("components")
    @classmethod
    def _known_kinds(cls, value: dict[str, ComponentFatigue]) -> dict[str, ComponentFatigue]:
        unknown = sorted(set(value) - set(FATIGUE_KINDS))
        if unknown:
            raise ValueError(
                f"unknown component kind(s) {unknown}; a [material.components.<kind>] table "
                f"names one of {', '.join(FATIGUE_KINDS)} (the same for every drive side)"
            )
        return value

    @model_validator(mode="before")
    @classmethod
    def _removed(cls, data: Any) -> Any:
        """Fields a mill file may still carry that nothing reads any more: refused in words."""
        unused = sorted(set(data) & set(_REMOVED_MATERIAL)) if isinstance(data, dict) else []
        if unused:
            raise ValueError("; ".join(f"{name} is not used: {_REMOVED_MATERIAL[name]}; remove it"
                                       for name in unused))  # fmt: skip
        return data

    @property
    def endurance_limit_mpa(self) -> float:
        """S_e = k_a k_b k_c k_d · 0.5 S_ut in MPa (Diering 2011 §8.1 eqs. 2–4)."""
        return self.ka * self.kb * self.kc * self.kd * 0.5 * self.s_ut_mpa

    def sn_curve(self, kind: str | None = None) -> SNCurve:
        """The S-N curve of component ``kind`` (its ``[material.components.<kind>]`` ``sn``),
        else the material's ``[material.sn]``; S_e defaults to this material's Marin endurance
        limit. ``kind`` may carry a drive side suffix (``pinion_torsion_bs``)."""
        own = self._component(kind)
        model = own.sn if own is not None and own.sn is not None else self.sn
        p = model.resolved_params()
        s_e = p.get("S_e")
        params = SNModelParameters(
            S_ut=self.s_ut_mpa,
            S_e=self.endurance_limit_mpa if s_e is None else s_e,
            fat=p.get("fat"),
        )
        return build_sn_curve(model.name, params)

    def mean_correction(self, kind: str) -> GoodmanCorrection | None:
        """The mean-stress correction of component ``kind`` (side suffix allowed): Goodman on
        this material's S_ut when its table says ``mean_stress = "goodman"``, else None."""
        own = self._component(kind)
        if own is None or own.mean_stress == "none":
            return None
        return GoodmanCorrection(self.s_ut_mpa)

    def _component(self, kind: str | None) -> ComponentFatigue | None:
        """The ``[material.components]`` table of ``kind`` with any drive side suffix removed."""
        if kind is None:
            return None
        return self.components.get(kind.removesuffix("_bs").removesuffix("_nbs"))


_KEY_PATTERN = r"^[a-z0-9][a-z0-9_\-]*(/[a-z0-9][a-z0-9_\-]*)*$"
_UNITS = {"torque": "kN·m", "bending": "MPa", "rpm": "rpm", "tacho": "V"}


class ChannelConfig(_Frozen):
    """One telemetry channel.

    ``value = gain · (raw − offset)`` converts raw samples to engineering units (zero offset
    subtracted, then the shunt-calibration gain, Diering 2011 §5.2.6). ``full_scale`` is the fixed
    range (engineering units) that sets rainflow bin edges. ``kind`` is ``torque`` (kN·m),
    ``bending`` (MPa), ``rpm`` (speed, rpm) or ``tacho`` (reflector pulse train in V, converted
    to speed with ``pulses_per_rev``, Diering 2011 §5.2.5).
    """

    key: Annotated[str, Field(pattern=_KEY_PATTERN, max_length=120)]
    kind: Literal["torque", "bending", "rpm", "tacho"]
    shaft: Literal["motor", "pinion"] = "pinion"
    side: Literal["bs", "nbs"] | None = None
    units: str
    gain: Finite = 1.0
    offset: Finite = 0.0
    full_scale: tuple[Finite, Finite] | None = None
    pulses_per_rev: Annotated[int, Field(ge=1, le=1000)] | None = None

    @field_validator("gain")
    @classmethod
    def _nonzero_gain(cls, gain: float) -> float:
        if gain == 0.0:
            raise ValueError("must be non-zero")
        return gain

    @model_validator(mode="after")
    def _consistent(self) -> ChannelConfig:
        if self.units != _UNITS[self.kind]:
            raise ValueError(f"units of a {self.kind} channel must be {_UNITS[self.kind]!r}")
        if self.kind in ("torque", "bending") and self.full_scale is None:
            raise ValueError("full_scale [low, high] is required for torque and bending")
        if self.full_scale is not None and not self.full_scale[0] < self.full_scale[1]:
            raise ValueError("full_scale must be [low, high] with low < high")
        if self.kind == "tacho" and self.pulses_per_rev is None:
            raise ValueError("pulses_per_rev is required for a tacho channel")
        if self.kind == "bending" and self.shaft != "pinion":
            raise ValueError("bending is measured on the pinion shaft")
        return self


NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class AlarmThresholds(_Frozen):
    """The ``[alarms]`` section: thresholds (source values; % are of motor rated torque, sources in
    the module docstring) and the rules' options the sources do not fix — deadbands, delays (s),
    data-quality limits, resonance margin, life fractions, load-sharing limits. Those options'
    defaults are engineering judgement; every field names its unit. :mod:`millwatch.alarms.rules`
    says which rule uses which field."""

    start_peak_warn_pct: Positive | None = Field(
        default=None,
        description="None: the starter type's, mean + 2 standard deviations "
        "(Diering 2011 Tables 3-11), capped at the motor shaft's absolute limit",
    )
    start_peak_alarm_pct: Positive | None = Field(
        default=None,
        description="None: the starter type's, mean + 3 standard deviations "
        "(Diering 2011 Tables 3-11), capped at the motor shaft's absolute limit",
    )
    starts_per_month_warn: Annotated[int, Field(ge=1)] = 5
    starts_per_month_alarm: Annotated[int, Field(ge=1)] = 20
    oscillation_range_warn_pct: Positive = 25.0
    oscillation_range_alarm_pct: Positive = 45.0
    bending_amplitude_warn_mpa: Positive = 25.0
    bending_amplitude_alarm_mpa: Positive = 43.0
    bending_amplitude_critical_mpa: Positive = 90.0
    barring_peak_pct: Positive | None = Field(
        default=None, description="None: 185 % single drive, 314 % dual drive (Tables 12-13)"
    )
    # Rule options: engineering judgement, not source values (millwatch.alarms.rules says which
    # rule uses
    # which). Times in s, deadbands in the rule's unit, rates per minute, fractions as named.
    # fmt: off
    raise_delay_s: NonNegative = 60.0             # a level stays beyond this long to raise …
    clear_delay_s: NonNegative = 300.0            # … and within the clear level to clear
    start_peak_deadband_pct: NonNegative = 10.0
    clean_starts_to_clear: Annotated[int, Field(ge=1)] = 1  # the next normal start clears
    # an acknowledged start-peak alarm returns to normal this long after its last exceeding
    # start (option: the next shift has seen it; EEMUA 191, no alarm standing over a day)
    start_peak_hold_s: Positive = 43200.0
    oscillation_deadband_pct: NonNegative = 2.0
    bending_deadband_mpa: NonNegative = 2.0
    barring_deadband_pct: NonNegative = 10.0
    unexplained_peak_quiet_s: Positive = 3600.0   # no recurrence this long: clear
    # resonance: warn when an excitation is within this fraction of a natural frequency
    resonance_margin_warn: Annotated[float, Field(gt=0, lt=1)] = 0.10
    resonance_margin_deadband: NonNegative = 0.02
    # natural-frequency shift: the run-up resonance away from the model's natural frequency, %
    # of it (f ∝ √k: 10 % is a fifth of the stiffness); clears at the next start within warn −
    # deadband (clean_starts_to_clear)
    natural_frequency_shift_warn_pct: Positive = 10.0
    natural_frequency_shift_alarm_pct: Positive = 20.0
    natural_frequency_shift_deadband_pct: NonNegative = 2.0
    # remaining life below these fractions of the remaining design life: warning, alarm
    life_warn_fraction: Positive = 1.0
    life_alarm_fraction: Positive = 0.5
    life_deadband_fraction: NonNegative = 0.05
    stale_after_s: Positive = 10.0                # no data from a channel this long: warning
    spike_rate_warn_per_min: Positive = 6.0
    spike_rate_deadband_per_min: NonNegative = 3.0
    sequence_gaps_warn_blocks: NonNegative = 0.0  # blocks lost in one unrecoverable loss
    data_quality_quiet_s: Positive = 300.0        # no further loss / implausible block: clear
    archive_clean_reports_to_clear: Annotated[int, Field(ge=1)] = 3
    analysis_lag_warn_s: Positive = 120.0         # analysis behind the archive this long
    # dual drives: load-sharing imbalance (BS − NBS) / mean, %; unbalanced sharing is common
    # (Diering 2011 §6.2.2; start peaks 167 % barring side vs 144 % non-barring, Tables 7–8)
    # and the simulated LRS dual drive runs 20 % apart: at 10 % its alarm stood 34 h of 48
    imbalance_warn_pct: Positive = 25.0
    imbalance_alarm_pct: Positive = 35.0
    imbalance_deadband_pct: NonNegative = 2.0
    # fmt: on

    @model_validator(mode="after")
    def _ordered(self) -> AlarmThresholds:
        pairs = [
            ("start_peak_warn_pct", "start_peak_alarm_pct"),
            ("starts_per_month_warn", "starts_per_month_alarm"),
            ("oscillation_range_warn_pct", "oscillation_range_alarm_pct"),
            ("bending_amplitude_warn_mpa", "bending_amplitude_alarm_mpa"),
            ("bending_amplitude_alarm_mpa", "bending_amplitude_critical_mpa"),
            ("imbalance_warn_pct", "imbalance_alarm_pct"),
            ("natural_frequency_shift_warn_pct", "natural_frequency_shift_alarm_pct"),
            ("life_alarm_fraction", "life_warn_fraction"),  # lower life is worse
        ]
        for low, high in pairs:
            if getattr(self, low) is None or getattr(self, high) is None:
                continue
            if not getattr(self, low) < getattr(self, high):
                raise ValueError(
                    f"{low} ({getattr(self, low)}) must be below {high} ({getattr(self, high)})"
                )
        return self


#: The analysed components of each drive side: combined (bending + torsion, §8.2) and torsion
#: stress on the pinion shaft, torsion on the motor shaft (``_bs``/``_nbs`` on dual drives).
COMPONENT_KINDS = ("pinion_combined", "pinion_torsion", "motor_torsion")
_PRIOR_RATE = re.compile(r"^first_([1-9]\d{0,3})_days$")


class LifeConfig(_Frozen):
    """How remaining life is projected (``[life]`` of a mill file; :mod:`millwatch.reports.life`).

    Damage before monitoring began (Diering 2011 §8.3: a 15-year-old shaft is not new): the date
    the drivetrain was ``commissioned`` and *either* an estimated ``prior_damage`` (Miner sum,
    one value for every component or a table per component) *or* an assumed ``prior_rate``:
    ``"first_<N>_days"`` applies the damage rate of the first N days of monitoring from
    commissioning to the start of monitoring. Without either, damage counts from the start of
    monitoring only, and the answer says so.

    No projection before ``min_monitoring_days`` of monitoring including ``min_starts`` starts;
    ``rate_window_days`` is the "recent" rate's window; ``miner_limit`` the Miner sum taken as
    failure (default 1, Diering 2011 §8.2; below 1 for a conservative assessment)."""

    commissioned: date | None = Field(
        default=None, description="Local date the drivetrain went into service."
    )
    prior_damage: Annotated[float, Field(ge=0, le=1)] | dict[str, Annotated[
        float, Field(ge=0, le=1)]] | None = None  # fmt: skip
    prior_rate: str | None = Field(default=None, description='e.g. "first_90_days"')
    min_monitoring_days: Annotated[float, Field(ge=0, le=3650)] = 14.0
    min_starts: Annotated[int, Field(ge=0, le=1000)] = 1
    rate_window_days: Annotated[int, Field(ge=1, le=366)] = 30
    miner_limit: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)] = Field(
        default=1.0,
        description="Miner sum D at which a component is taken to fail (Diering 2011 §8.2: 1); "
        "life consumed is D / miner_limit, remaining life (miner_limit − D) / rate",
    )

    @field_validator("prior_rate")
    @classmethod
    def _rate_form(cls, value: str | None) -> str | None:
        if value is not None and not _PRIOR_RATE.match(value):
            raise ValueError(f"{value!r} is not first_<N>_days (e.g. first_90_days)")
        return value

    @model_validator(mode="after")
    def _prior_needs_a_date(self) -> LifeConfig:
        if self.prior_damage is not None and self.prior_rate is not None:
            raise ValueError("give prior_damage or prior_rate, not both")
        if self.prior_rate is not None and self.commissioned is None:
            raise ValueError("prior_rate needs commissioned (the date to apply it from)")
        if self.prior_damage is not None and self.commissioned is None:
            raise ValueError("prior_damage needs commissioned (the date it is estimated from)")
        return self

    @property
    def prior_rate_days(self) -> int | None:
        """N of ``first_<N>_days``; None without a prior rate."""
        m = _PRIOR_RATE.match(self.prior_rate or "")
        return int(m.group(1)) if m else None


class SimulationConfig(_Frozen):
    """The simulated mill's condition (``[simulation]``, only in a ``simulated = true`` file):
    the simulator's scene parameters for this mill, each overriding the sources' default a
    catalogue scene would use (a scene file's own ``[params]`` override these in turn).

    ``bending_range_mpa``: steady pinion bending range, MPa (default: Diering 2011 Tables 16–17
    averages, 15.29 single / 37.5 dual; §6.2.5 measured 73.5–88 MPa on misaligned pinions);
    ``motor_oscillation_pct`` / ``pinion_oscillation_pct``: steady torque oscillation ranges, %
    of motor rated torque (default Table 14 averages, 23.61 / 16.38); ``load_pct``: steady load,
    % of rated (default 90)."""

    bending_range_mpa: Annotated[float, Field(ge=0, le=500, allow_inf_nan=False)] | None = None
    motor_oscillation_pct: Annotated[float, Field(ge=0, le=200, allow_inf_nan=False)] | None = None
    pinion_oscillation_pct: Annotated[float, Field(ge=0, le=200, allow_inf_nan=False)] | None = None
    load_pct: Annotated[float, Field(gt=0, le=200, allow_inf_nan=False)] | None = None

    def scene_params(self) -> dict[str, float]:
        """The parameters set here, by the simulator's names."""
        return self.model_dump(exclude_none=True)


#: Barring peak limits in % of motor rated torque (Diering 2011 Tables 12–13, §6.2.3).
BARRING_LIMIT_PCT = {DriveLayout.SINGLE: 185.0, DriveLayout.DUAL: 314.0}


class MillConfig(_Frozen):
    """A mill: identity, drivetrain, shafts, material, channels, alarms (README "Design")."""

    id: Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_\-]*$", max_length=64)]
    site: Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_\-]*$", max_length=64)]
    time_zone: str = "UTC"
    design_life_years: Annotated[float, Field(gt=0, le=100)] = 20.0
    sample_rate_hz: Positive = 1000.0
    telemetry_bandwidth_hz: Positive = 250.0
    drive: DriveConfig
    shafts: ShaftConfig = Field(default_factory=ShaftConfig)
    material: MaterialConfig = Field(default_factory=MaterialConfig)
    channels: dict[Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]*$")], ChannelConfig] = Field(
        min_length=1
    )
    alarms: AlarmThresholds = Field(default_factory=AlarmThresholds)
    life: LifeConfig = Field(default_factory=LifeConfig)
    torsional: TorsionalParams | None = Field(
        default=None,
        description="The drivetrain's lumped torsional model referred to the pinion shaft "
        "(Fedin & Vinogradov 2018 Table 2): natural frequencies for the harmonic tracker and "
        "the resonance_margin alarm. None: no model (the analysis says so).",
    )
    simulated: bool = Field(
        default=False,
        description="The mill's data come from the simulator (the demo, example mills): every "
        "answer, report and alarm about the mill says so. Never set for a real mill.",
    )
    simulation: SimulationConfig | None = Field(
        default=None,
        description="The simulator's scene parameters for this mill (only with simulated = "
        "true); see SimulationConfig.",
    )

    @field_validator("time_zone")
    @classmethod
    def _known_zone(cls, name: str) -> str:
        try:
            zoneinfo.ZoneInfo(name)
        except (zoneinfo.ZoneInfoNotFoundError, ValueError) as exc:
            raise ValueError(f"unknown IANA time zone {name!r}") from exc
        return name

    @model_validator(mode="after")
    def _consistent(self) -> MillConfig:
        if self.telemetry_bandwidth_hz > self.sample_rate_hz / 2:
            raise ValueError("telemetry_bandwidth_hz must not exceed sample_rate_hz / 2")
        _unique_keys(self.channels)
        dual = self.drive.layout is DriveLayout.DUAL
        for name, ch in self.channels.items():
            if ch.kind in ("torque", "bending") and dual != (ch.side is not None):
                need = "needs side 'bs' or 'nbs'" if dual else "must not set side"
                raise ValueError(f"channel {name!r} on a {self.drive.layout} drive {need}")
        self.start_peak_limits()  # a configured start-peak level must fit the starter's
        self._goodman_bounded()
        if self.simulation is not None and not self.simulated:
            raise ValueError(
                "simulation: scene parameters are only for a simulated mill (simulated = true); "
                "a real mill's file leaves [simulation] out"
            )
        prior = self.life.prior_damage
        if isinstance(prior, dict):
            unknown = sorted(set(prior) - set(self.components))
            if unknown:
                raise ValueError(f"life.prior_damage: unknown component(s) {unknown}; this "
                                 f"mill's components: {', '.join(self.components)}")  # fmt: skip
        return self

    def _goodman_bounded(self) -> None:
        """Goodman has no answer for a cycle mean at S_ut (a block holding one is refused,
        :class:`~millwatch.analytics.fatigue.sn_curves.MeanStressError`): a component with the
        correction
        must not reach S_ut within its channels' full scales (beyond them a sample is flagged
        at the rail and not counted)."""
        s_ut = self.material.s_ut_mpa
        for comp, bound in self.stress_bounds().items():
            kind = comp.removesuffix("_bs").removesuffix("_nbs")
            if self.material.mean_correction(comp) is not None and bound >= s_ut:
                raise ValueError(
                    f'material.components.{kind}.mean_stress = "goodman": within the channels\' '
                    f"full scales {comp} reaches {bound:.0f} MPa, not below S_ut = {s_ut:g} MPa "
                    "(Goodman gives no finite life there); narrow the torque and bending "
                    "channels' full_scale to the real range, or leave the correction out"
                )

    def stress_bounds(self) -> dict[str, float]:
        """The largest |stress| (MPa, fatigue factors included) each component can reach within
        its channels' full scales; a component without its channels is left out."""
        model, sh, out = self.shafts.stress_model(), self.shafts, {}
        for side in self.sides:
            sfx = f"_{side}" if side else ""
            top = {
                (ch.kind, ch.shaft): max(abs(v) for v in ch.full_scale)
                for ch in self.channels.values()
                if ch.side == side and ch.full_scale is not None
            }
            sb = top.get(("bending", "pinion"))
            tp, tm = top.get(("torque", "pinion")), top.get(("torque", "motor"))
            tau_p = None if tp is None else tp / (math.pi * sh.pinion_diameter_m**3 / 16 * 1e3)
            if tau_p is not None and sb is not None:
                out[f"pinion_combined{sfx}"] = model.combined_bound(sb, tau_p)
            if tau_p is not None:
                out[f"pinion_torsion{sfx}"] = model.torsion_scale * tau_p
            if tm is not None:
                tau_m = tm / (math.pi * sh.motor_diameter_m**3 / 16 * 1e3)
                out[f"motor_torsion{sfx}"] = model.torsion_scale * tau_m
            if sb is not None:
                out[f"pinion_bending{sfx}"] = model.bending_scale * sb
        return {c: b for c, b in out.items() if c in self.components}

    @classmethod
    def from_toml_text(cls, text: str) -> MillConfig:
        """Parse and validate TOML text; raises ``TOMLDecodeError`` or ``ValidationError``."""
        return cls.model_validate(tomllib.loads(text))

    def stored_form(self) -> dict[str, Any]:
        """The configuration as the store keeps it (plain JSON data): what the mill file set,
        defaults left out, so it reads back as the same configuration (a full dump would
        write out settings a mode refuses, e.g. ``kt_bending`` beside App. D's single K_t)."""
        return self.model_dump(mode="json", exclude_unset=True)

    @property
    def components(self) -> list[str]:
        """The analysed components: each of :data:`COMPONENT_KINDS` on each drive side, and
        ``pinion_bending`` when ``[material.components.pinion_bending]`` asks for it."""
        kinds = COMPONENT_KINDS + (
            ("pinion_bending",) if "pinion_bending" in self.material.components else ()
        )
        return [f"{k}_{s}" if s else k for s in self.sides for k in kinds]

    @property
    def sides(self) -> tuple[str | None, ...]:
        """Drive sides: ``(None,)`` single drive, ``("bs", "nbs")`` dual (barring/non-barring)."""
        return ("bs", "nbs") if self.drive.layout is DriveLayout.DUAL else (None,)

    @property
    def motor_rated_torque_knm(self) -> float:
        """T_rated = P / (2π n / 60) per motor, kN·m (Diering 2011 §6.2.1)."""
        return self.drive.motor_power_kw / (2.0 * math.pi * self.drive.motor_speed_rpm / 60.0)

    @property
    def pinion_rated_torque_knm(self) -> float:
        """Motor rated torque × reducer ratio, kN·m (Diering 2011 §6.2.1)."""
        return self.motor_rated_torque_knm * self.drive.reducer_ratio

    @property
    def pinion_speed_rpm(self) -> float:
        """Motor speed / reducer ratio, rpm."""
        return self.drive.motor_speed_rpm / self.drive.reducer_ratio

    @property
    def mill_speed_rpm(self) -> float:
        """Pinion speed × pinion teeth / girth teeth, rpm."""
        return self.pinion_speed_rpm * self.drive.pinion_teeth / self.drive.girth_teeth

    @property
    def barring_peak_limit_pct(self) -> float:
        """Barring peak limit, % motor rated torque (configured, else Tables 12–13)."""
        configured = self.alarms.barring_peak_pct
        return configured if configured is not None else BARRING_LIMIT_PCT[self.drive.layout]

    def start_peak_limits(self) -> StartPeakLimits:
        """Start-peak set points, % of motor rated torque: the starter type's
        (:func:`~millwatch.analytics.drivetrain.start_limits.start_peak_limits`, capped at the motor
        shaft's absolute limit), each replaced by ``alarms.start_peak_warn_pct`` /
        ``alarms.start_peak_alarm_pct`` when the mill file sets it."""
        shaft = shaft_limit_pct(
            self.shafts.motor_diameter_m, self.motor_rated_torque_knm, self.material.s_ut_mpa
        )
        limits = start_peak_limits(str(self.drive.starter), self.sides, shaft)
        warn, alarm = self.alarms.start_peak_warn_pct, self.alarms.start_peak_alarm_pct
        alarm = limits.alarm if alarm is None else alarm
        warn = limits.warning if warn is None else warn
        if warn is not None and not warn < alarm:
            raise ValueError(
                f"alarms: start_peak_warn_pct ({warn}) must be below the start-peak alarm "
                f"level ({alarm:.0f} % for this {self.drive.starter} starter)"
            )
        return dataclasses.replace(limits, warning=warn, alarm=alarm)

    def start_peak_levels(self) -> tuple[float, float]:
        """(warning, alarm) start-peak levels, % of motor rated torque
        (:meth:`start_peak_limits`; the alarm level twice when the shaft's cap leaves no
        warning band)."""
        limits = self.start_peak_limits()
        warning = limits.alarm if limits.warning is None else limits.warning
        return warning, limits.alarm

    def excitation_orders(self) -> dict[str, float]:
        """Expected excitations as orders of pinion rotation (cycles per pinion revolution).

        Diering 2011 §6.1.2 lists mill speed, pinion speed, liner passing, motor speed, pinion/girth
        mesh and reducer mesh; Fedin & Vinogradov 2018 eq. 12 adds 3× the drive-gear (pinion)
        rotation.
        """
        d = self.drive
        mill = d.pinion_teeth / d.girth_teeth
        orders = {
            "mill_speed": mill,
            "pinion_speed": 1.0,
            "pinion_3x": 3.0,
            "liner_passing": d.liner_count * mill,
            "girth_mesh": float(d.pinion_teeth),
            "motor_speed": d.reducer_ratio,
        }
        shaft = d.reducer_ratio  # speed of the stage's input shaft, in pinion orders
        for i, (driver, driven) in enumerate(d.reducer_stages, start=1):
            orders[f"reducer_mesh_{i}"] = shaft * driver
            shaft *= driver / driven
        return orders

    def excitation_frequencies_hz(self) -> dict[str, float]:
        """:meth:`excitation_orders` at rated pinion speed, in Hz."""
        rev_hz = self.pinion_speed_rpm / 60.0
        return {name: order * rev_hz for name, order in self.excitation_orders().items()}

    def observable(self, frequency_hz: float) -> bool:
        """Whether a frequency lies within the telemetry bandwidth and below Nyquist."""
        return 0.0 <= frequency_hz <= min(self.telemetry_bandwidth_hz, self.sample_rate_hz / 2)


def _unique_keys(channels: dict[str, ChannelConfig]) -> None:
    """``ValueError`` naming the channels that share a key (each key is one zenoh key)."""
    owners: dict[str, list[str]] = {}
    for name, ch in channels.items():
        owners.setdefault(ch.key, []).append(f"channels.{name}.key")
    shared = {k: names for k, names in owners.items() if len(names) > 1}
    if shared:
        said = "; ".join(
            f"{' and '.join(n)} are {'all' if len(n) > 2 else 'both'} {k!r}"
            for k, n in shared.items()
        )
        raise ValueError(f"{said}: each channel needs a key of its own")


#: Patterns of the mill file's names, in words.
_PATTERN_WORDS = {
    _KEY_PATTERN: "lower-case letters, digits, '_' and '-', in segments separated by '/', "
    "each starting with a letter or digit",
    r"^[a-z0-9][a-z0-9_\-]*$": "lower-case letters, digits, '_' and '-', starting with a letter "
    "or digit",
    r"^[a-z][a-z0-9_]*$": "lower-case letters, digits and '_', starting with a letter",
}

#: Errors whose value says nothing more (the field's name is the point, or there is none).
_NO_VALUE = ("missing", "extra_forbidden")

_MESSAGES = {
    "greater_than": "must be > {gt}",
    "greater_than_equal": "must be >= {ge}",
    "less_than": "must be < {lt}",
    "less_than_equal": "must be <= {le}",
    "extra_forbidden": "unknown field (typo?)",
    "missing": "required field is missing",
    "string_pattern_mismatch": "must match {pattern}",
}


def _message(error: Any) -> str:
    ctx = error.get("ctx", {})
    words = _PATTERN_WORDS.get(str(ctx.get("pattern")))
    if error["type"] == "string_pattern_mismatch" and words:
        return f"must be {words}"
    template = _MESSAGES.get(error["type"])
    if template is not None:
        return template.format(**ctx)
    return str(error["msg"]).removeprefix("Value error, ")


def describe_validation_error(exc: ValidationError) -> list[str]:
    """One line per error: the dotted field, what is wrong and the value given (a plain value,
    not a table), e.g. ``drive.reducer_ratio: must be > 0.0, got -5.65``; an error about
    several fields (e.g. two channels with one key) names them in its message."""
    lines = []
    for error in exc.errors():
        loc = ".".join(str(part) for part in error["loc"])
        line = f"{loc}: {_message(error)}" if loc else _message(error)
        value = error.get("input")
        if loc and error["type"] not in _NO_VALUE and not isinstance(value, dict | list):
            line += f", got {value!r}"
        lines.append(line)
    return lines
