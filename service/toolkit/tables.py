"""The DataFrames of the notebook API, built from the typed results, generically.

Each table is made from a typed model's fields (pydantic ``model_fields``, dataclass fields), so
a field added to a model — e.g. to the start record — appears as a column without a change
here. Times become UTC ``pandas.Timestamp`` columns (``t``) beside the ``*_ns`` integers.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from pydantic import BaseModel

from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.results import (
    BarringEvent,
    ComponentCycles,
    StartEvent,
    SteadyWindowResult,
    StopEvent,
)
from millwatch.analytics.spectra.facts import LineMeasurement
from millwatch.toolkit.report import DamageRow

__all__ = [
    "cycles_table",
    "damage_table",
    "damage_totals_table",
    "events_table",
    "harmonics_table",
    "matrix_table",
    "steady_table",
    "utc",
]

_SCALARS = (int, float, bool, str, type(None))


def utc(t_ns: Any) -> Any:
    """ns since the Unix epoch → UTC pandas timestamps (one, or a DatetimeIndex of many)."""
    return pd.to_datetime(t_ns, unit="ns", utc=True)


def scalar_fields(model: type[BaseModel]) -> list[str]:
    """The fields of ``model`` that hold one number, flag or word (optional or not)."""
    out = []
    for name, info in model.model_fields.items():
        ann = info.annotation
        union = typing.get_origin(ann) in (typing.Union, types.UnionType)
        args = typing.get_args(ann) if union else (ann,)
        if all(a in _SCALARS for a in args):
            out.append(name)
    return out


def events_table(events: Sequence[StartEvent | StopEvent | BarringEvent]) -> pd.DataFrame:
    """One row per event in the given order: ``kind`` (start, stop, trip or barring), ``t``
    (UTC), then every scalar field of its typed record (numbers, flags, words such as
    ``alarm``); a field one kind lacks is missing (NaN/None) in the others' rows."""
    rows = []
    for e in events:
        kind = e.kind if isinstance(e, StopEvent) else e.event
        fields = [f for f in scalar_fields(type(e)) if f not in ("kind", "event")]
        rows.append({"kind": kind, "t": utc(e.t_ns), **{f: getattr(e, f) for f in fields}})
    return pd.DataFrame(rows, columns=None if rows else ["kind", "t"])


def damage_table(damage: dict[str, DamageRow]) -> pd.DataFrame:
    """Committed damage of the attributed cycles, per component (rows) × phase (columns)."""
    out = pd.DataFrame({c: row.phases for c, row in damage.items()}).T
    out.index.name, out.columns.name = "component", "phase"
    return out.astype(np.float64)


def damage_totals_table(damage: dict[str, DamageRow]) -> pd.DataFrame:
    """Per component: ``committed``, ``pending_residue``, ``with_residue`` (Miner sums)."""
    cols = ["committed", "pending_residue", "with_residue"]
    out = pd.DataFrame(
        [[getattr(row, c) for c in cols] for row in damage.values()], index=list(damage),
        columns=cols,
    )  # fmt: skip
    out.index.name = "component"
    return out


def steady_table(windows: Sequence[SteadyWindowResult], fs: float) -> pd.DataFrame:
    """One row per steady-state window: ``t`` and ``t_end`` (UTC), its scalar fields, and each
    per-channel field as ``<field>.<channel>`` (e.g. ``range_pct.motor_torque``)."""
    rows = []
    for w in windows:
        row: dict[str, Any] = {
            "t": utc(w.t_ns), "t_end": utc(w.t_ns + round((w.end_sample - w.sample) * 1e9 / fs))
        }  # fmt: skip
        for name, value in w:
            if isinstance(value, dict):
                row |= {f"{name}.{ch}": v for ch, v in value.items()}
            else:
                row[name] = value
        rows.append(row)
    return pd.DataFrame(rows, columns=None if rows else ["t", "t_end"])


def harmonics_table(lines: Sequence[LineMeasurement]) -> pd.DataFrame:
    """One row per channel and expected line, the columns the measurement's fields."""
    names = [f.name for f in dataclasses.fields(LineMeasurement)]
    return pd.DataFrame([dataclasses.astuple(m) for m in lines], columns=names)


def cycles_table(c: ComponentCycles) -> pd.DataFrame:
    """``range`` and ``mean`` (MPa), ``count`` (1 or 0.5) and ``t`` (UTC) of each cycle."""
    return pd.DataFrame(
        {"range": c.range_mpa, "mean": c.mean_mpa, "count": c.count, "t": utc(c.t_ns)}
    )


def matrix_table(m: RangeMeanMatrix) -> pd.DataFrame:
    """The matrix as cycles (half cycles count 0.5): rows the range bins, columns the mean
    bins (MPa, ``[lo, hi)`` intervals; the first and last of each axis are the under- and
    overflow bins, to ∓inf)."""

    def axis(edges: np.ndarray, name: str) -> pd.IntervalIndex:
        breaks = np.concatenate([[-np.inf], edges, [np.inf]])
        return pd.IntervalIndex.from_breaks(breaks, closed="left", name=name)

    return pd.DataFrame(
        m.half_cycles / 2.0, index=axis(m.range_edges, "range"), columns=axis(m.mean_edges, "mean")
    )
