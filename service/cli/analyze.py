"""``millwatch analyze``: offline analysis of an archive with the analyzer the live worker runs.

Reads MCAP files, or every ``*.mcap`` file of a directory in name order (rotated archive files
sort by time), as the worker's recovery replays them
(:mod:`millwatch.worker.offline_analysis`: batches, admission by sequence number, calibration,
aligned frames) into one :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer` per mill given:
operating states, starts (switch-on and short-circuit peaks, rise times), stops, barring,
starts per month against the norm (Diering 2011 §6.1.3), steady-state metrics, fatigue damage per
component and phase (§8.2, App. D), harmonics (§6.2.7) and the alarms they raise.

Output: a human summary (damage as closed cycles by phase + open residue = total), or
``--json`` with the whole report (one mill: the report; several: ``{"mills": [...]}``) and a
``reading`` part that counts what reading met (repeats, gaps, malformed blocks, foreign keys,
torn file tails). Mills are split over processes with ``--jobs``; a progress bar shows on a
terminal. Unreadable files are named.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import multiprocessing
import os
import queue
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

from millwatch.alarms.from_analysis import report_observations
from millwatch.alarms.report import alarms_for_report
from millwatch.alarms.times import iso_local
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.cli.args import mill_option
from millwatch.ingest import wire
from millwatch.ingest.archive.reader import RawMessage
from millwatch.worker.admission import BlockAdmission
from millwatch.worker.offline_analysis import ReadingStats, analyze_files

__all__ = [
    "add_parser",
    "analyze_recording",
    "json_body",
    "mill_result",
    "plan_jobs",
    "recording_files",
    "run_jobs",
]

log = logging.getLogger(__name__)


def recording_files(path: Path) -> list[Path]:
    """The MCAP files of ``path`` (a file, or a directory's ``*.mcap`` in name order)."""
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if not files:
            raise ValueError(f"RECORDING {path}: directory holds no .mcap files")
        return files
    if not path.is_file():
        raise ValueError(f"RECORDING {path}: no such file or directory")
    return [path]


class _Blocks:
    """The Foxglove export's admission of one mill's archive messages, as analyze admits them
    (:class:`~millwatch.worker.admission.BlockAdmission`): ``(channel, block)`` of a new
    block, None for anything else (counted)."""

    def __init__(self, config: MillConfig) -> None:
        self.admission = BlockAdmission([config], replayed=True, warn_foreign=False)

    def admit(self, msg: RawMessage) -> tuple[str, wire.Block] | None:
        got = self.admission.admit(msg.key, msg.payload, msg.log_time_ns)
        return None if got is None else (got.channel, got.block)


def analyze_recording(
    files: list[Path], config: MillConfig, *, progress: bool = False, spectra: bool = True
) -> tuple[MillAnalyzer, dict[str, Any]]:
    """Run the mill analyzer over the recording (one process); returns it and reading
    statistics (:func:`millwatch.worker.offline_analysis.analyze_files`)."""
    total = sum(p.stat().st_size for p in files)
    with _bar(total, config.id, progress) as bar:
        sink, read = analyze_files(files, [config], spectra=spectra, advance=bar.update)
    return sink.analyzers[config.id], _stats(read, sink.reading(config.id))


def _bar(total: int, desc: str, show: bool) -> Any:
    return tqdm(total=total, unit="B", unit_scale=True, disable=not show, file=sys.stderr,
                desc=f"analyze {desc}", smoothing=0.05)  # fmt: skip


def _stats(read: ReadingStats, mill: dict[str, Any]) -> dict[str, Any]:
    """The ``reading`` part of a mill's report: the recording's counts and the mill's own."""
    return {
        "files": read.files,
        "malformed_blocks": dict(read.malformed_blocks),
        "foreign_blocks": read.foreign_blocks,
        "unreadable_tails": read.unreadable_tails,
        **mill,
        "dropped_blocks": mill["late_blocks"],
    }


# ---------------------------------------------------------------- jobs
@dataclass(frozen=True)
class _Job:
    """One process's share: its mills, the files it reads (and whether it counts the blocks
    of no given mill in each: exactly one job does per file) and the analysis options."""

    configs: list[MillConfig]
    files: list[tuple[Path, bool]]
    spectra: bool
    background: bool = False  # the spectra of each mill on a thread of its own
    matrices: bool = False  # each report with its range–mean matrices (for --plots)
    others: list[MillConfig] = field(default_factory=list)  # given mills other jobs analyse


def plan_jobs(files: list[Path], configs: list[MillConfig], jobs: int, *,
              spectra: bool = True, cores: int | None = None,
              matrices: bool = False) -> list[_Job]:  # fmt: skip
    """Split the mills over at most ``jobs`` processes, balanced by the bytes of the files
    named after each mill (``<mill id>_…``, as ``millwatch simulate --out DIR`` writes them);
    such a file is read only by the job with its mill, any other file by every job. With
    fewer mills than ``cores`` (default: this machine's), each mill's spectra run on a thread
    of their own."""
    ids = sorted((c.id for c in configs), key=len, reverse=True)  # longest prefix wins

    def owner(path: Path) -> str | None:
        return next((m for m in ids if path.name.startswith(f"{m}_")), None)

    own = {p: owner(p) for p in files}
    weight = {c.id: sum(p.stat().st_size for p, m in own.items() if m == c.id) for c in configs}
    groups: list[list[MillConfig]] = [[] for _ in range(max(1, min(jobs, len(configs))))]
    load = [0] * len(groups)
    for c in sorted(configs, key=lambda c: (-weight[c.id], c.id)):
        k = load.index(min(load))
        groups[k].append(c)
        load[k] += weight[c.id] or 1
    plan = []
    counted: set[Path] = set()
    # a core left over for each mill's spectra: a thread of their own (same results)
    background = spectra and len(configs) < (cores or os.cpu_count() or 1)
    for group in groups:
        mine = {c.id for c in group}
        reads = [p for p in files if own[p] is None or own[p] in mine]
        reads_of = [(p, p not in counted) for p in reads]
        others = [c for c in configs if c.id not in mine]  # their blocks are not foreign
        plan.append(_Job(group, reads_of, spectra, background, matrices, others))
        counted.update(reads)
    return plan


def _run_job(job: _Job, advance: Any) -> dict[str, Any]:
    """One job in this process: its mills' reports (plain data) and what reading met."""
    sink, read = analyze_files(
        [p for p, _ in job.files], job.configs, spectra=job.spectra, advance=advance,
        uncounted=frozenset(p for p, counts in job.files if not counts),
        background=job.background, others=job.others,
    )  # fmt: skip
    try:
        reports = {
            mill_id: (analyzer.report(), sink.reading(mill_id))
            for mill_id, analyzer in sink.analyzers.items()
            if analyzer.samples
        }
        if job.matrices:
            for mill_id, (report, _) in reports.items():
                report["cycle_matrices"] = sink.analyzers[mill_id].cycle_matrices_by_day()
    finally:
        sink.close()
    return {"reports": reports, "reading": read}


def _job_process(index: int, job: _Job, out: Any) -> None:
    """Entry of a job process: runs :func:`_run_job`, sends progress and the result."""
    try:
        out.put(("done", index, _run_job(job, lambda n: out.put(("bytes", index, n)))))
    except BaseException as exc:  # reported to the parent, which names the job's mills
        out.put(("error", index, str(exc) if isinstance(exc, ValueError) else repr(exc)))


def run_jobs(plan: list[_Job], *, progress: bool) -> list[dict[str, Any]]:
    """Run the plan: in this process for one job, else one process per job (``spawn``: no
    state is inherited), with one progress bar over every job's bytes."""
    total = sum(p.stat().st_size for job in plan for p, _ in job.files)
    desc = plan[0].configs[0].id if len(plan) == 1 and len(plan[0].configs) == 1 else "mills"
    with _bar(total, desc, progress) as bar:
        if len(plan) == 1:
            return [_run_job(plan[0], bar.update)]
        ctx = multiprocessing.get_context("spawn")
        out = ctx.Queue()
        procs = [ctx.Process(target=_job_process, args=(k, job, out), daemon=True)
                 for k, job in enumerate(plan)]  # fmt: skip
        for proc in procs:
            proc.start()
        results: dict[int, dict[str, Any]] = {}
        try:
            while len(results) < len(plan):
                try:
                    kind, k, value = out.get(timeout=1.0)
                except queue.Empty:
                    _check_alive(procs, results, plan)
                    continue
                if kind == "bytes":
                    bar.update(value)
                elif kind == "done":
                    results[k] = value
                else:  # (a user error, e.g. an unreadable file, reads as one)
                    raise ValueError(f"analysis of mill(s) {_ids(plan[k])}: {value}")
        finally:
            for proc in procs:
                proc.join(timeout=5.0)
                if proc.is_alive():
                    proc.terminate()
        return [results[k] for k in range(len(plan))]


def _ids(job: _Job) -> str:
    return ", ".join(c.id for c in job.configs)


def _check_alive(procs: list[Any], results: dict[int, Any], plan: list[_Job]) -> None:
    for k, proc in enumerate(procs):
        if k not in results and not proc.is_alive() and proc.exitcode not in (None, 0):
            raise RuntimeError(
                f"the process analysing mill(s) {_ids(plan[k])} died (exit code {proc.exitcode})"
            )


# ---------------------------------------------------------------- output
def mill_result(
    config: MillConfig, report: dict[str, Any], mill_reading: dict[str, Any], read: ReadingStats
) -> tuple[dict[str, Any], dict[str, Any]]:
    """One mill's report as ``analyze`` gives it (the alarms its results raise added) and its
    ``reading`` part; the Python API (:func:`millwatch.analyze`) calls this too."""
    report["alarms"] = alarms_for_report(report_observations(config.id, report), config)
    return report, _stats(read, mill_reading)


def json_body(out: list[tuple[dict[str, Any], dict[str, Any]]]) -> dict[str, Any]:
    """What ``analyze --json`` prints of the mills' :func:`mill_result`: one mill's report with
    its ``reading``, several as ``{"mills": [...]}``."""
    if len(out) == 1:
        return {**out[0][0], "reading": out[0][1]}
    return {"mills": [{**r, "reading": st} for r, st in out]}


def _fmt(x: float | None, spec: str = ".1f") -> str:
    return "—" if x is None else format(x, spec)


def _spectral_and_alarm_lines(report: dict[str, Any]) -> list[str]:
    lines = [
        f"  line {h['channel']} {h['name']}: {h['frequency_hz']:.2f} Hz, "
        f"{h['amplitude_pct']:.2f} % rated"
        for h in report["harmonics"]
        if h.get("detected") and h.get("amplitude_pct") is not None
    ]
    lines += [
        f"  UNEXPLAINED peak {p['channel']} {p['frequency_hz']:.2f} Hz (possible torsional "
        + (
            "resonance)"
            if p.get("nearest_natural_hz") is None
            else f"resonance; nearest natural frequency {p['nearest_natural_hz']:.2f} Hz)"
        )
        for p in report["unexplained_peaks"]
    ]
    alarms = report["alarms"]
    return lines + [f"  alarm {a['severity']} {a['rule']}: {a['message']}" for a in alarms]


def _damage_lines(comp: str, d: dict[str, Any]) -> list[str]:
    """A component's damage as lines that add up: closed cycles by phase, their sum, the open
    residue on its own line, the total."""
    phases = {p: v for p, v in d["phases"].items() if v}
    closed = sum(d["phases"].values())
    lines = [f"  damage {comp} (Miner sum, S-N curve {d['curve']}, {d['stress_factors']}):"]
    parts = " + ".join(f"{p} {v:.3g}" for p, v in phases.items()) or "none"
    lines.append(f"    closed cycles      {closed:.3g}  ({parts})")
    unattributed = d["committed"] - closed
    if abs(unattributed) > 1e-9 * max(abs(d["committed"]), 1e-300):
        lines.append(f"    closed, phase not yet decided  {unattributed:.3g}")
    lines.append(f"    open residue       {d['pending_residue']:.3g}  (reversals not yet closed, "
                 "counted as half cycles)")  # fmt: skip
    lines.append(f"    total              {d['with_residue']:.3g}")
    hours = d["start_cost"]["hours_of_running_per_start"]
    if hours is not None:
        lines.append(f"    one start costs {hours:.3g} h of steady running")
    return lines


#: What the summary's "reading" line says of each count (when not zero).
_READING = {
    "foreign_blocks": "blocks on keys of no mill given with --mill (skipped)",
    "malformed_blocks": "malformed blocks (skipped)",
    "unreadable_tails": "file(s) read up to a torn or corrupt record",
    "missing_blocks": "blocks missing (sequence gaps)",
    "repeated_blocks": "repeated blocks (dropped, as live)",
    "clock_fault_blocks": "blocks with a clock fault (placed by sequence number)",
    "implausible_blocks": "implausible blocks (skipped, as live; README 'Admission')",
    "gap_samples": "samples of gaps (NaN)",
    "late_blocks": "blocks too late to align (dropped)",
}


def _count(value: int | dict[str, Any], words: str) -> str:
    """``3 words``, or for counts by kind / by file ``3 words (a: 1, b: 2)``."""
    if not isinstance(value, dict):
        return f"{value} {words}"
    number = sum(v for v in value.values() if isinstance(v, int)) or len(value)
    return f"{number} {words} ({', '.join(f'{k}: {v}' for k, v in value.items())})"


def _event_line(e: dict[str, Any], zone: str) -> str:
    """One start, stop or barring session, its time in site time."""
    at = iso_local(e["t_ns"], zone)
    if e["event"] == "start":
        return (f"  {at}  start{' FAILED' if e['failed'] else ''}: switch-on "
                f"{_fmt(e['switch_on_peak_pct'])} %, short-circuit "
                f"{_fmt(e['short_circuit_peak_pct'])} %, rise 10-90 "
                f"{_fmt(e['rise_time_10_90_ms'])} ms, accel {_fmt(e['accel_s'])} s")  # fmt: skip
    if e["event"] == "stop":
        return (f"  {at}  {e['kind']}: rocking peak {_fmt(e['rocking_peak_pct'])} % for "
                f"{_fmt(e['rocking_s'])} s")  # fmt: skip
    return (f"  {at}  barring: peak {e['peak_pct']:.1f} %, average {e['average_pct']:.1f} %, "
            f"{e['duration_s']:.0f} s")  # fmt: skip


def _time_basis(report: dict[str, Any]) -> str:
    """The header's statement of the one time basis of the summary: the site's zone."""
    zone = report["time_zone"]
    t = report["t0_ns"]
    offset = "" if t is None else f", UTC{iso_local(t, zone)[23:]} at the first sample"
    return f"times in site time, {zone}{offset}"


#: The summary's words for a channel's fault counts (``data_quality.faults``), in order.
_FAULTS = {"spikes": "spikes", "dropouts": "dropouts (NaN/inf runs)",
           "zero_runs": "zero runs", "rail_hits": "rail hits"}  # fmt: skip


def _data_quality_line(report: dict[str, Any]) -> str:
    """Flagged samples per channel and why (the fault detector's counts: held at the last
    valid value for counting, left out of steady-state values), then the gaps filled with NaN."""
    dq = report["data_quality"]
    flagged = {ch: c for ch, c in dq["faults"].items() if c["flagged_samples"]}
    parts = []
    for ch, c in flagged.items():
        why = ", ".join(f"{c[k]:,} {w}" for k, w in _FAULTS.items() if c[k])
        parts.append(f"{ch} {c['flagged_samples']:,} ({why or 'flagged'})")
    total = sum(c["flagged_samples"] for c in flagged.values())
    text = (f"{total:,} flagged samples, held at the last valid value for counting: "
            + "; ".join(parts)) if parts else "no flagged samples"  # fmt: skip
    gaps = (f"{dq['gap_samples']:,} samples of gaps (NaN) from {dq['missing_blocks']:,} missing "
            "blocks" if dq["gap_samples"] or dq["missing_blocks"] else "no gaps")  # fmt: skip
    late = f"; {dq['late_blocks']:,} blocks too late to align" if dq["late_blocks"] else ""
    return f"  data quality: {text}; {gaps}{late}"


def _spread(values: list[float]) -> str:
    """``min / median / max`` of the finite ``values`` (— when none)."""
    v = sorted(x for x in values if math.isfinite(x))
    if not v:
        return "—"
    mid = len(v) // 2
    median = v[mid] if len(v) % 2 else (v[mid - 1] + v[mid]) / 2
    return f"{v[0]:.1f} / {median:.1f} / {v[-1]:.1f}"


def _steady_lines(windows: list[dict[str, Any]]) -> list[str]:
    """The steady-state windows: how many, and the spread of their values over the windows."""
    if not windows:
        return ["  steady-state windows: none"]
    lines = [f"  steady-state windows: {len(windows)} (min / median / max over the windows; "
             "range = mean of the per-revolution maxima minus minima)"]  # fmt: skip
    pct = "% rated motor torque"
    rows = [
        ("range", "range_pct", pct),
        ("mean", "mean_pct", pct),
        ("amplitude", "bending_amplitude_mpa", "MPa (half the range per revolution)"),
    ]
    for what, key, unit in rows:
        for ch in windows[0].get(key, {}):
            got = _spread([w[key].get(ch, math.nan) for w in windows])
            lines.append(f"    {ch} {what}: {got} {unit}")
    return lines


def _resonance_text(start: dict[str, Any]) -> str:
    """A start's run-up resonance beside the model's nearest natural frequency, or why none."""
    if start.get("resonance_hz") is None:
        return f"run-up resonance: none ({start.get('resonance_note') or 'not measured'})"
    natural = start.get("model_natural_hz")
    model = "no torsional model" if natural is None else f"model natural {natural:.2f} Hz"
    return (f"run-up resonance {start['resonance_hz']:.2f} Hz at "
            f"{start['resonance_speed_pct']:.1f} % speed ({model})")  # fmt: skip


def _summary(report: dict[str, Any], stats: dict[str, Any]) -> str:
    lines = [f"mill {report['mill']} ({report['site']}): {report['samples']} samples, "
             f"state now {report['state']}; {_time_basis(report)}"]  # fmt: skip
    lines.append(_data_quality_line(report))
    for e in report["events"]:
        lines.append(_event_line(e, report["time_zone"]))
        if e["event"] == "start":
            lines.append(f"    {_resonance_text(e)}")
    for month, m in report["starts_per_month"].items():
        lines.append(f"  starts {month}: {m['starts']} ({m['failed_starts']} failed), "
                     f"norm {m['norm'][0]}-{m['norm'][1]}: {m['status']}")  # fmt: skip
    lines += _steady_lines(report["steady_state"])
    for comp, d in report["damage"].items():
        lines += _damage_lines(comp, d)
    summary = report["summary"]
    if "spectra" in summary:
        lines.append(f"  harmonics: {summary['spectra']}")
    elif "segments_note" in summary:
        lines.append(f"  harmonics: {summary['segments_note']}")
    if "torsional_model" in summary:
        lines.append(f"  torsional model: {summary['torsional_model']}")
    lines += _spectral_and_alarm_lines(report)
    problems = [_count(stats[k], words) for k, words in _READING.items() if stats[k]]
    if problems:
        lines.append("  reading: " + "; ".join(problems))
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "analyze",
        help="analyse an MCAP recording: starts, stops, barring, steady state, damage by phase",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch simulate --scene start-lrs --out start.mcap\n"
            "  millwatch analyze start.mcap --mill deploy/mills/sag-5200-lrs.toml --json\n"
            "  millwatch analyze archive/ --mill deploy/mills/ --jobs 0   # all mills and cores\n"
            "  millwatch analyze archive/ --mill deploy/mills/sag-5200-lrs.toml --no-spectra\n"
            "  millwatch analyze /mnt/archive --mill deploy/mills --scheduler tcp://10.0.0.5:8786\n"
            "\n"
            'speed (measured, README Benchmarks "Offline analysis"): 12 h of one mill, running\n'
            "91 % of the time, at about 2,200-2,500x real time per core of CPU with every\n"
            "analysis on; --no-spectra skips the harmonic spectra, about a third of the work,\n"
            "for questions about starts, stops and damage: about 3,500-3,700x.\n"
            "\n"
            "output: times in site time with their offset (the zone in the header); events in\n"
            "time order (--json: 'events', beside 'starts', 'stops', 'barring'); a data-quality\n"
            "line. Steady-state oscillation range (range_pct): the mean of the per-revolution\n"
            "maxima minus the mean of the minima (Diering 2011 App. C routine 4), not the\n"
            "peak-to-peak a scene's truth gives (motor_oscillation_pct), which is larger. The\n"
            "'measured' monthly projection needs at least 7 days of record (else null, why)."
        ),
    )
    p.add_argument("recording", type=Path, nargs="+", metavar="RECORDING",
                   help="MCAP file or directory of .mcap files (several: read in the order "
                        "given, a directory's files in name order)")  # fmt: skip
    p.add_argument("--mill", type=Path, action="append", required=True, metavar="M.toml|DIR",
                   help="mill configuration .toml, or a directory of them; repeat for several "
                        "mills (each mill of the recording not given is only counted)")  # fmt: skip
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="processes to split the mills over (default 1; 0 = one per core); one "
                        "mill is always analysed by one process")  # fmt: skip
    p.add_argument("--scheduler", metavar="tcp://HOST:8786|local:N",
                   help="run on Dask distributed instead of --jobs, one task per mill (the "
                        "workers read the files at the paths given: a shared filesystem); "
                        "local:N starts N worker processes on this machine for the run; the "
                        "same report, byte for byte (README 'Fleet re-analysis')")  # fmt: skip
    p.add_argument("--no-spectra", action="store_true",
                   help="skip the harmonic spectra: states, events, steady state and damage "
                        "are the same; harmonics, unexplained peaks not computed")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the full report as JSON")
    p.add_argument("--plots", type=Path, metavar="DIR",
                   help="also write PNG plots into DIR: each start and stop with its events, "
                        "each run-up's Campbell diagram, each component's range–mean matrix, "
                        "the natural frequency start by start (millwatch.plots)")  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar "
                   "(none is shown anyway when stderr is not a terminal)")  # fmt: skip
    p.set_defaults(handler=_main)


