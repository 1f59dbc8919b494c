"""``millwatch spectrum``: the steady-state torque spectrum of a recording, expected lines marked.

Reads one MCAP recording (``millwatch simulate --out`` or the ingest archive; its blocks admitted
as ``millwatch analyze`` admits them: :mod:`millwatch.worker.admission`), keeps only the
running portions (pinion speed within the running band for ``--settle`` seconds: a plain
speed-band test, :func:`millwatch.analytics.spectra.settings.is_running`, not the analyzer's
operating-state machine, whose run edges differ), feeds them to
:class:`millwatch.analytics.spectra.tracker.HarmonicTracker`
(order-tracked Welch PSD, see that module) and renders one PSD panel per torque/bending channel
with the drivetrain's expected excitation lines marked and labelled — Diering 2011 §6.2.7, Figures
35–36, with Diering 2011's colours (mill speed orange, pinion speed blue, liner passing green, motor
speed magenta, pinion/girth mesh red, reducer mesh cyan). Peaks that match no expected line are
marked as possible torsional resonance. ``--report`` writes the harmonic table as JSON.

The samples pass the telemetry fault stage first, as in the analyzer (Diering 2011 §5.2.2): a
flagged
spike is held at the channel's last good value, so it neither ends a running period nor enters
the speed estimate; a missing (NaN) sample stays missing and cuts its segment. The output says
how many spectral segments were used and dropped, and why, and what was flagged per channel.

Example::

    millwatch simulate --scene resonance --duration 120s --out r.mcap
    millwatch spectrum r.mcap --mill deploy/mills/sag-5200-lrs.toml --out r.png
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.kinematics import ExpectedLine
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.signal.fault_stage import FaultStage, LastGood
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.analytics.signal.telemetry_faults import FaultCounts
from millwatch.analytics.spectra.report import harmonics_report
from millwatch.analytics.spectra.settings import HarmonicSettings, is_running
from millwatch.analytics.spectra.tracker import HarmonicTracker
from millwatch.cli.args import non_negative_float, positive_float
from millwatch.ingest import wire
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.mill_files import load_mill_config
from millwatch.worker.admission import BlockAdmission

__all__ = ["TrackedRecording", "add_parser", "plot_spectrum", "track_recording"]

log = logging.getLogger(__name__)

#: Diering 2011 §6.2.7 colours by line family; others get grey.
COLOURS = {
    "mill_speed": "tab:orange",
    "pinion_speed": "tab:blue",
    "liner_passing": "tab:green",
    "motor_speed": "magenta",
    "girth_mesh": "red",
    "reducer_mesh": "cyan",
    "pinion_3x": "tab:purple",
    "media_oscillation": "tab:brown",
}
LOW_HZ = 0.1


# ---------------------------------------------------------------- reading
@dataclass
class _Assembler:
    """Aligns the blocks of several channels into common frames (by sample index); gaps are
    filled with NaN (the tracker restarts after them), overlaps dropped."""

    names: tuple[str, ...]
    fs: float
    t0_ns: int | None = None
    parts: dict[str, list[np.ndarray]] = field(default_factory=dict)
    pos: dict[str, int] = field(default_factory=dict)
    emitted: int = 0

    def add(self, name: str, block: wire.Block) -> None:
        if self.t0_ns is None:
            self.t0_ns = block.t0_ns
        start = round((block.t0_ns - self.t0_ns) * self.fs / 1e9)
        x = np.asarray(block.samples, dtype=np.float64)
        pos = self.pos.get(name, self.emitted)
        if start > pos:
            x = np.concatenate((np.full(start - pos, np.nan), x))
        elif start < pos:
            x = x[pos - start :]
        self.parts.setdefault(name, []).append(x)
        self.pos[name] = pos + x.shape[0]

    def frame(self, minimum: int) -> tuple[int, dict[str, np.ndarray]] | None:
        """The next common frame of at least ``minimum`` samples, if available."""
        if self.t0_ns is None or any(n not in self.pos for n in self.names):
            return None
        n = min(self.pos.values()) - self.emitted
        if n < max(1, minimum):
            return None
        out = {}
        for name in self.names:
            data = np.concatenate(self.parts[name])
            out[name], rest = data[:n], data[n:]
            self.parts[name] = [rest]
        t0 = self.t0_ns + round(self.emitted * 1e9 / self.fs)
        self.emitted += n
        return t0, out


def recording_frames(
    path: Path, config: MillConfig, names: list[str], frame_s: float = 1.0
) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
    """(t0_ns, frame) of channels ``names`` of ``config`` from one MCAP file, in time order,
    of the blocks ``millwatch analyze`` admits (:class:`~millwatch.worker.admission.BlockAdmission`:
    live keys or a replay run's; malformed blocks and repeats counted and skipped)."""
    admission = BlockAdmission([config], replayed=True, warn_foreign=False)
    asm = _Assembler(tuple(names), float(config.sample_rate_hz))
    minimum = round(frame_s * config.sample_rate_hz)
    for msg in TailTolerantReader(path).messages():
        got = admission.admit(msg.key, msg.payload, msg.log_time_ns)
        if got is None or got.channel not in names:
            continue
        asm.add(got.channel, got.block)
        while (out := asm.frame(minimum)) is not None:
            yield out
    while (out := asm.frame(1)) is not None:
        yield out


@dataclass
class TrackedRecording:
    """What :func:`track_recording` read: the tracker, and the telemetry faults the fault stage
    flagged per checked channel (their samples held at the last good value, a NaN one left
    missing)."""

    tracker: HarmonicTracker
    faults: dict[str, FaultCounts]

    def data_quality(self) -> dict[str, Any]:
        """The report's ``data_quality``: fault counts per checked channel, and what was done."""
        return {
            "faults": {n: c.to_dict() for n, c in self.faults.items()},
            "policy": "flagged samples held at the channel's last good value (a missing one "
            "stays missing and cuts the segment); they never end a running period",
        }


def track_recording(
    path: Path,
    config: MillConfig,
    settings: HarmonicSettings | None = None,
    *,
    settle_s: float = 5.0,
    channels: list[str] | None = None,
) -> TrackedRecording:
    """Feed the running portions of a recording to a new tracker, through the telemetry fault
    stage: a flagged spike is held at the last good value, so it neither ends a running period
    (the speed-band test sees the held speed) nor enters the speed estimate (issue 18)."""
    tracker = HarmonicTracker(config, channels, settings)
    speed = tracker.speed_channel
    band = tracker.settings.running_band
    shaft = config.channels[speed].shaft if speed is not None else "pinion"
    names = [c.name for c in tracker.channels] + ([speed] if speed is not None else [])
    read = config.model_copy(update={"channels": {n: config.channels[n] for n in names}})
    stage, last_good = FaultStage(read), LastGood()
    running_s, fs = 0.0, float(config.sample_rate_hz)

    def feed(frame: Frame | None) -> None:
        nonlocal running_s
        if frame is None or len(frame) == 0:
            return
        held = last_good.hold(frame)
        for name in frame.flags or {}:  # a missing sample stays missing (a dropout is no data)
            missing = ~np.isfinite(frame.data[name])
            if missing.any():
                held[name] = np.where(missing, np.nan, held[name])
        ok = speed is None or is_running(held[speed], config, shaft=shaft, band=band)
        running_s = running_s + len(frame) / fs if ok else 0.0
        tracker.feed(frame.t0_ns, fs, held, ok and running_s > settle_s)

    for t0, data in recording_frames(path, config, names):
        feed(stage.feed(Frame(t0, fs, data)))
    feed(stage.flush())
    tracker.flush()
    return TrackedRecording(tracker, stage.totals())


# ---------------------------------------------------------------- plotting
def _mark_lines(ax: Any, lines: list[ExpectedLine], top: float) -> None:
    import matplotlib.transforms as mtransforms

    trans = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
    for ln in lines:
        if not ln.observable or not LOW_HZ <= ln.frequency_hz <= top:
            continue
        colour = COLOURS.get(ln.family.rstrip("_0123456789"), "grey")
        main = ln.kind in ("fundamental", "fixed")
        ax.axvline(ln.frequency_hz, color=colour, ls=":", lw=1.0 if main else 0.6,
                   alpha=1.0 if main else 0.6)  # fmt: skip
        if ln.kind != "sideband":
            ax.text(ln.frequency_hz, 0.98, f" {ln.name} {ln.frequency_hz:.2f} Hz", color=colour,
                    rotation=90, va="top", ha="right", fontsize=6, transform=trans)  # fmt: skip


def _panel(ax: Any, tracker: HarmonicTracker, channel: str, top: float) -> None:
    freq, psd, _ = tracker.average_spectrum(channel)
    keep = (freq >= LOW_HZ) & (freq <= top)
    unit = tracker.config.channels[channel].units
    ax.loglog(freq[keep], psd[keep], color="black", lw=0.6)
    _mark_lines(ax, tracker.expected(), top)
    table = tracker.total_table()
    for p in table.peaks if table is not None else ():
        if p.channel == channel:
            y = float(np.interp(p.frequency_hz, freq, psd))
            ax.plot([p.frequency_hz], [y], "v", color="darkred", ms=6)
            label = f"? {p.frequency_hz:.2f} Hz (resonance?)"
            ax.annotate(label, (p.frequency_hz, y), xytext=(4, 4), textcoords="offset points",
                        fontsize=7, color="darkred")  # fmt: skip
    ax.set_ylabel(f"PSD [{unit}²/Hz]")
    ax.set_title(f"{tracker.config.id} — {channel}", fontsize=9)
    ax.grid(True, which="both", alpha=0.2)


def plot_spectrum(tracker: HarmonicTracker, out: Path, channels: list[str] | None = None) -> None:
    """Render the long-run PSD of ``channels`` (default: all tracked) to ``out`` (.png/.svg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = channels or [c.name for c in tracker.channels]
    top = min(tracker.config.telemetry_bandwidth_hz, tracker.fs / 2.0)
    fig, axes = plt.subplots(len(names), 1, figsize=(11, 3.2 * len(names)), squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        _panel(ax, tracker, name, top)
    axes[-1, 0].set_xlabel("frequency [Hz] (order-tracked, at the mean running speed)")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "spectrum",
        help="PSD of the running portions of a recording with the expected lines marked",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("recording", type=Path, help="MCAP recording (one file)")
    p.add_argument("--mill", type=Path, required=True, help="mill configuration .toml")
    p.add_argument("--channel", action="append", help="channel to plot (repeatable; default all)")
    p.add_argument("--out", type=Path, help="FILE.png or FILE.svg (default: RECORDING.png)")
    p.add_argument("--report", type=Path, help="also write the harmonic table as JSON here")
    p.add_argument("--window-s", type=positive_float, default=20.0,
                   help="segment length, s (resolution 1/window, 20 s = 0.05 Hz)")  # fmt: skip
    p.add_argument("--settle", type=non_negative_float, default=5.0,
                   help="seconds of running before frames are used (default 5)")  # fmt: skip
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    config = load_mill_config(args.mill)
    out = args.out or args.recording.with_suffix(".png")
    if out.suffix.lower() not in (".png", ".svg"):
        raise ValueError(f"--out {out}: must end in .png or .svg")
    if not args.recording.is_file():
        raise OSError(f"{args.recording}: no such file")
    settings = HarmonicSettings(window_s=args.window_s)
    read = track_recording(
        args.recording, config, settings, settle_s=args.settle, channels=args.channel
    )
    tracker = read.tracker
    if tracker.running_segments == 0:
        raise ValueError(
            f"{args.recording}: no steady running long enough for one "
            f"{tracker.revs}-revolution segment (~{args.window_s:g} s)"
        )
    plot_spectrum(tracker, out, args.channel)
    report = harmonics_report(tracker) | {"data_quality": read.data_quality()}
    if args.report is not None:
        args.report.write_text(json.dumps(report, indent=2) + "\n")
    _summary(report, out)
    return 0


def _summary(report: dict[str, Any], out: Path) -> None:
    s = report["summary"]
    sys.stdout.write(
        f"{s['running_s']:.0f} s running at "
        f"{s['pinion_speed_rpm']:.2f} rpm pinion, resolution {s['resolution_hz']:.4f} Hz → {out}\n"
    )
    sys.stdout.write(s["segments_note"] + "\n")
    for name, c in report["data_quality"]["faults"].items():
        if c["flagged_samples"]:
            sys.stdout.write(
                f"{name}: {c['spikes']} spikes, {c['dropouts']} dropouts, {c['zero_runs']} "
                f"zero runs, {c['rail_hits']} rail pins flagged ({c['flagged_samples']} samples "
                "held at the last good value, a missing one left missing)\n"
            )
    for p in report["unexplained_peaks"]:
        pct = f" ({p['amplitude_pct']:.1f} % rated)" if p["amplitude_pct"] is not None else ""
        sys.stdout.write(
            f"unexplained peak on {p['channel']}: {p['frequency_hz']:.2f} Hz, "
            f"{p['amplitude']:.2f} {p['unit']}{pct}: possible torsional resonance\n"
        )
