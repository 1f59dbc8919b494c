"""The monthly damage report's tables as CSV (seed 000 §10.6 "automatic reports").

Two tables, each a plain CSV document with a header row (RFC 4180, ``\\r\\n`` line ends):

* ``starts``: one row per switch-on (local time, UTC ns, failed, peaks in % of rated motor
  torque, rise time, acceleration time, status against the start-peak levels);
* ``damage``: one row per local day, component and phase (Miner damage; days without damage
  are not listed, the daily rows sum to the month's totals of the report).

:func:`render_csv` joins them into one document with a ``# table`` comment line before each,
for the API's ``format=csv``; :func:`starts_csv` / :func:`damage_csv` give one table each.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence

from service.reports.monthly import MonthlyReport

__all__ = ["CSV_TABLES", "damage_csv", "render_csv", "starts_csv"]

STARTS_HEADER = ("local_time", "t_ns", "failed", "switch_on_pct", "short_circuit_pct",
                 "pinion_switch_on_pct", "rise_10_90_ms", "accel_s", "status")  # fmt: skip
DAMAGE_HEADER = ("day", "component", "phase", "damage")


def _csv(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(header)
    writer.writerows(["" if v is None else v for v in row] for row in rows)
    return buf.getvalue()


def starts_csv(r: MonthlyReport) -> str:
    """One row per start of the month."""
    return _csv(
        STARTS_HEADER,
        ([s.local_time, s.t_ns, int(s.failed), s.switch_on_pct, s.short_circuit_pct,
          s.pinion_switch_on_pct, s.rise_10_90_ms, s.accel_s, s.status]
         for s in r.starts.starts),
    )  # fmt: skip


def damage_csv(r: MonthlyReport) -> str:
    """One row per day, component and phase (``repr`` floats: full precision)."""
    return _csv(
        DAMAGE_HEADER,
        ([day, c.component, phase, repr(d)]
         for c in r.damage for day, phases in c.per_day.items() for phase, d in phases.items()),
    )  # fmt: skip


CSV_TABLES = {"starts": starts_csv, "damage": damage_csv}


def render_csv(r: MonthlyReport) -> str:
    """Both tables in one document: ``# <table>`` line, then the table, then a blank line."""
    head = f"# millwatch monthly report: mill {r.mill}, site {r.site}, month {r.month}\r\n"
    return head + "".join(f"# {name}\r\n{fn(r)}\r\n" for name, fn in CSV_TABLES.items())
