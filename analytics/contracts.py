"""The contracts every stateful analytics object keeps, stated once.

README "The numerical contract" and "Persistence and recovery"; the idea is pyLife's
``AbstractDetector`` ("``process(signal)`` is equivalent to ``process(signal[:n])`` then
``process(signal[n:])``"), which every detector inherits instead of restating it.

:class:`Stateful` is the contract of the counters (rainflow, operating-state machine, spectral
tracker, fault detectors, aligner, tacho) and of the recorders (damage accumulators, matrices,
per-phase damage) that live as long as a mill is watched. An implementation's docstring points
here instead of restating it. :func:`check_snapshot` is the one kind/version check of a snapshot.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

__all__ = ["SnapshotMismatch", "Stateful", "check_snapshot"]


@runtime_checkable
class Stateful(Protocol):
    """A streaming counter or recorder of one mill (structural type; nothing inherits it).

    Split anywhere
        Feeding ``x`` in one call (``feed``, ``record``, ``push`` — the verb is the
        class's) leaves the object exactly as feeding ``x[:n]`` then ``x[n:]`` does, for every
        ``n``: the facts emitted (cycles, events, spectra) and the totals are the same, bit for
        bit where the sums are exact. Empty, constant and monotone inputs give empty results and
        never raise. Tests split every signal at random points to check it.

    Snapshot
        :meth:`snapshot` returns the complete state as plain JSON data (dicts, lists, strings,
        numbers, None; arrays packed by :mod:`millwatch.analytics.snapshot_arrays`) carrying a
        ``kind``
        and a ``version``; the restore of that data (a classmethod ``restore(snapshot)`` or, for
        objects built from a configuration, a method or a classmethod that also takes it)
        continues exactly where the snapshotted object stood: feeding the rest of the samples to
        the restored object gives what the uninterrupted one gives. A snapshot of another kind
        or version is refused with :func:`check_snapshot`'s ``ValueError``.

    Bounded state
        Memory does not grow with running time: bins and buffers are sized from the
        configuration, never from the data seen.
    """

    def snapshot(self) -> dict[str, Any]:
        """The complete state as plain JSON-serialisable data, with ``kind`` and ``version``."""
        ...


def check_snapshot(
    snapshot: dict[str, Any], kind: str, version: int | None, what: str = ""
) -> None:
    """Raise ``ValueError`` unless ``snapshot`` is of ``kind`` and ``version`` (``None``: any).

    The message names what was expected (``what``, default ``kind``) and what was found, e.g.
    ``not a rainflow counter snapshot of version 2: kind='tacho', version=2``.

    >>> check_snapshot({"kind": "tacho", "version": 2}, "tacho", 2)
    >>> check_snapshot({"kind": "tacho", "version": 1}, "tacho", 2)
    Traceback (most recent call last):
    ...
    ValueError: not a tacho snapshot of version 2: kind='tacho', version=1
    """
    got_kind, got_version = snapshot.get("kind"), snapshot.get("version")
    if got_kind == kind and (version is None or got_version == version):
        return
    of_version = "" if version is None else f" of version {version}"
    raise ValueError(
        f"not a {what or kind} snapshot{of_version}: kind={got_kind!r}, version={got_version!r}"
    )


class SnapshotMismatch(ValueError):
    """A sound snapshot taken under another mill configuration that does not fit the object
    this configuration builds; the message names the mill and what differs. From
    :meth:`HarmonicTracker.restore <millwatch.analytics.spectra.tracker.HarmonicTracker.restore>`
    (segment length, bins, buffer or tracked lines differ) it concerns only spectra in
    progress, so a caller may start a fresh tracker instead
    (:meth:`MillAnalyzer.restore <millwatch.analytics.mill.analyzer.MillAnalyzer.restore>` does)."""