def _configs(paths: list[Path]) -> list[MillConfig]:
    configs: dict[str, MillConfig] = {}
    for path in paths:
        files = sorted(path.glob("*.toml")) if path.is_dir() else [path]
        if not files:
            raise ValueError(f"--mill {path}: directory holds no .toml mill configurations")
        for f in files:
            config = mill_option(f)
            if config.id in configs:
                raise ValueError(f"--mill {f}: mill {config.id!r} is given twice")
            configs[config.id] = config
    return list(configs.values())


def _main(args: argparse.Namespace) -> int:
    configs = _configs(args.mill)
    files = [f for r in args.recording for f in recording_files(r)]
    if args.jobs < 0:
        raise ValueError(f"--jobs {args.jobs}: must be ≥ 0 (0 = one process per core)")
    if args.scheduler and args.plots is not None:
        raise ValueError(f"--plots {args.plots} with --scheduler {args.scheduler}: the plots are "
                         "drawn from the recording on this machine; run --plots without "
                         "--scheduler (one mill at a time is quick)")  # fmt: skip
    jobs = args.jobs or os.cpu_count() or 1
    progress = not args.no_progress and sys.stderr.isatty()
    started = time.perf_counter()
    if args.scheduler:  # (Dask is an optional extra: imported only when asked for)
        from millwatch.fleet.distributed import analyze_on_dask

        results = analyze_on_dask(files, configs, args.scheduler, spectra=not args.no_spectra,
                                  progress=progress)  # fmt: skip
    else:
        plan = plan_jobs(files, configs, jobs, spectra=not args.no_spectra,
                         matrices=args.plots is not None)  # fmt: skip
        results = run_jobs(plan, progress=progress)
    read = ReadingStats()
    for r in results:
        read.merge(r["reading"])
    read.files = [str(f) for f in files if str(f) in set(read.files)]  # the recording's order
    reports = {m: rm for r in results for m, rm in r["reports"].items()}
    if not reports:
        given = ", ".join(repr(c.id) for c in configs)
        raise ValueError(f"RECORDING {' '.join(map(str, args.recording))}: no blocks of mill "
                         f"{given} found")  # fmt: skip
    out = []
    for config in configs:
        if config.id not in reports:
            log.warning("no blocks of mill %r in the recording", config.id)
            continue
        report, mill_reading = reports[config.id]
        if args.plots is not None:
            from millwatch.plots.files import write_plots

            written = write_plots(files, config, report, args.plots)
            log.info("%s: %d plots written to %s", config.id, len(written), args.plots)
            del report["cycle_matrices"]
        out.append(mill_result(config, report, mill_reading, read))
    if args.json:
        sys.stdout.write(json.dumps(json_body(out), indent=1) + "\n")
    else:
        sys.stdout.write("\n".join(_summary(r, st) for r, st in out) + "\n")
    _speed_note(out, configs, time.perf_counter() - started)
    return 0


def _speed_note(out: list[tuple[dict[str, Any], dict[str, Any]]], configs: list[MillConfig],
                wall_s: float) -> None:  # fmt: skip
    """One line on stderr (stdout stays the report): stream time analysed, how fast."""
    fs = {c.id: float(c.sample_rate_hz) for c in configs}
    stream_s = sum(r["samples"] / fs[r["mill"]] for r, _ in out)
    if stream_s and wall_s > 0:
        sys.stderr.write(f"analysed {len(out)} mill(s), {stream_s / 3600:.1f} h of samples, in "
                         f"{wall_s:.1f} s: {stream_s / wall_s:,.0f}x real time\n")  # fmt: skip
