"""Stress, rainflow counting and Miner damage of the load stage, per damage component.

Components (Diering 2011 §8.1–8.2), per drive side, each on its S-N curve and mean-stress
correction (``[material.components.<kind>]``, else the material's ``[material.sn]``, no
correction), with the fatigue factors of :mod:`millwatch.analytics.drivetrain.shaft_stress`
(``[shafts]``
of the mill file): ``pinion_combined`` (σ_θ at θ = ``plane_angle_deg``, default 45°, eq. 12 with
σ_y = 0: K_f,b·σ_b·(½ + ½cos 2θ) + K_f,t·τ·sin 2θ; or App. D's one factor on the whole trace),
``pinion_torsion`` and ``motor_torsion`` (τ = 16T/(πd³), K_f,t), and — only when the mill file
configures it — ``pinion_bending`` (σ_b alone, App. D §3). On the critical plane
(``plane_angle_deg = "critical"``) the combined stress is counted on every θ of the grid, as
traces ``pinion_combined@<θ>``, and each answer reports the one with the most committed damage
(its θ in the damage table's ``plane_angle_deg``). Each counted trace has one
:class:`~millwatch.analytics.fatigue.rainflow.RainflowCounter` and one
:class:`~millwatch.analytics.mill.phase_damage.PhaseDamage` that books its cycles by phase and
local day.

NaN policy: for rainflow counting the last valid value is held across missing and flagged
samples (the counter sees the signal with the gap closed: a plateau has no reversal), and
samples before the first valid one are skipped (``lead`` counts them, so counter indices map
back to stream samples).

:class:`FatigueCounting` is the part of :class:`~millwatch.analytics.mill.loads.LoadAnalysis` that
owns these (``counters``, ``damage``, ``lead``, ``last``) and their piece of the snapshot; the
phase timeline and how far the phases are decided are the caller's, passed in with every call.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

from millwatch.analytics.contracts import SnapshotMismatch
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.stress import shear_stress_from_torque
from millwatch.analytics.fatigue.cycle_log import CycleLog
from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.fatigue.miner import DamageRecorder
from millwatch.analytics.fatigue.rainflow import RainflowCounter
from millwatch.analytics.mill.app_d import AppDCost
from millwatch.analytics.mill.cycle_matrix import CycleMatrixDays, matrix_edges
from millwatch.analytics.mill.load_roles import LoadRoles
from millwatch.analytics.mill.phase_damage import BATCH, PhaseDamage, PhaseTimeline
from millwatch.analytics.mill.report import damage_table

__all__ = ["FatigueCounting"]

T = TypeVar("T")


class FatigueCounting:
    """Rainflow counters and damage recorders of a mill's components (module docstring)."""

    #: ``cycle_log``: the caller's record of the cycles (an offline analysis), not state.
    CONFIGURED = frozenset({"config", "roles", "fs", "cycle_log", "damage_batch"})

    def __init__(self, config: MillConfig, roles: LoadRoles, fs: float) -> None:
        self.config = config
        self.roles = roles
        self.fs = fs
        keys = self.keys()
        self.counters = {c: RainflowCounter() for c in keys}
        self.damage: dict[str, PhaseDamage] = {}
        self.lead = dict.fromkeys(keys, 0)
        self.last = dict.fromkeys(keys, math.nan)
        #: A whole record's cycles (matrices, or every cycle), when a caller asks for them
        #: before the first sample (:meth:`logged`).
        self.cycle_log: CycleLog | None = None
        #: Raw cycles each damage recorder holds before costing them in one pass
        #: (:data:`millwatch.analytics.mill.phase_damage.BATCH`; results do not depend on it).
        self.damage_batch = BATCH

    def keys(self) -> list[str]:
        """The counted traces: each component, the combined one on every plane of the critical
        plane search as ``<component>@<θ in degrees>``."""
        model = self.roles.stress_model
        out = []
        for c in self.roles.components:
            if c.startswith("pinion_combined") and model.critical_step_deg is not None:
                out += [f"{c}@{t:g}" for t in model.plane_angles_deg()]
            else:
                out.append(c)
        return out

    def chosen(self) -> dict[str, str]:
        """Each component's counted trace: itself, or on the critical plane the plane with the
        most committed damage so far (ties: the plane nearest 45°, App. D's)."""
        out: dict[str, str] = {}
        for key in sorted(self.damage, key=_from_45):
            comp = key.split("@")[0]
            best = out.get(comp)
            if best is None or self.damage[key].committed > self.damage[best].committed:
                out[comp] = key
        return {c: out[c] for c in self.roles.components if c in out}

    def pick(self, per_trace: Mapping[str, T]) -> dict[str, T]:
        """Per component, the value of its counted trace (:meth:`chosen`) from a mapping keyed
        by trace (e.g. App. D's costs, counted on every plane of a critical plane search)."""
        chosen = self.chosen()
        keys = {c: chosen.get(c, c) for c in self.roles.components}
        return {c: per_trace[k] for c, k in keys.items() if k in per_trace}

    def reported(self) -> dict[str, PhaseDamage]:
        """The damage recorder of each component (:meth:`chosen`)."""
        return {c: self.damage[k] for c, k in self.chosen().items()}

    def begin(self, t0_ns: int) -> None:
        """New damage recorders for a record whose sample 0 is at ``t0_ns`` (ns since the
        Unix epoch): each component on its own S-N curve and mean-stress correction
        (``[material.components]``, else the material's curve) with its stress scale."""
        cfg, model = self.config, self.roles.stress_model
        bounds = cfg.stress_bounds()
        for key in self.keys():
            c = key.split("@")[0]
            rec = DamageRecorder(
                cfg.material.sn_curve(c),
                scale=model.scale(c),
                mean_correction=cfg.material.mean_correction(c),
            )
            bound = bounds.get(c)
            matrices = None if bound is None else CycleMatrixDays(*matrix_edges(bound))
            self.damage[key] = PhaseDamage(
                rec, t0_ns, self.fs, cfg.time_zone, matrices=matrices, batch=self.damage_batch
            )
            if self.cycle_log is not None and bound is not None:  # the whole record's matrix
                self.cycle_log.bin(key, RangeMeanMatrix(*matrix_edges(bound)), rec.scale)

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
            if model.critical_step_deg is None:
                out[f"pinion_combined{sfx}"] = model.combined(sb, tau_p)
            else:
                for theta in model.plane_angles_deg():
                    out[f"pinion_combined{sfx}@{theta:g}"] = model.at(theta).combined(sb, tau_p)
            out[f"pinion_torsion{sfx}"] = tau_p
            out[f"motor_torsion{sfx}"] = shear_stress_from_torque(tm, shafts.motor_diameter_m)
            if f"pinion_bending{sfx}" in self.counters:
                out[f"pinion_bending{sfx}"] = sb
        return out

    def count(self, block: np.ndarray, timeline: PhaseTimeline, decided: int) -> None:
        """Count the block's cycles and book their damage (phases decided until ``decided``)."""
        for comp, x in self._stress(block).items():
            filled = self._hold(comp, x)
            cycles = self.counters[comp].feed(filled)
            self.damage[comp].record(cycles, timeline, decided, offset=self.lead[comp])
            if self.cycle_log is not None:
                self.cycle_log.record(comp, cycles, offset=self.lead[comp])

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

    def logged(self, component: str) -> tuple[Cycles | None, RangeMeanMatrix | None, float]:
        """What :attr:`cycle_log` recorded of ``component``'s counted trace (:meth:`chosen`):
        its cycles (None when the log keeps none; stream sample indices, MPa of the counted
        stress), its whole-record range–mean matrix (None without a stress bound) and the
        stress factor (``scale``: K_t or the fatigue factors) the matrix and the damage apply."""
        if self.cycle_log is None:
            raise RuntimeError("cycles are recorded only when asked for before the first sample")
        key = self.chosen().get(component)
        if key is None:
            raise ValueError(f"no component {component!r}: this mill counts "
                             f"{', '.join(self.roles.components)}")  # fmt: skip
        log = self.cycle_log
        cycles = log.cycles(key) if log.keep_cycles else None
        return cycles, log.matrix(key), self.damage[key].recorder.scale

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
        for pd in self.damage.values():
            pd.attribute(timeline, decided)
        return {comp: pd.days() for comp, pd in self.reported().items()}

    def cycles_by_day(self, timeline: PhaseTimeline, decided: int) -> dict[str, Any]:
        """Attributed rainflow cycles per component, local day and phase (half cycles 0.5)."""
        for pd in self.damage.values():
            pd.attribute(timeline, decided)
        return {comp: pd.cycle_days() for comp, pd in self.reported().items()}

    def matrices_by_day(self, timeline: PhaseTimeline, decided: int) -> dict[str, Any]:
        """Range-mean matrices of the attributed cycles per component, local day and phase (the
        last days kept; :mod:`millwatch.analytics.mill.cycle_matrix`), components without one left
        out."""
        for pd in self.damage.values():
            pd.attribute(timeline, decided)
        out = {comp: pd.matrix_days() for comp, pd in self.reported().items()}
        return {comp: m for comp, m in out.items() if m is not None}

    def summary(self) -> dict[str, dict[str, float]]:
        """Miner damage per component: ``committed``, ``pending_residue``, ``with_residue``."""
        out = {}
        for comp, key in self.chosen().items():
            pd = self.damage[key]
            committed = pd.committed
            with_residue = pd.with_residue(self.counters[key].close())
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
        """:func:`~millwatch.analytics.mill.report.damage_table` after ``n`` stream samples, the
        cycles of the decided phases attributed and the open residues closed (on copies), each
        component with the fatigue factors its stress carries in words (``stress_factors``)."""
        for pd in self.damage.values():
            pd.attribute(timeline, decided)
        chosen = self.chosen()
        residues = {c: self.counters[k].close() for c, k in chosen.items()}
        table = damage_table(
            self.reported(), residues, seconds, starts_total, n / self.fs, self.pick(app_d)
        )
        for comp, row in table.items():
            row["stress_factors"] = self.roles.stress_model.describe(comp)
            if "@" in chosen[comp]:
                row["plane_angle_deg"] = float(chosen[comp].split("@")[1])
        return table

    def check(self, snapshot: dict[str, Any]) -> None:
        """:class:`SnapshotMismatch` when the snapshot's damage was computed with other fatigue
        factors (:meth:`~millwatch.analytics.drivetrain.shaft_stress.ShaftStressModel.refusal`)."""
        scales = {d["recorder"]["scale"] for d in snapshot["damage"].values()}
        why = self.roles.stress_model.refusal(snapshot.get("stress"), scales)
        if why is None:
            why = self._fatigue_refusal(snapshot["damage"])
        if why is not None:
            raise SnapshotMismatch(f"mill {self.config.id!r}: {why}")

    def _fatigue_refusal(self, damage: dict[str, Any]) -> str | None:
        """Why recorders snapshotted with other components, S-N curves or mean-stress
        corrections (``[material]`` of the mill file) cannot continue; None when they can."""
        if damage and set(damage) != set(self.keys()):
            return (
                f"the snapshot holds the components {', '.join(sorted(damage))}, the "
                f"configuration gives {', '.join(sorted(self.keys()))} "
                "([material.components] of the mill file); analyse the archive afresh"
            )
        material = self.config.material
        for key, d in sorted(damage.items()):
            comp = key.split("@")[0]
            was, now = d["recorder"], material.sn_curve(comp).to_dict()
            correction = material.mean_correction(comp)
            now_mc = None if correction is None else correction.to_dict()
            if was["curve"] != now or was["mean_correction"] != now_mc:
                return (
                    f"{comp}'s damage was computed on the S-N curve {was['curve']['name']!r} "
                    f"with mean-stress correction {_mc_words(was['mean_correction'])}, the "
                    f"configuration now gives {now['name']!r} with {_mc_words(now_mc)} "
                    "([material.sn] and [material.components] of the mill file); restore the "
                    "file's earlier values, or analyse the archive afresh"
                )
        return None

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
        for pd in self.damage.values():
            pd.batch = self.damage_batch
        self._add_matrices()

    def _add_matrices(self) -> None:
        """Range-mean matrices for recorders restored from a checkpoint written before they
        were kept (its pending cycles stay out of them; the cycles counted from now on go in)."""
        bounds = self.config.stress_bounds()
        for key, pd in self.damage.items():
            bound = bounds.get(key.split("@")[0])
            if pd.matrices is None and bound is not None:
                pd.matrices = CycleMatrixDays(*matrix_edges(bound))


def _mc_words(correction: dict[str, Any] | None) -> str:
    """A recorded mean-stress correction in words."""
    return "none" if correction is None else f"Goodman (S_ut {correction['S_ut']:g} MPa)"


def _from_45(key: str) -> float:
    """How far a counted trace's plane lies from 45° (0 for a trace without a plane)."""
    return abs(float(key.split("@")[1]) - 45.0) if "@" in key else 0.0
