"""What each surface says about one scene, as a small typed table, and its comparison with
``millwatch analyze --json`` (the producer) for the parity test (issue 24, ``test_parity.py``).

A :class:`Figures` is one surface's answer: quantity → value. Quantities are named

=======================================  ==========================================================
``damage/<component>/<phase>``           committed Miner damage booked in a phase [1]
``damage/<component>/committed``         committed damage of all phases [1]
``damage/<component>/with_residue``      committed + the open rainflow residue as half cycles [1]
``seconds/<phase>``                      seconds in a phase (unknown, stopped, start, run, …) [s]
``start_cost/<component>/<figure>``      App. D's cost of a start (Diering 2011 App. D):
                                         ``damage_per_start`` [1], ``run_damage_per_hour`` [1/h]
``starts``                               successful starts
``steady/windows``                       steady-state windows (60 s of running each)
``steady/<k>/<channel>/range_per_rev``   window k (0 = first): range per revolution (Diering 2011
                                         App. C routine 4) [kN·m or MPa]
``steady/<k>/<channel>/range_pct``       the same of a torque channel, % of motor rated torque
``steady/latest/<channel>/…``            the same of the latest window
``steady/{max,mean}/<channel>/…``        over the windows (the report's daily table)
=======================================  ==========================================================

with ``<channel>`` as the surface names it: the mill file's channel names are the contract
(:func:`channel_names`), so a surface that renames a channel shows as a quantity missing here
and another one there. Each surface's collector says which quantities it renders
(:attr:`Figures.covers`); the expected table is the producer's figures restricted to them, and
:func:`mismatches` lists every quantity missing, extra or unequal, with both values. Equality
is exact unless the surface states a :class:`Tolerance` with its reason.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
import sqlite3
import zipfile
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from millwatch.analytics.drivetrain.mill_config import MillConfig

PHASE_OF_STATE = {
    "running": "run",
    "starting": "start",
    "stopping": "stop",
    "stopped": "stopped",
    "barring": "barring",
    "unknown": "unknown",
}
"""Operating state (Foxglove's ``/<mill>/state``) → the phase damage and seconds are booked in."""


@dataclass(frozen=True, slots=True)
class Tolerance:
    """How far a surface may be from the producer, and why (empty: exact)."""

    absolute: float = 0.0
    relative: float = 0.0
    why: str = ""

    def admits(self, want: float, got: float) -> bool:
        return abs(got - want) <= max(self.absolute, self.relative * abs(want))

    def __str__(self) -> str:
        bound = f"±{self.absolute:g}" if self.absolute else f"±{self.relative:g} relative"
        return f"tolerance {bound}: {self.why}" if self.why else "exact"


EXACT = Tolerance()


@dataclass(frozen=True, slots=True)
class Figures:
    """One surface's figures: ``values`` quantity → value (None: the surface shows no number,
    e.g. an OPC UA node with a Bad status); ``covers``: patterns (regular expressions, whole
    quantity) of the quantities it renders; ``tolerances``: (pattern, tolerance), the widest
    of those matching applies, exact when none does."""

    surface: str
    values: dict[str, float | None]
    covers: tuple[str, ...]
    tolerances: tuple[tuple[str, Tolerance], ...] = ()

    def renders(self, quantity: str) -> bool:
        return any(re.fullmatch(p, quantity) for p in self.covers)

    def tolerance(self, quantity: str) -> Tolerance:
        """The widest bounds of every tolerance whose pattern matches, with all their
        reasons (exact when none matches)."""
        found = [t for p, t in self.tolerances if re.fullmatch(p, quantity)]
        if not found:
            return EXACT
        return Tolerance(max(t.absolute for t in found), max(t.relative for t in found),
                         "; ".join(t.why for t in found))  # fmt: skip


@dataclass(frozen=True, slots=True)
class Mismatch:
    """A quantity on which a surface and the producer disagree (None: absent or no number)."""

    surface: str
    quantity: str
    want: float | None
    got: float | None
    allowed: Tolerance = field(default=EXACT)

    def line(self) -> str:
        want = "(absent)" if self.want is None else repr(self.want)
        got = "(absent)" if self.got is None else repr(self.got)
        diff = ""
        if self.want is not None and self.got is not None:
            diff = f"  diff {self.got - self.want:+.6g}"
        why = f"  ({self.allowed})" if self.allowed.why else ""
        return f"{self.surface:<28} {self.quantity:<44} analyze {want:<24} surface {got}{diff}{why}"


def mismatches(producer: Figures, surface: Figures) -> list[Mismatch]:
    """Every quantity ``surface`` renders on which it disagrees with ``producer``: missing,
    extra (a quantity the producer does not have, e.g. a channel under another name) or
    unequal beyond the surface's tolerance."""
    want = {q: v for q, v in producer.values.items() if surface.renders(q)}
    out = []
    for q in sorted(set(want) | set(surface.values)):
        a, b = want.get(q), surface.values.get(q)
        tol = surface.tolerance(q)
        if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
            if a != b:
                out.append(Mismatch(surface.surface, q, a, b, tol))
        elif not tol.admits(a, b):
            out.append(Mismatch(surface.surface, q, a, b, tol))
    return out


def table(problems: Iterable[Mismatch]) -> str:
    """A readable diff: one line per mismatch."""
    return "\n".join(m.line() for m in problems)


def matrix(producer: Figures, surfaces: Iterable[Figures]) -> str:
    """Every quantity (rows) in the producer and in each surface (columns, ``·``: not
    rendered there, ``-``: rendered but absent), as text to read or paste."""
    surfaces = list(surfaces)
    rows = sorted(set(producer.values).union(*(f.values for f in surfaces)))

    def cell(f: Figures, q: str) -> str:
        if q in f.values:
            v = f.values[q]
            return "-" if v is None else f"{v:.12g}"
        return "-" if f.renders(q) else "·"

    head = ["quantity", producer.surface, *(f.surface for f in surfaces)]
    body = [[q, cell(producer, q), *(cell(f, q) for f in surfaces)] for q in rows]
    widths = [max(len(r[i]) for r in [head, *body]) for i in range(len(head))]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in [head, *body]
    )


