"""Campbell (waterfall) diagram of a run-up: short-time spectra of the torque against speed,
the mill's excitation orders as rays from the origin, the torsional model's natural
frequencies as horizontal lines and the resonance crossed marked (Diering 2011 §6.1.1: a
resonance near 90 % speed; §6.1.2: the expected excitations; Fedin & Vinogradov 2018: natural
frequencies). Where an order ray crosses a natural frequency the drivetrain is excited at it.

The spectra are :func:`millwatch.analytics.operation.runup.runup_spectrogram`'s (the analyzer's
resonance search reads the same), in dB re 1 kN·m. Artists carry ``gid`` ``"order-line"``,
``"natural-line"`` and ``"resonance-marker"``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from millwatch.analytics.mill.results import StartEvent
from millwatch.analytics.operation.runup import RunupSpectrogram

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["NATURAL_GID", "ORDER_GID", "RESONANCE_GID", "campbell_figure"]

ORDER_GID, NATURAL_GID, RESONANCE_GID = "order-line", "natural-line", "resonance-marker"
#: An order is drawn when its line is below ``max_hz`` from this speed (fraction of rated) on.
MIN_SPEED_SHOWN = 0.1


def campbell_figure(
    spec: RunupSpectrogram,
    orders: Mapping[str, float],
    order_hz_at_rated: float,
    natural_hz: Sequence[float],
    start: StartEvent,
    *,
    max_hz: float = 40.0,
    title: str = "",
) -> Figure:
    """The run-up's spectra (``spec``; speed as % of rated on x, Hz on y up to ``max_hz``),
    each excitation order of ``orders`` (cycles per revolution of the shaft turning at
    ``order_hz_at_rated`` Hz at rated speed: the mill file's
    :meth:`~millwatch.analytics.drivetrain.mill_config.MillConfig.excitation_orders` and the
    pinion's rated rotation frequency) as a line ``f = order · order_hz_at_rated · speed``
    (an order above ``max_hz`` already at :data:`MIN_SPEED_SHOWN` is left out), every
    natural frequency below ``max_hz`` as a horizontal line, and ``start``'s resonance."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 5.5), layout="constrained")
    ax = fig.subplots()
    ax.set_facecolor("#202020")  # no spectrum (below the first frame's speed): dark, as quiet
    keep = spec.freq_hz <= max_hz
    if len(spec):
        order = np.argsort(spec.speed, kind="stable")
        db = 20.0 * np.log10(np.maximum(spec.amplitude[order][:, keep], 1e-6))
        mesh = ax.pcolormesh(100.0 * spec.speed[order], spec.freq_hz[keep], db.T,
                             shading="nearest", cmap="magma", rasterized=True,
                             vmin=float(np.percentile(db, 5)), vmax=float(db.max()))  # fmt: skip
        fig.colorbar(mesh, ax=ax, pad=0.01, label="torque amplitude (dB re 1 kN·m)")
    speeds = np.array([0.0, 105.0])
    for name, k in orders.items():
        f_rated = k * order_hz_at_rated
        if f_rated * MIN_SPEED_SHOWN > max_hz:
            continue
        ax.plot(speeds, f_rated * speeds / 100.0, color="white", lw=0.8, ls="--", gid=ORDER_GID)
        x = min(100.0, 100.0 * max_hz / f_rated * 0.97)  # where the line leaves the plot
        ax.annotate(name, (x, f_rated * x / 100.0), color="white", fontsize=7, ha="right",
                    va="bottom" if x >= 100.0 else "top")  # fmt: skip
    for f in natural_hz:
        if f <= max_hz:
            ax.axhline(f, color="cyan", lw=1.0, gid=NATURAL_GID)
            ax.annotate(f"model natural {f:.2f} Hz", (2.0, f), color="cyan", fontsize=7,
                        va="bottom")  # fmt: skip
    if start.resonance_hz is not None and start.resonance_speed_pct is not None:
        ax.plot([start.resonance_speed_pct], [start.resonance_hz], marker="o", ms=10, mfc="none",
                mec="lime", mew=2, ls="none", gid=RESONANCE_GID,
                label=f"resonance {start.resonance_hz:.2f} Hz at "
                      f"{start.resonance_speed_pct:.1f} %")  # fmt: skip
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlim(0.0, 105.0)
    ax.set_ylim(0.0, max_hz)
    ax.set_xlabel("speed (% of rated)")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(title or "run-up Campbell diagram", fontsize=10)
    return fig
