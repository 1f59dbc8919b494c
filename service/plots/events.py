"""A start's or stop's record against time with its events marked (Diering 2011 §6.1.1, Figure
20: switch-on peak, acceleration with the resonance near 90 % speed, short-circuit peak, steady
running; switch-off and rocking to rest).

:func:`event_marks` lists what a start or stop record marks, from the analyzer's typed event
alone; :func:`event_figure` draws the torques (kN·m) and the speed (rpm, right axis) of the
record's samples with one labelled vertical marker per mark (``gid`` ``"event-marker"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from millwatch.analytics.mill.results import StartEvent, StopEvent

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["EVENT_GID", "event_figure", "event_marks"]

#: ``gid`` of every event marker line (tests count them).
EVENT_GID = "event-marker"


def event_marks(event: StartEvent | StopEvent) -> list[tuple[int, str]]:
    """``(t_ns, label)`` of each thing the record marks, in time order: a start's switch-on,
    each side's switch-on and short-circuit peaks (% of rated motor torque), the run-up
    resonance (Hz at % speed) and the start of steady running; a stop's switch-off (kind) and
    rest."""
    if isinstance(event, StopEvent):
        return [(event.t_ns, event.kind), (event.end_t_ns, "at rest")]
    dt = 1e9 / _fs(event)
    marks = [(event.t_ns, "switch-on")]
    for name, peaks in (
        ("switch-on peak", event.switch_on),
        ("short-circuit", event.short_circuit),
    ):
        for p in peaks:
            side = f" {p.side}" if p.side else ""
            t = event.t_ns + round((p.sample - event.sample) * dt)
            marks.append((t, f"{name}{side} {p.motor_pct:.0f} %"))
    if event.resonance_t_ns is not None and event.resonance_hz is not None:
        marks.append((event.resonance_t_ns, f"resonance {event.resonance_hz:.2f} Hz "
                                            f"at {event.resonance_speed_pct:.0f} %"))  # fmt: skip
    marks.append((event.end_t_ns, "failed" if event.failed else "steady"))
    return sorted(marks)


def _fs(event: StartEvent | StopEvent) -> float:
    """The sample rate (Hz) the event's samples and times imply."""
    span = event.end_sample - event.sample
    return 1e9 * span / (event.end_t_ns - event.t_ns) if span > 0 else 1000.0


def event_figure(
    t0_ns: int,
    fs: float,
    torque: Mapping[str, np.ndarray],
    speed: np.ndarray,
    event: StartEvent | StopEvent,
    *,
    speed_label: str = "speed (rpm)",
    title: str = "",
) -> Figure:
    """Torques (kN·m, one line per channel name) and ``speed`` of the samples from ``t0_ns``
    (ns UTC) at ``fs`` Hz against seconds from the event's start, with :func:`event_marks`."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 4.8), layout="constrained")
    ax = fig.subplots()
    n = speed.shape[0]
    t = (t0_ns - event.t_ns) / 1e9 + np.arange(n) / fs
    for name, x in torque.items():
        ax.plot(t, x, lw=0.6, label=f"{name} (kN·m)")
    ax.set_xlabel(f"time from the {event.event} (s)")
    ax.set_ylabel("torque (kN·m)")
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(t, speed, color="black", lw=1.0, ls="--", label=speed_label)
    ax2.set_ylabel(speed_label)
    marks = [((t_ns - event.t_ns) / 1e9, label) for t_ns, label in event_marks(event)]
    _mark(ax, ax2, marks, float(t[-1] - t[0]) if n else 1.0)
    lines = ax.get_lines()[: len(torque)] + ax2.get_lines()
    ax.legend(lines, [str(ln.get_label()) for ln in lines], fontsize=8, loc="lower right")
    ax.set_title(title or f"{event.event} at {_iso(event.t_ns)}", fontsize=10)
    return fig


def _mark(ax: Any, top: Any, marks: list[tuple[float, str]], span_s: float) -> None:
    """A labelled vertical line per mark on ``ax``, its label on ``top`` (the twin axes drawn
    last, so no line covers it); labels of marks closer than 3 % of the plot's span alternate
    sides of their lines and step down the axes, so none covers another."""
    previous, k = -math.inf, 0
    for x, label in marks:
        k = k + 1 if x - previous < 0.03 * span_s else 0
        previous = x
        ax.axvline(x, color="tab:red", lw=0.8, alpha=0.7, gid=EVENT_GID)
        top.annotate(label, (x, 1.0 - 0.45 * (k // 2)), xycoords=("data", "axes fraction"),
                     rotation=90, fontsize=7, ha="left" if k % 2 else "right", va="top",
                     xytext=(2 if k % 2 else -2, -4), textcoords="offset points",
                     color="tab:red", bbox={"fc": "white", "ec": "none", "alpha": 0.75,
                                            "pad": 0.5})  # fmt: skip


def _iso(t_ns: int) -> str:
    from millwatch.alarms.times import iso_utc

    return iso_utc(t_ns)