# ----------------------------------------------------------------------------- the producer
def channel_names(config: MillConfig) -> set[str]:
    """The mill file's names of the channels with steady-state figures (torque and bending)."""
    return {n for n, c in config.channels.items() if c.kind in ("torque", "bending")}


def analyze_figures(report: Mapping[str, Any]) -> Figures:
    """Everything ``millwatch analyze --json`` says about the four quantities."""
    values: dict[str, float | None] = {}
    for comp, d in report["damage"].items():
        values |= {f"damage/{comp}/{p}": v for p, v in d["phases"].items()}
        values[f"damage/{comp}/committed"] = d["committed"]
        values[f"damage/{comp}/with_residue"] = d["with_residue"]
        for f in START_COST:
            values[f"start_cost/{comp}/{f}"] = d["start_cost"][f]
    values |= {f"seconds/{p}": v for p, v in report["phase_seconds"].items()}
    values["starts"] = sum(not s["failed"] for s in report["starts"])
    values |= steady_figures(report["steady_state"])
    return Figures("millwatch analyze --json", values, (".*",))


START_COST = ("damage_per_start", "run_damage_per_hour")
"""App. D's cost of a start as ``analyze`` and the report's damage table state it."""


def steady_figures(
    windows: list[Mapping[str, Any]], *, summary: bool = True
) -> dict[str, float | None]:
    """Window count, each window's and the latest window's ranges, and (``summary``) their
    max and mean over the windows."""
    values: dict[str, float | None] = {"steady/windows": len(windows)}
    series: dict[str, list[float]] = defaultdict(list)
    for k, w in enumerate(windows):
        for kind in ("range_per_rev", "range_pct"):
            for ch, v in w[kind].items():
                values[f"steady/{k}/{ch}/{kind}"] = v
                if k == len(windows) - 1:
                    values[f"steady/latest/{ch}/{kind}"] = v
                series[f"{ch}/{kind}"].append(v)
    for name, vs in series.items() if summary else ():
        values[f"steady/max/{name}"] = max(vs)
        values[f"steady/mean/{name}"] = sum(vs) / len(vs)
    return values


