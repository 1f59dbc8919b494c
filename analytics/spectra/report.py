"""The harmonics part of a mill's report: the long-run table of a :class:`HarmonicTracker`.

Diering 2011 §6.2.7 and §10.5: the steady-state spectrum's expected lines and unexplained peaks, as
one row per channel and line, for operators and the monthly report, and how many spectral
segments the table rests on and how many were dropped, and why (issue 18).
"""

from __future__ import annotations

from typing import Any

from millwatch.analytics.drivetrain.torsional_model import torsional_note
from millwatch.analytics.spectra.resonance import resonance_margins
from millwatch.analytics.spectra.tracker import HarmonicTracker, describe_segments

__all__ = ["harmonics_report"]


def harmonics_report(tracker: HarmonicTracker) -> dict[str, Any]:
    """Report of the running portions so far (long-run Welch average over every segment).

    Keys: ``harmonics`` (one row per channel and expected line), ``unexplained_peaks``,
    ``resonance_margins`` (per channel, the measured excitation nearest a torsional natural
    frequency: :mod:`millwatch.analytics.spectra.resonance`), and ``summary``: ``torsional_model``
    (the mill's natural frequencies in words, or that its file has no model), ``segments`` (used,
    as ``segments_used``), ``segments_dropped`` (count per reason, every key of
    :data:`~millwatch.analytics.spectra.tracker.DROP_REASONS`), ``segments_note`` (the same in one
    plain sentence), and once a segment is used the running seconds, mean pinion speed, resolution
    and tracking mode. JSON-ready.
    """
    used, dropped = tracker.segment_accounting()
    accounting = {
        "segments": used,
        "segments_used": used,
        "segments_dropped": dropped,
        "segments_note": describe_segments(used, dropped),
        "torsional_model": torsional_note(tracker.config),
    }
    table = tracker.total_table()
    if table is None:
        return {
            "harmonics": [],
            "unexplained_peaks": [],
            "resonance_margins": [],
            "summary": accounting,
        }
    return {
        "harmonics": [m.to_dict() for m in table.lines],
        "unexplained_peaks": [p.to_dict() for p in table.peaks],
        "resonance_margins": [
            m.to_dict() for m in resonance_margins(table, tracker.natural_frequencies_hz)
        ],
        "summary": accounting
        | {
            "running_s": tracker.counters["running_samples"] / tracker.fs,
            "pinion_speed_rpm": table.pinion_speed_rpm,
            "resolution_hz": table.resolution_hz,
            "tracking": table.tracking,
        },
    }
