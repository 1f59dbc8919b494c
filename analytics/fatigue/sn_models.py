"""Named S-N models: the one place that turns a model name and its parameters into a curve.

Used by the CLI options and by mill configuration files, so that ``shigley-limit`` means the same
curve everywhere. Defaults are Diering 2011 App. D section 1: pinion shaft of
S_ut = 850 MPa with Marin factors k_a = 0.8, k_b = 0.688, k_c = 0.814, k_d = k_e = k_f = 1, so
S_e = 0.5·850·0.8·0.688·0.814 = 190.4 MPa (amplitude).

=================  ============================================================================
name               curve
=================  ============================================================================
``shigley``        0.8·S_ut at 10³ → S_e at 10⁶, same slope below (App. D section 1), amplitude
``shigley-limit``  the same with m₂ = 2m₁ − 1 below the knee at 10⁶ (App. D section 2)
``fat-normal``     EN 1993-1-9 normal-stress range, FAT at 2·10⁶ (default 160), m 3/5, cut-off 10⁸
``fat-shear``      EN 1993-1-9 shear-stress range, FAT at 2·10⁶ (default 100), m 5, cut-off 10⁸
=================  ============================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # imported when a curve is built: the names and defaults stay light (CLI)
    from millwatch.analytics.fatigue.sn_curves import SNCurve

__all__ = ["SN_MODEL_NAMES", "SN_MODEL_PARAMETERS", "SNModelParameters", "build_sn_curve"]

#: App. D section 1: S_ut and the Marin factors of the pinion shaft.
APP_D_S_UT = 850.0
APP_D_MARIN = {"ka": 0.8, "kb": 0.688, "kc": 0.814, "kd": 1.0}

#: Each model's own parameter (besides S_ut) and its default: ``None`` = from S_ut and the Marin
#: factors (App. D section 1, or the material's in a mill configuration).
SN_MODEL_PARAMETERS: dict[str, dict[str, float | None]] = {
    "shigley": {"S_e": None},
    "shigley-limit": {"S_e": None},
    "fat-normal": {"fat": 160.0},
    "fat-shear": {"fat": 100.0},
}
SN_MODEL_NAMES = tuple(SN_MODEL_PARAMETERS)


@dataclass(frozen=True, slots=True)
class SNModelParameters:
    """Parameters of a named S-N model (MPa). ``S_e`` ``None``: from S_ut and App. D's Marin
    factors; ``fat`` ``None``: 160 for normal, 100 for shear stress."""

    S_ut: float = APP_D_S_UT
    S_e: float | None = None
    fat: float | None = None


def build_sn_curve(name: str, params: SNModelParameters | None = None) -> SNCurve:
    """The S-N curve called ``name`` (see the module table); raises ``ValueError`` naming the
    known models for an unknown name."""
    from millwatch.analytics.fatigue.sn_curves import SNCurve, marin_endurance_limit

    p = params or SNModelParameters()
    if name in ("shigley", "shigley-limit"):
        s_e = p.S_e if p.S_e is not None else marin_endurance_limit(p.S_ut, **APP_D_MARIN)
        curve = SNCurve.shigley(p.S_ut, s_e)
        return curve.with_fatigue_limit() if name == "shigley-limit" else curve
    if name == "fat-normal":
        return SNCurve.fat_normal(160.0 if p.fat is None else p.fat)
    if name == "fat-shear":
        return SNCurve.fat_shear(100.0 if p.fat is None else p.fat)
    raise ValueError(f"unknown S-N model {name!r}; known models: {', '.join(SN_MODEL_NAMES)}")