def without_prior(figures: Figures, priors: Mapping[str, float]) -> Figures:
    """A surface that shows damage so far *including* the damage before monitoring (``/life``,
    OPC UA ``Damage``, ``millwatch_damage_ratio``) with that prior taken off again, ``priors``
    per component as ``/life`` states them (``damage_prior``, from the mill file's ``[life]``):
    exact to the rounding of the surface's sum (2 ulp of the prior; exact with no prior)."""
    values, tolerances = dict(figures.values), list(figures.tolerances)
    for q, v in figures.values.items():
        m = re.fullmatch(r"damage/([^/]+)/with_residue", q)
        prior = priors.get(m.group(1), 0.0) if m else 0.0
        if v is not None and prior:
            values[q] = v - prior
            why = f"shown as the prior damage {prior:g} + the monitored damage"
            tolerances.append((re.escape(q), Tolerance(absolute=2 * math.ulp(prior), why=why)))
    return Figures(figures.surface, values, figures.covers, tuple(tolerances))


def with_zero_phases(
    values: dict[str, float | None], phases: Iterable[str], components: Iterable[str]
) -> dict[str, float | None]:
    """A surface that lists only the phases with damage booked: the others are 0."""
    for c in components:
        for p in phases:
            values.setdefault(f"damage/{c}/{p}", 0.0)
    return values


# ----------------------------------------------------------------------------- the store file
def store_rows(path: Path, mill: str) -> dict[str, Any]:
    """What the store file holds of ``mill`` (read-only, plain SQL): damage per component and
    phase summed over the days, successful starts, the steady-state windows oldest first."""
    with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as db:
        damage = db.execute(
            "SELECT component, phase, damage FROM damage_daily WHERE mill_id = ? ORDER BY day",
            (mill,),
        ).fetchall()
        starts = db.execute(
            "SELECT count(*) FROM events WHERE mill_id = ? AND kind = 'start' "
            "AND NOT coalesce(json_extract(data_json, '$.failed'), 0)",
            (mill,),
        ).fetchone()[0]
        steady = db.execute(
            "SELECT data_json FROM records WHERE mill_id = ? AND kind = 'steady' ORDER BY t_ns",
            (mill,),
        ).fetchall()
    summed: dict[tuple[str, str], float] = defaultdict(float)
    for comp, phase, v in damage:
        summed[comp, phase] += v
    return {
        "damage": dict(summed),
        "starts": int(starts),
        "steady": [json.loads(s) for (s,) in steady],
    }


def store_figures(
    rows: Mapping[str, Any], seconds: Mapping[str, float], phases: Iterable[str]
) -> Figures:
    """The store's figures: ``rows`` from :func:`store_rows`, ``seconds`` the phase seconds
    as the store's one reading of them gives (``millwatch.reports.history.life_inputs``)."""
    values: dict[str, float | None] = {f"damage/{c}/{p}": v for (c, p), v in rows["damage"].items()}
    with_zero_phases(values, phases, {c for c, _ in rows["damage"]})
    values |= {f"seconds/{p}": v for p, v in seconds.items()}
    values["starts"] = rows["starts"]
    values |= steady_figures(rows["steady"], summary=False)
    return Figures(
        "SQLite store",
        values,
        (
            r"damage/[^/]+/(?!committed|with_residue)[^/]+",
            r"seconds/.*",
            "starts",
            r"steady/(\d+|latest)/.*",
            "steady/windows",
        ),
    )


# ----------------------------------------------------------------------------- the report CSV
def csv_tables(zip_path: Path) -> dict[str, list[dict[str, str]]]:
    """The monthly report's CSV tables: name (after ``<mill>-<month>-``) → rows."""
    out = {}
    with zipfile.ZipFile(zip_path) as z:
        for name in z.namelist():
            short = re.sub(r"^.*-\d{4}-\d{2}-", "", name).removesuffix(".csv")
            out[short] = list(csv.DictReader(io.StringIO(z.read(name).decode("utf-8"))))
    return out


