"""Stress, rainflow counting and Miner damage of the load stage, per damage component.

Components (Diering 2011 §8.1–8.2), per drive side, on the material's S-N curve, with the
fatigue factors of :mod:`analytics.drivetrain.shaft_stress` (``[shafts]`` of the mill file):
``pinion_combined`` (σ_θ at θ = 45°, eq. 12 with σ_y = 0: K_f,b·σ_b·(½ + ½cos 2θ) +
K_f,t·τ·sin 2θ; or App. D's one factor on the whole trace), ``pinion_torsion`` and
``motor_torsion`` (τ = 16T/(πd³), K_f,t). Each has one
:class:`~analytics.fatigue.rainflow.RainflowCounter` and one
:class:`~analytics.mill.phase_damage.PhaseDamage` that books its cycles by phase and local day.

NaN policy: for rainflow counting the last valid value is held across missing and flagged
samples (the counter sees the signal with the gap closed: a plateau has no reversal), and
samples before the first valid one are skipped (``lead`` counts them, so counter indices map
back to stream samples).

:class:`FatigueCounting` is the part of :class:`~analytics.mill.loads.LoadAnalysis` that owns
these (``counters``, ``damage``, ``lead``, ``last``) and their piece of the snapshot; the
phase timeline and how far the phases are decided are the caller's, passed in with every call.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from analytics.contracts import SnapshotMismatch
from analytics.drivetrain.mill_config import MillConfig
from analytics.drivetrain.stress import shear_stress_from_torque
from analytics.fatigue.miner import DamageRecorder
from analytics.fatigue.rainflow import RainflowCounter
from analytics.mill.app_d import AppDCost
from analytics.mill.load_roles import LoadRoles
from analytics.mill.phase_damage import PhaseDamage, PhaseTimeline
from analytics.mill.report import damage_table

__all__ = ["FatigueCounting"]


class FatigueCounting:
    """Rainflow counters and damage recorders of a mill's components (module docstring)."""

    CONFIGURED = frozenset({"config", "roles", "fs"})

    def __init__(self, config: MillConfig, roles: LoadRoles, fs: float) -> None:
        self.config = config
        self.roles = roles
        self.fs = fs
        self.counters = {c: RainflowCounter() for c in roles.components}
        self.damage: dict[str, PhaseDamage] = {}
        self.lead = dict.fromkeys(roles.components, 0)
        self.last = dict.fromkeys(roles.components, math.nan)

    def begin(self, t0_ns: int) -> None:
        """New damage recorders for a record whose sample 0 is at ``t0_ns`` (ns since the
        Unix epoch), on the material's S-N curve with each component's stress scale."""
        cfg, model = self.config, self.roles.stress_model
        curve = cfg.material.sn_curve()
        for c in self.roles.components:
            combined = c.startswith("pinion_combined")
            rec = DamageRecorder(
                curve, scale=model.combined_scale if combined else model.torsion_scale
            )
            self.damage[c] = PhaseDamage(rec, t0_ns, self.fs, cfg.time_zone)

    def stress(self, block: np.ndarray) -> dict[str, np.ndarray]:
        """Stress (MPa) of each component over a block of ring rows (NaN where missing)."""
        return self._stress(block)

    @property
    def recorders(self) -> dict[str, DamageRecorder]:
        """Each component's damage recorder (curve, stress scale), after :meth:`begin`."""
        return {c: pd.recorder for c, pd in self.damage.items()}

    def _stress(self, block: np.ndarray) -> dict[str, np.ndarray]:
        """Stress (MPa) of each component over a block of ring rows."""
        shafts, model, out = self.config.shafts, self.roles.stress_model, {}
        for k, side in enumerate(self.roles.sides):  # rows: speed, motor, pinion, bending/side
            sfx = f"_{side}" if side else ""
            tm, tp, sb = block[1 + 3 * k], block[2 + 3 * k], block[3 + 3 * k]  # missing: NaN
            tau_p = shear_stress_from_torque(tp, shafts.pinion_diameter_m)
            out[f"pinion_combined{sfx}"] = model.combined(sb, tau_p)
            out[f"pinion_torsion{sfx}"] = tau_p
            out[f"motor_torsion{sfx}"] = shear_stress_from_torque(tm, shafts.motor_diameter_m)
        return out

    def count(self, block: np.ndarray, timeline: PhaseTimeline, decided: int) -> None:
        """Count the block's cycles and book their damage (phases decided until ``decided``)."""
        for comp, x in self._stress(block).items():
            filled = self._hold(comp, x)
            cycles = self.counters[comp].feed(filled)
            self.damage[comp].record(cycles, timeline, decided, offset=self.lead[comp])

    def _hold(self, comp: str, x: np.ndarray) -> np.ndarray:
        """The NaN policy: hold the last valid value; skip samples before the first one."""
        ok = np.isfinite(x)
        if ok.all():
            self.last[comp] = float(x[-1])
            return x
        idx = np.where(ok, np.arange(x.shape[0]), -1)
        np.maximum.accumulate(idx, out=idx)
        if math.isnan(self.last[comp]):
            lead = int(np.count_nonzero(idx < 0))
            if self.counters[comp].samples_seen == 0:
                self.lead[comp] += lead
            out = x[idx[lead:]]
        else:
            out = np.where(idx >= 0, x[np.maximum(idx, 0)], self.last[comp])
        if out.size:
            self.last[comp] = float(out[-1])
        return out

    def oldest_needed(self, decided: int) -> int:
        """Oldest stream sample whose phase an open residue or a pending cycle still needs."""
        oldest = decided
        for comp, counter in self.counters.items():
            _, idx = counter.residue()
            if idx.size:
                oldest = min(oldest, int(idx[0]) + self.lead[comp])
            pending = self.damage[comp].oldest_pending
            if pending is not None:
                oldest = min(oldest, pending)
        return oldest

    def by_day(self, timeline: PhaseTimeline, decided: int) -> dict[str, Any]:
        """Attributed damage per component, local day and phase so far."""
        out = {}
        for comp, pd in self.damage.items():
            pd.attribute(timeline, decided)
            out[comp] = pd.days()
        return out

    def cycles_by_day(self, timeline: PhaseTimeline, decided: int) -> dict[str, Any]:
        """Attributed rainflow cycles per component, local day and phase (half cycles 0.5)."""
        out = {}
        for comp, pd in self.damage.items():
            pd.attribute(timeline, decided)
            out[comp] = pd.cycle_days()
        return out

    def summary(self) -> dict[str, dict[str, float]]:
        """Miner damage per component: ``committed``, ``pending_residue``, ``with_residue``."""
        out = {}
        for comp, pd in self.damage.items():
            committed = pd.committed
            with_residue = pd.with_residue(self.counters[comp].close())
            out[comp] = {
                "committed": committed,
                "pending_residue": with_residue - committed,
                "with_residue": with_residue,
            }
        return out

    def table(
        self,
        timeline: PhaseTimeline,
        decided: int,
        seconds: dict[str, float],
        starts_total: int,
        n: int,
        app_d: dict[str, AppDCost],
    ) -> dict[str, Any]:
        """:func:`~analytics.mill.report.damage_table` after ``n`` stream samples, the cycles
        of the decided phases attributed and the open residues closed (on copies), each
        component with the fatigue factors its stress carries in words (``stress_factors``)."""
        for pd in self.damage.values():
            pd.attribute(timeline, decided)
        residues = {c: k.close() for c, k in self.counters.items()}
        table = damage_table(self.damage, residues, seconds, starts_total, n / self.fs, app_d)
        for comp, row in table.items():
            row["stress_factors"] = self.roles.stress_model.describe(comp)
        return table

    def check(self, snapshot: dict[str, Any]) -> None:
        """:class:`SnapshotMismatch` when the snapshot's damage was computed with other fatigue
        factors (:meth:`~analytics.drivetrain.shaft_stress.ShaftStressModel.refusal`)."""
        scales = {d["recorder"]["scale"] for d in snapshot["damage"].values()}
        why = self.roles.stress_model.refusal(snapshot.get("stress"), scales)
        if why is not None:
            raise SnapshotMismatch(f"mill {self.config.id!r}: {why}")

    def snapshot(self) -> dict[str, Any]:
        """The counters' and recorders' state (plain JSON data)."""
        return {
            "lead": self.lead,
            "last": {k: repr(v) for k, v in self.last.items()},
            "counters": {c: k.snapshot() for c, k in self.counters.items()},
            "damage": {c: p.snapshot() for c, p in self.damage.items()},
        }

    def load(self, d: dict[str, Any]) -> None:
        """Set back what :meth:`snapshot` wrote."""
        self.lead = d["lead"]
        self.last = {k: float(v) for k, v in d["last"].items()}
        self.counters = {c: RainflowCounter.restore(s) for c, s in d["counters"].items()}
        self.damage = {c: PhaseDamage.restore(s) for c, s in d["damage"].items()}
