"""A legacy recording on the mill's sample grid: which signal is which channel, and when each
sample was taken.

**Channels.** A signal named like a ``[channels.<name>]`` table of the mill file is that
channel; ``mapping`` (``--map SRC=CHANNEL``) names the others; ``ignore`` leaves signals out.
A signal that is none of these is an error naming it and the mill's channels, and so is a
channel with no signal — unless ``allow_missing``: then the channel is absent from the import,
and the analyzer treats it as the live worker treats a channel that sends nothing (its samples
NaN, counted as missing blocks).

**Time.** The analyzer takes a mill's samples at the rate of its mill file
(``sample_rate_hz``) on one grid, sample ``k`` at ``t0 + k/fs`` (README "Conventions"); the
import never resamples. A uniform signal's rate must be the mill's (to 1 part in 10⁶). A
timestamped signal's median step must be the mill's period (to 1 %), and every sample must lie
on the grid of its first one to :data:`GRID_TOLERANCE` of a period (a float64 time near 2026
resolves 0.24 µs, 0.024 % of a 1 kHz period): a step of a whole number ``m > 1`` of periods is
a *gap* of ``m − 1`` samples — a new :class:`Run` —, anything else (a sample off the grid, a
time that does not increase) is an error naming the row. Signals may start at different times
on one grid. NaN values stay NaN: the analyzer counts and flags them as dropouts, as live.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.legacy.tracks import LegacyFileError, SourceTrack

__all__ = ["GRID_TOLERANCE", "RATE_TOLERANCE", "Recording", "Run", "assign_channels", "build"]

#: How far (in sample periods) a timestamp may lie from the grid.
GRID_TOLERANCE = 0.01
#: Relative difference allowed between a uniform signal's rate and the mill's.
RATE_TOLERANCE = 1e-6
#: Relative difference allowed between a timestamped signal's median step and the mill's period.
STEP_TOLERANCE = 0.01
_NS_PER_S = 1_000_000_000


@dataclass(frozen=True, eq=False)
class Run:
    """Contiguous samples of one channel: ``values[i]`` (float64, engineering units) is grid
    sample ``start + i`` of the recording."""

    start: int
    values: np.ndarray

    @property
    def stop(self) -> int:
        """Grid index just after the run's last sample."""
        return self.start + int(self.values.shape[0])