def _column(row: Mapping[str, str], prefix: str) -> dict[str, float | None]:
    """Columns ``<prefix><name> [unit]`` of a row → name → number (None for empty)."""
    out: dict[str, float | None] = {}
    for key, text in row.items():
        if key.startswith(prefix):
            name = key[len(prefix) :].split(" [")[0]
            out[name] = _number(text)
    return out


def report_csv_figures(
    tables: Mapping[str, list[dict[str, str]]], phases: Iterable[str], bending: set[str]
) -> Figures:
    """The monthly report CSV's figures: ``damage`` (per component: each phase, the total, the
    running damage per hour — from which the run seconds follow), ``starts`` (one row a start)
    and ``steady_daily`` (windows, mean and max of the ranges per channel; one day here)."""
    values: dict[str, float | None] = {}
    for row in tables["damage"]:
        comp = row["component"]
        for p, v in _column(row, "damage_").items():
            if p != "per_start":
                values[f"damage/{comp}/{p}"] = v
        values[f"damage/{comp}/committed"] = float(row["damage [1]"])
        values[f"start_cost/{comp}/damage_per_start"] = _number(row["damage_per_start [1]"])
        values[f"start_cost/{comp}/run_damage_per_hour"] = _number(row["run_damage_per_hour [1/h]"])
    with_zero_phases(values, phases, [r["component"] for r in tables["damage"]])
    values["starts"] = sum(r["failed"] != "true" for r in tables["starts"])
    values |= _steady_daily(tables["steady_daily"])
    return Figures(
        "report CSV",
        values,
        (
            r"damage/[^/]+/(?!with_residue)[^/]+",
            r"start_cost/[^/]+/[^/]+",
            "starts",
            "steady/windows",
            r"steady/(max|mean)/[^/]+/range_pct",
            *(rf"steady/(max|mean)/{re.escape(b)}/range_per_rev" for b in bending),
        ),
        (
            (r"start_cost/.*", Tolerance(relative=8 * EPS, why=START_COST_SUM)),
            (r"steady/mean/.*", Tolerance(relative=1e-12, why=MEAN)),
            (r"damage/[^/]+/committed", Tolerance(relative=4 * EPS, why=TOTAL)),
        ),
    )


START_COST_SUM = (
    "the report sums its stops' App. D records, each rounded once when stored, then divides; "
    "analyze divides the exact sums: a few ulp"
)


def _number(text: str) -> float | None:
    return float(text) if text not in ("", "–") else None


MEAN = "the report's mean over the windows, summed in its own order"
EPS = 2.0**-52
TOTAL = (
    "the report's total is the exact sum of the stored per-phase, per-day values, each "
    "rounded once when stored; analyze rounds the exact sum of every cycle once: a few ulp"
)


def _steady_daily(rows: list[dict[str, str]]) -> dict[str, float | None]:
    """``steady_daily`` of one day: torque ranges in % rated, bending as amplitude (range/2)."""
    if len(rows) != 1:
        return {"steady/windows": sum(int(r["windows"]) for r in rows)}
    (row,) = rows
    values: dict[str, float | None] = {"steady/windows": int(row["windows"])}
    for stat in ("mean", "max"):
        for ch, v in _column(row, f"range_{stat}_").items():
            values[f"steady/{stat}/{ch}/range_pct"] = v
        for ch, v in _column(row, f"bending_{stat}_").items():
            values[f"steady/{stat}/{ch}/range_per_rev"] = None if v is None else 2.0 * v
    return values


