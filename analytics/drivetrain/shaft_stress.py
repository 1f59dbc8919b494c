"""The local (notch) stress of each analysed component: the one place the stress concentration
factors of a mill file's ``[shafts]`` table enter the fatigue damage.

Sources
-------
* Diering 2011 §8.1 eq. 5: the fatigue strength reduction factor ``K_f = 1 + q (K_t − 1)`` from
  the theoretical factor ``K_t`` (Peterson, 2.2 for pinion-shaft bending at the keyway) and the
  notch sensitivity ``q`` (the thesis takes q = 1, so K_f = K_t).
* Diering 2011 §8.2 eq. 12 with σ_y = 0: ``σ_θ = ½σ_x + ½σ_x cos 2θ + τ sin 2θ`` at θ = 45°, σ_x
  the pinion bending stress and τ = 16T/(πd³) the pinion shear stress (eq. 11). Bending and
  torsion are different loads at the keyway, each with its own factor, so the local combined
  stress is ``σ_θ = K_f,b σ_b (½ + ½ cos 2θ) + K_f,t τ sin 2θ`` — the factors act before rainflow
  counting, on the trace, since the two parts of one trace carry different factors.
* Diering 2011 App. D §3: the bending stress alone as a component of its own
  (``pinion_bending``, on the normal-stress curve), with K_f,b — or App. D's one factor.
* θ is the mill file's ``shafts.plane_angle_deg`` (default 45°), or the critical plane: the
  combined stress counted on every θ of a grid (``shafts.critical_plane_step_deg``) and reported
  on the one with the most damage so far (the critical-plane idea of multiaxial fatigue; the
  thesis' own θ(t) search, §8.2 eq. 13, found 45° at the torque peaks).
* Diering 2011 App. D: one ``K_t = 2`` multiplies the whole (torsional) stress trace. Kept as the
  explicit option ``shafts.stress_concentration = "single_kt"``: the combined trace of eq. 12 is
  scaled as a whole by the torsion factor ``K_f,t`` (= ``kt_torsion`` for q = 1), and
  ``kt_bending`` is not used (a mill file that sets it with this option is refused).

The torsion components (``pinion_torsion``, ``motor_torsion``) carry ``K_f,t`` either way, applied
to the cycle ranges by the damage recorder (a positive factor commutes with rainflow counting).

Units: stress MPa, factors dimensionless, angle rad.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from millwatch.analytics.drivetrain.stress import THETA_SEED

__all__ = ["ShaftStressModel", "StressConcentration", "fatigue_factor"]

#: ``"per_load"`` (default: K_f,b on bending, K_f,t on torsion, Diering 2011 §8.1–8.2) or
#: ``"single_kt"`` (Diering 2011 App. D: K_f,t on the whole combined trace).
StressConcentration = Literal["per_load", "single_kt"]


def fatigue_factor(kt: float, q: float) -> float:
    """``K_f = 1 + q (K_t − 1)`` (Diering 2011 §8.1 eq. 5): ``kt`` ≥ 1, ``q`` in [0, 1]."""
    if not (math.isfinite(kt) and kt >= 1.0):
        raise ValueError(f"stress concentration factor K_t must be ≥ 1, got {kt!r}")
    if not 0.0 <= q <= 1.0:
        raise ValueError(f"notch sensitivity q must be in [0, 1], got {q!r}")
    return 1.0 + q * (kt - 1.0)


@dataclass(frozen=True)
class ShaftStressModel:
    """Fatigue factors of one mill's shafts and the local combined stress they give.

    ``kf_bending``/``kf_torsion``: K_f of bending and of torsion (:func:`fatigue_factor`);
    ``mode``: :data:`StressConcentration`; ``theta``: the angle of eq. 12 (rad, 45° as the
    thesis found at the torque peaks); ``critical_step_deg``: None, or the grid step (degrees)
    of the critical plane search — the combined component is then counted at every
    :meth:`plane_angles_deg` and reported at the one with the most damage."""

    kf_bending: float
    kf_torsion: float
    mode: StressConcentration = "per_load"
    theta: float = THETA_SEED
    critical_step_deg: float | None = None

    @classmethod
    def from_factors(
        cls,
        kt_bending: float,
        kt_torsion: float,
        q: float,
        mode: StressConcentration,
        theta: float = THETA_SEED,
        critical_step_deg: float | None = None,
    ) -> ShaftStressModel:
        """The model of a mill file's ``[shafts]`` values (``q``: notch sensitivity; ``theta``:
        the plane angle of eq. 12, rad; ``critical_step_deg``: the critical plane's grid)."""
        kf_b, kf_t = fatigue_factor(kt_bending, q), fatigue_factor(kt_torsion, q)
        return cls(kf_b, kf_t, mode, theta, critical_step_deg)

    def plane_angles_deg(self) -> tuple[float, ...]:
        """The planes the combined stress is counted on, degrees: θ alone, or the critical
        plane's grid −90 + k·step strictly between −90° and 90° (θ and θ + 180° give the same
        σ_θ; at ±90° σ_θ is 0)."""
        step = self.critical_step_deg
        if step is None:
            return (math.degrees(self.theta),)
        n = round(180.0 / step)
        return tuple(-90.0 + k * step for k in range(1, n))

    def at(self, theta_deg: float) -> ShaftStressModel:
        """The same factors on the one plane ``theta_deg`` (degrees)."""
        return dataclasses.replace(self, theta=math.radians(theta_deg), critical_step_deg=None)

    @property
    def _weights(self) -> tuple[float, float]:
        """(weight of σ_b, weight of τ) in the combined trace."""
        two = 2.0 * self.theta
        if self.mode == "single_kt":
            return 0.5 + 0.5 * math.cos(two), math.sin(two)
        return self.kf_bending * (0.5 + 0.5 * math.cos(two)), self.kf_torsion * math.sin(two)

    def combined(self, sigma_b: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """The combined stress trace rainflow counts (MPa, a new array): the local stress
        ``K_f,b σ_b (½ + ½ cos 2θ) + K_f,t τ sin 2θ`` (``"per_load"``), or the nominal eq. 12
        stress that :attr:`combined_scale` then multiplies (``"single_kt"``)."""
        wb, wt = self._weights
        out = np.multiply(sigma_b, wb, dtype=np.float64)
        out += np.multiply(tau, wt, dtype=np.float64)
        return out

    @property
    def combined_scale(self) -> float:
        """Factor on the combined component's cycle ranges: 1 (``"per_load"``: the factors are
        in the trace) or K_f,t (``"single_kt"``, App. D)."""
        return self.kf_torsion if self.mode == "single_kt" else 1.0

    @property
    def torsion_scale(self) -> float:
        """Factor on the torsion components' cycle ranges: K_f,t."""
        return self.kf_torsion

    @property
    def bending_scale(self) -> float:
        """Factor on the bending component's cycle ranges (``pinion_bending``, App. D §3):
        K_f,b (``"per_load"``), or App. D's one factor K_f,t (``"single_kt"``)."""
        return self.kf_torsion if self.mode == "single_kt" else self.kf_bending

    def scale(self, component: str) -> float:
        """Factor on ``component``'s cycle ranges (drive side suffix allowed)."""
        if component.startswith("pinion_combined"):
            return self.combined_scale
        if component.startswith("pinion_bending"):
            return self.bending_scale
        return self.torsion_scale

    def describe(self, component: str) -> str:
        """The factors a component's damage carries, in words, e.g. "K_f 2.2 on bending, 2 on
        torsion"."""
        if component.startswith("pinion_combined") and self.mode == "per_load":
            return (
                f"K_f {self.kf_bending:g} on bending, {self.kf_torsion:g} on torsion{self._plane}"
            )
        if component.startswith("pinion_combined"):
            return f"K_f {self.kf_torsion:g} on the whole combined stress (App. D){self._plane}"
        if component.startswith("pinion_bending"):
            return f"K_f {self.bending_scale:g} on bending"
        return f"K_f {self.kf_torsion:g} on torsion"

    def combined_bound(self, sigma_b: float, tau: float) -> float:
        """The largest |combined stress| (MPa, with :attr:`combined_scale`) that nominal
        bending and shear stresses of at most ``sigma_b`` and ``tau`` (MPa) can give on any of
        :meth:`plane_angles_deg`."""
        out = 0.0
        for theta in self.plane_angles_deg():
            wb, wt = self.at(theta)._weights
            out = max(out, abs(wb) * sigma_b + abs(wt) * tau)
        return out * self.combined_scale

    @property
    def _plane(self) -> str:
        """The plane of the combined stress in words ("" at App. D's 45°)."""
        if self.critical_step_deg is not None:
            return f", on the critical plane (θ of most damage, {self.critical_step_deg:g}° grid)"
        theta = math.degrees(self.theta)
        return "" if self.theta == THETA_SEED else f", at θ = {theta:g}°"

    def summary(self) -> str:
        """Every component's factors in one phrase (reports' basis of the damage)."""
        return (
            f"{self.describe('pinion_combined')} in pinion_combined; "
            f"{self.describe('pinion_torsion')} in pinion_torsion and motor_torsion"
        )

    def as_dict(self) -> dict[str, float | str]:
        """Plain data: what a snapshot's damage was computed with (the factors used by
        :attr:`mode`, and the plane angle in degrees when it is not 45°, so that snapshots
        from before the angle was configurable still match)."""
        out: dict[str, float | str] = {"mode": self.mode, "kf_torsion": self.kf_torsion}
        if self.mode == "per_load":
            out = {"mode": self.mode, "kf_bending": self.kf_bending, "kf_torsion": self.kf_torsion}
        if self.critical_step_deg is not None:
            out["critical_step_deg"] = self.critical_step_deg
        elif self.theta != THETA_SEED:
            out["theta_deg"] = math.degrees(self.theta)
        return out

    def refusal(self, was: Mapping[str, Any] | None, scales: Collection[float]) -> str | None:
        """Why damage and rainflow residues computed with the factors ``was`` (a snapshot's
        :meth:`as_dict`) cannot continue under this model, naming the ``[shafts]`` values that
        would continue them; None when they can. ``was`` None: a snapshot from before the
        factors were recorded, App. D's one factor on every trace — its recorders' ``scales``
        (none: nothing analysed yet, nothing to refuse)."""
        if was is None:
            if not scales:
                return None
            was = {"mode": "single_kt", "kf_torsion": max(scales)}
        now = self.as_dict()
        if dict(was) == now:
            return None
        return (
            f"the snapshot's damage was computed with the stress concentration {_words(was)}, "
            f"the configuration now gives {_words(now)} ([shafts] of the mill file); to "
            f"continue from it, set {_settings(was, len(now) > len(_plain(now)))} in [shafts], or "
            "analyse the archive afresh "
            "with the new factors"
        )


def _plain(d: Mapping[str, Any]) -> dict[str, Any]:
    """Recorded factors without the plane (its keys exist only off App. D's 45°)."""
    return {k: v for k, v in d.items() if k not in ("theta_deg", "critical_step_deg")}


def _words(d: Mapping[str, Any]) -> str:
    """Recorded fatigue factors (and plane angle) in words."""
    theta = f" at θ = {d['theta_deg']:g}°" if "theta_deg" in d else ""
    if "critical_step_deg" in d:
        theta = f" on the critical plane ({d['critical_step_deg']:g}° grid)"
    if d["mode"] == "single_kt":
        return f"K_f {d['kf_torsion']:g} on the whole stress (App. D){theta}"
    return f"K_f {d['kf_bending']:g} on bending and {d['kf_torsion']:g} on torsion{theta}"


def _settings(d: Mapping[str, Any], angle: bool) -> str:
    """``[shafts]`` values (notch sensitivity 1) that give recorded fatigue factors (and the
    plane angle when it was not 45° or ``angle`` asks for it)."""
    angle = angle or "theta_deg" in d or "critical_step_deg" in d
    theta = f", plane_angle_deg = {d.get('theta_deg', 45.0):g}" if angle else ""
    if "critical_step_deg" in d:
        theta = (f', plane_angle_deg = "critical", critical_plane_step_deg = '
                 f"{d['critical_step_deg']:g}")  # fmt: skip
    if d["mode"] == "single_kt":
        return f'stress_concentration = "single_kt", kt_torsion = {d["kf_torsion"]:g}{theta}'
    return f"kt_bending = {d['kf_bending']:g}, kt_torsion = {d['kf_torsion']:g}{theta}"