@dataclass(frozen=True, eq=False)
class Recording:
    """A recording's channels on the mill's grid: grid sample ``k`` is at :meth:`t_ns` ``(k)``,
    ``t0_ns`` (ns since the Unix epoch, UTC) being the earliest sample of any channel, ``fs``
    the mill's rate in Hz. ``runs[channel]``: the channel's samples, in time order, one
    :class:`Run` per stretch without a gap (mill-config order; a channel allowed to be missing
    is absent). ``sources[channel]``: the file's name for it."""

    path: str
    t0_ns: int
    fs: float
    runs: dict[str, tuple[Run, ...]]
    sources: dict[str, str]

    def t_ns(self, index: np.ndarray | int) -> np.ndarray:
        """int64 ns since the epoch of grid sample(s) ``index``, as the simulator and the
        wire format time them (``t0 + k·1e9/fs``; whole-Hz rates exactly, by integers)."""
        k = np.asarray(index, dtype=np.int64)
        if float(self.fs).is_integer():
            q, r = np.divmod(k, int(self.fs))
            return self.t0_ns + q * _NS_PER_S + (r * _NS_PER_S) // int(self.fs)
        return self.t0_ns + np.rint(k * 1e9 / self.fs).astype(np.int64)

    @property
    def n_grid(self) -> int:
        """Grid samples from the first to just after the last sample of any channel."""
        return max((r[-1].stop for r in self.runs.values() if r), default=0)

    @property
    def n_samples(self) -> int:
        """Samples the file holds, over all channels."""
        return sum(int(r.values.shape[0]) for runs in self.runs.values() for r in runs)

    def samples(self, channel: str) -> tuple[np.ndarray, np.ndarray]:
        """``(times_ns, values)`` of ``channel``: every sample the file holds, in time order
        (int64 ns since the epoch, UTC; float64 engineering units)."""
        runs = self.runs[channel]
        index = np.concatenate([np.arange(r.start, r.stop) for r in runs] or [np.zeros(0, int)])
        values = np.concatenate([r.values for r in runs] or [np.zeros(0)])
        return self.t_ns(index), values

    def table(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Every channel on the times any channel has a sample: ``(times_ns, {channel:
        values})``, NaN where a channel has none (for a DataFrame)."""
        spans = [np.arange(r.start, r.stop) for runs in self.runs.values() for r in runs]
        index = np.unique(np.concatenate(spans)) if spans else np.zeros(0, np.int64)
        columns = {}
        for channel, runs in self.runs.items():
            column = np.full(index.shape[0], np.nan)
            for r in runs:
                at = np.searchsorted(index, r.start)
                column[at : at + r.values.shape[0]] = r.values
            columns[channel] = column
        return self.t_ns(index), columns


def assign_channels(
    path: str,
    names: Iterable[str],
    config: MillConfig,
    mapping: Mapping[str, str] | None = None,
    ignore: Iterable[str] = (),
    allow_missing: bool = False,
) -> dict[str, str]:
    """``{channel: signal name}`` for the file's signals ``names`` (module docstring); raises
    :class:`LegacyFileError` naming unknown signals, unmapped channels and bad ``--map``\\ s."""
    names = list(names)
    mapping = dict(mapping or {})
    _check_mapping(path, names, config, mapping)
    left_out = set(ignore)
    chosen: dict[str, str] = {target: source for source, target in mapping.items()}
    unknown = []
    for name in names:
        if name in mapping or name in left_out:
            continue
        if name in config.channels and name not in chosen:
            chosen[name] = name
        else:
            unknown.append(name)
    channels = ", ".join(config.channels)
    if unknown:
        raise LegacyFileError(
            f"{path}: signal(s) {', '.join(unknown)} are none of mill {config.id}'s channels "
            f"({channels}): name each with --map SIGNAL=CHANNEL, or leave it out with "
            f"--ignore SIGNAL"
        )
    missing = [c for c in config.channels if c not in chosen]
    if missing and not allow_missing:
        raise LegacyFileError(
            f"{path}: no signal for channel(s) {', '.join(missing)} of mill {config.id} (the "
            f"file has: {', '.join(names) or 'nothing'}): name one with --map SIGNAL=CHANNEL, "
            "or add --allow-missing to import without it (analysed as a dead channel, as live)"
        )
    return {c: chosen[c] for c in config.channels if c in chosen}


def _check_mapping(
    path: str, names: list[str], config: MillConfig, mapping: dict[str, str]
) -> None:
    targets: dict[str, str] = {}
    for source, target in mapping.items():
        if target not in config.channels:
            raise LegacyFileError(
                f"--map {source}={target}: {target!r} is not a channel of mill {config.id} "
                f"(channels: {', '.join(config.channels)})"
            )
        if source not in names:
            raise LegacyFileError(
                f"--map {source}={target}: {path} has no signal {source!r} (it has: "
                f"{', '.join(names) or 'nothing'})"
            )
        if target in targets:
            raise LegacyFileError(
                f"--map: signals {targets[target]!r} and {source!r} both map to {target!r}"
            )
        targets[target] = source


def build(
    path: str, tracks: list[SourceTrack], config: MillConfig, channels: dict[str, str]
) -> Recording:
    """The :class:`Recording` of ``tracks`` for ``channels`` (``{channel: signal name}``,
    :func:`assign_channels`) on the grid of ``config.sample_rate_hz`` (module docstring)."""
    if not channels:
        raise LegacyFileError(f"{path}: no signal to import")
    fs = float(config.sample_rate_hz)
    by_name = {t.name: t for t in tracks}
    chosen = {c: by_name[s] for c, s in channels.items()}
    t0 = min(t.t0_ns for t in chosen.values())
    runs: dict[str, tuple[Run, ...]] = {}
    for channel, track in chosen.items():
        where = f"{path}: {track.name}"
        offset = _grid_offset(track.t0_ns - t0, fs, where)
        runs[channel] = tuple(
            Run(offset + start, values) for start, values in _track_runs(track, fs, where)
        )
    return Recording(path, t0, fs, runs, dict(channels))


def _grid_offset(delta_ns: int, fs: float, where: str) -> int:
    """Grid index of a signal that starts ``delta_ns`` after the recording's first sample."""
    pos = delta_ns * fs / 1e9
    k = round(pos)
    if abs(pos - k) > GRID_TOLERANCE:
        raise LegacyFileError(
            f"{where}: starts {delta_ns / 1e9:.9f} s after the recording's first sample, "
            f"{abs(pos - k):.2f} sample periods off the {fs:g} Hz grid of the other signals"
        )
    return k


def _track_runs(track: SourceTrack, fs: float, where: str) -> list[tuple[int, np.ndarray]]:
    values = np.asarray(track.values, dtype=np.float64)
    if values.ndim != 1 or values.shape[0] == 0:
        raise LegacyFileError(
            f"{where}: expected a non-empty row of samples, got shape {values.shape}"
        )
    if track.fs is not None:
        if abs(track.fs / fs - 1.0) > RATE_TOLERANCE:
            raise LegacyFileError(_rate_message(where, track.fs, fs))
        return [(0, values)]
    assert track.rel_s is not None
    return _timestamped_runs(track, values, np.asarray(track.rel_s, np.float64), fs, where)


def _rate_message(where: str, got: float, fs: float) -> str:
    return (
        f"{where}: sampled at {got:g} Hz, but the mill file's sample_rate_hz is {fs:g}: "
        "millwatch does not resample; resample the recording, or use a mill file with its rate"
    )


def _timestamped_runs(
    track: SourceTrack, values: np.ndarray, rel: np.ndarray, fs: float, where: str
) -> list[tuple[int, np.ndarray]]:
    """Runs ``(first grid index, values)`` of a timestamped signal (module docstring)."""
    n = rel.shape[0]
    bad = np.flatnonzero(~np.isfinite(rel))
    if bad.size:
        raise LegacyFileError(f"{where}: {track.row(int(bad[0]))}: the time is not a number")
    if n > 1:
        step = float(np.median(np.diff(rel)))
        if not step > 0 or abs(step * fs - 1.0) > STEP_TOLERANCE:
            got = 1.0 / step if step > 0 else float("nan")
            raise LegacyFileError(
                _rate_message(where, got, fs) + f" (its median time step is {step:g} s; times "
                "are in seconds)"
            )
    pos = rel * fs
    k = np.rint(pos)
    off = np.abs(pos - k)
    bad = np.flatnonzero(off > GRID_TOLERANCE)
    if bad.size:
        i = int(bad[0])
        raise LegacyFileError(
            f"{where}: {track.row(i)}: its time ({rel[i]:.9f} s after the first sample) lies "
            f"{off[i]:.2f} sample periods off the {fs:g} Hz grid of the first sample; the "
            "import takes uniformly sampled recordings (a gap must be a whole number of periods)"
        )
    step_k = np.diff(k)
    back = np.flatnonzero(step_k <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise LegacyFileError(
            f"{where}: {track.row(i)}: its time ({rel[i]:.9f} s after the first sample) does "
            f"not come after the one before ({rel[i - 1]:.9f} s); times must increase"
        )
    cuts = [0, *(np.flatnonzero(step_k > 1) + 1).tolist(), n]
    return [(int(k[a]), values[a:b]) for a, b in itertools.pairwise(cuts) if b > a]