# ----------------------------------------------------------------------------- /metrics
def metrics_figures(text: str, mill: str, bending: set[str]) -> Figures:
    """``/metrics`` of ``mill``: ``millwatch_damage_ratio`` (with residue; no prior here),
    ``millwatch_starts_this_month``, ``millwatch_oscillation_range_percent`` (range % rated of
    the latest window) and ``millwatch_bending_amplitude_megapascals`` (range per rev / 2)."""
    values: dict[str, float | None] = {}
    line = re.compile(r"^(millwatch_[a-z_]+)\{([^}]*)\} (\S+)$")
    for m in map(line.match, text.splitlines()):
        if m is None:
            continue
        labels = dict(re.findall(r'(\w+)="([^"]*)"', m.group(2)))
        if labels.get("mill") != mill:
            continue
        name, value = m.group(1), float(m.group(3))
        if name == "millwatch_damage_ratio":
            values[f"damage/{labels['component']}/with_residue"] = value
        elif name == "millwatch_starts_this_month":
            values["starts"] = value
        elif name == "millwatch_oscillation_range_percent":
            values[f"steady/latest/{labels['channel']}/range_pct"] = value
        elif name == "millwatch_bending_amplitude_megapascals":
            values[f"steady/latest/{labels['channel']}/range_per_rev"] = 2.0 * value
    covers = (
        r"damage/[^/]+/with_residue",
        "starts",
        r"steady/latest/[^/]+/range_pct",
        *(f"steady/latest/{re.escape(b)}/range_per_rev" for b in bending),
    )
    return Figures("/metrics", values, covers)


# ----------------------------------------------------------------------------- the REST API
def rest_figures(
    mill: Mapping[str, Any],
    life: Mapping[str, Any],
    starts: Mapping[str, Any],
    monthly: Mapping[str, Any],
    phases: Iterable[str],
    bending: set[str],
) -> list[Figures]:
    """The REST API's figures, one table per endpoint: ``/mills/{id}`` (live damage, latest
    steady window, starts this month), ``/life`` (damage by phase, monitored and total),
    ``/starts?month=`` and ``/reports/monthly?format=json`` (phase seconds, damage by phase,
    starts, every steady window)."""
    status = mill.get("status", {})
    live: dict[str, float | None] = {"starts": status.get("starts_this_month")}
    for comp, d in status.get("damage", {}).items():
        live[f"damage/{comp}/committed"] = d["committed"]
        live[f"damage/{comp}/with_residue"] = d["with_residue"]
    latest = status.get("latest_steady") or {}
    for kind in ("range_per_rev", "range_pct"):
        live |= {f"steady/latest/{ch}/{kind}": v for ch, v in latest.get(kind, {}).items()}
    phases = list(phases)
    by_phase: dict[str, float | None] = {}
    for comp, c in life.get("components", {}).items():
        by_phase |= {f"damage/{comp}/{p}": v for p, v in c["damage_by_phase"].items()}
        by_phase[f"damage/{comp}/committed"] = c["damage_monitored"]
        by_phase[f"damage/{comp}/with_residue"] = c["damage"]
    with_zero_phases(by_phase, phases, life.get("components", {}))
    month: dict[str, float | None] = {
        f"seconds/{p}": v for p, v in monthly["phase_seconds"].items()
    }
    for c in monthly["damage"]:
        month |= {f"damage/{c['component']}/{p}": v for p, v in c["per_phase"].items()}
        month[f"damage/{c['component']}/committed"] = c["total"]
    with_zero_phases(month, phases, [c["component"] for c in monthly["damage"]])
    month["starts"] = monthly["starts"]["count"]
    month |= _monthly_steady(monthly["steady"])
    return [
        Figures(
            "REST /mills/{id}",
            live,
            (r"damage/[^/]+/(committed|with_residue)", "starts", r"steady/latest/.*"),
        ),
        Figures("REST /mills/{id}/life", by_phase, (r"damage/.*",)),
        Figures("REST /mills/{id}/starts", {"starts": starts.get("count")}, ("starts",)),
        Figures(
            "REST /reports/monthly json",
            month,
            (
                r"seconds/.*",
                r"damage/[^/]+/(?!with_residue)[^/]+",
                "starts",
                "steady/windows",
                r"steady/\d+/[^/]+/range_pct",
                *(rf"steady/\d+/{re.escape(b)}/range_per_rev" for b in bending),
            ),
            ((r"damage/[^/]+/committed", Tolerance(relative=4 * EPS, why=TOTAL)),),
        ),
    ]


def _monthly_steady(steady: Mapping[str, Any]) -> dict[str, float | None]:
    values: dict[str, float | None] = {"steady/windows": steady["windows"]}
    for k, p in enumerate(steady["points"]):
        values |= {f"steady/{k}/{ch}/range_pct": v for ch, v in p["range_pct"].items()}
        values |= {
            f"steady/{k}/{ch}/range_per_rev": None if v is None else 2.0 * v
            for ch, v in p["bending_amplitude_mpa"].items()
        }
    return values


# ----------------------------------------------------------------------------- OPC UA
async def opcua_figures(endpoint: str, site: str, mill: str) -> Figures:
    """OPC UA (anonymous, read only): ``Components/<c>/Damage`` (with residue, as ``/life``),
    ``StartsThisMonth`` and ``SteadyState/<channel>/{RangePerRev,RangePct}`` of every
    channel the server lists; a node with a Bad status is a value of None."""
    from asyncua import Client, ua  # imported here: only this collector needs it

    async with Client(endpoint, timeout=10) as client:
        ns = await client.get_namespace_index("urn:millwatch")
        node = lambda path: client.get_node(ua.NodeId(f"{site}/{mill}/{path}", ns))  # noqa: E731

        async def value(path: str) -> float | None:
            dv = await node(path).read_data_value(raise_on_bad_status=False)
            return None if not dv.StatusCode.is_good() else float(dv.Value.Value)

        values: dict[str, float | None] = {"starts": await value("StartsThisMonth")}
        for child in await node("Components").get_children():
            comp = (await child.read_browse_name()).Name
            values[f"damage/{comp}/with_residue"] = await value(f"Components/{comp}/Damage")
        for child in await node("SteadyState").get_children():
            ch = (await child.read_browse_name()).Name
            if await child.read_node_class() != ua.NodeClass.Object:
                continue  # Time, SpeedPct, ImbalancePct
            values[f"steady/latest/{ch}/range_per_rev"] = await value(
                f"SteadyState/{ch}/RangePerRev"
            )
            values[f"steady/latest/{ch}/range_pct"] = await value(f"SteadyState/{ch}/RangePct")
    return Figures("OPC UA", values, (r"damage/[^/]+/with_residue", "starts", r"steady/latest/.*"))


# ----------------------------------------------------------------------------- Foxglove export
def foxglove_figures(export: Mapping[str, list[tuple[Any, ...]]], mill: str) -> Figures:
    """The Foxglove export (``read_export`` of ``tests.service.export.recorded``): the last
    ``/<mill>/damage/<c>`` message (committed, with residue), seconds per phase from the
    ``/<mill>/state`` changes up to the span end (the last damage message, at the end of the
    span), and the successful starts of ``/<mill>/events``."""
    values: dict[str, float | None] = {}
    end = 0
    for topic, msgs in export.items():
        if topic.startswith(f"/{mill}/damage/"):
            comp, (_, t, _, last) = topic.rsplit("/", 1)[1], msgs[-1]
            values[f"damage/{comp}/committed"] = last.committed
            values[f"damage/{comp}/with_residue"] = last.with_residue
            end = max(end, t)
    changes = [(t, d.value) for _, t, _, d in export.get(f"/{mill}/state", [])]
    ns: dict[str, int] = defaultdict(int)
    for (t, state), (t_next, _) in zip(changes, [*changes[1:], (end, "")], strict=True):
        ns[PHASE_OF_STATE.get(state, state)] += t_next - t
    values |= {f"seconds/{p}": v / 1e9 for p, v in ns.items()}
    for p in PHASE_OF_STATE.values():
        values.setdefault(f"seconds/{p}", 0.0)
    events = [
        {kv.key: kv.value for kv in d.metadata} for *_, d in export.get(f"/{mill}/events", [])
    ]
    values["starts"] = sum(e.get("event") == "start" and e.get("failed") != "True" for e in events)
    return Figures(
        "Foxglove export",
        values,
        (r"damage/[^/]+/(committed|with_residue)", r"seconds/.*", "starts"),
    )
