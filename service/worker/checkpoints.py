"""When each mill is checkpointed, and which archived blocks a mill's checkpoint already covers.

Issue 5 (sample-to-store latency): checkpointing every mill at once serialised ~1.9 MB of JSON
per mill on the worker thread — ~95 MB and seconds of stalled block processing at 50 mills.
Instead each mill is checkpointed on its own, every ``interval_s``, the mills' turns spread
evenly over the interval (:class:`CheckpointSchedule`); at each step the worker checkpoints the
mills whose turn has come within a small time budget, so a step stalls for about one mill's
snapshot and write (~10–30 ms), never for all of them.

Each mill's checkpoint carries the archive position it was taken at. Recovery restores every
mill's newest checkpoint, replays the archive from the earliest of those positions and, per mill,
skips the blocks that lie before the mill's own position (:func:`covers`): their effect is
already in the snapshot. Every mill so sees each of its blocks exactly once, as in an
uninterrupted run.

A mill whose checkpoint cannot be restored (:class:`CheckpointRestoreError`) is *held* by the
worker: left out of the positions the replay starts from and out of the schedule, and never
checkpointed, so its last good checkpoint stays as it is until the configuration is reverted.

A *damaged* checkpoint is another matter: every checkpoint is stored with a SHA-256 checksum
(:mod:`millwatch.store.checkpoint_seal`) and verified before it is parsed, and one that is
truncated, changed or not JSON is refused (:func:`refusal_message` names the mill, the
checkpoint and the store file). The mill then starts from its previous kept checkpoint, or — if
none of its kept checkpoints is intact — from nothing, replaying the archive from its start
(:func:`fallback`); the other mills start as usual, and the worker never stops for it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import numpy as np
import numpy.typing as npt

from millwatch.alarms.times import iso_utc
from millwatch.ingest.archive.files import ArchivePosition, archive_file_order
from millwatch.store.database import CheckpointChoice, RefusedCheckpoint

__all__ = [
    "CheckpointRestoreError",
    "CheckpointSchedule",
    "MillHeldError",
    "covers",
    "earliest",
    "fallback",
    "refusal_message",
]

#: Checkpoint work allowed per worker step (s) once the first due mill is done; mills left over
#: are checkpointed at the next steps (they wait at most a few steps).
STEP_BUDGET_S = 0.05


class CheckpointRestoreError(RuntimeError):
    """A mill's checkpoint could not be restored at start; the message names the mill, the
    checkpoint's archive position and time, what went wrong and what the operator can do."""

    def __init__(self, mill_id: str, position: ArchivePosition | None, cause: Exception) -> None:
        self.mill_id = mill_id
        super().__init__(
            f"mill {mill_id}: its checkpoint {_where(position)} cannot be restored: {cause}. "
            "If the mill's configuration was changed since that checkpoint, revert the change "
            "and start the worker again: the mill then restores from that checkpoint, kept as "
            "it is, and replays the archive it missed"
        )


class MillHeldError(RuntimeError):
    """An action needs the analysis of a mill the worker holds (its checkpoint could not be
    restored), e.g. acknowledging one of its alarms; the message names the mill and why."""

    def __init__(self, mill_id: str, reason: str) -> None:
        self.mill_id = mill_id
        super().__init__(f"mill {mill_id} is not analysed (held) until its checkpoint can be "
                         f"restored: {reason}")  # fmt: skip


def _where(position: ArchivePosition | None) -> str:
    """A checkpoint's archive position in words."""
    if position is None:
        return "(taken without an archive position)"
    at = f"at archive file {position.file}, message {position.index}"
    if position.log_time_ns:
        at += f", logged {iso_utc(position.log_time_ns)}"
    return f"({at})"


class CheckpointSchedule:
    """Turns of the parts (mills) to be checkpointed, each every ``interval_s`` seconds of the
    monotonic ``clock``, the first turns spread evenly over one interval."""

    def __init__(
        self,
        parts: Iterable[str],
        interval_s: float,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not interval_s > 0:
            raise ValueError(f"checkpoint interval must be > 0 s, got {interval_s!r}")
        self.parts = sorted(parts)
        self.interval_s = float(interval_s)
        self._clock = clock
        self._next: dict[str, float] = {}
        self.restart()

    def restart(self) -> None:
        """Spread the next turns over one interval from now (at start, after a recovery)."""
        now, n = self._clock(), len(self.parts)
        self._next = {p: now + self.interval_s * (i + 1) / n for i, p in enumerate(self.parts)}

    def drop(self, part: str) -> None:
        """No more turns for ``part`` (a held mill)."""
        if part in self._next:
            self.parts.remove(part)
            del self._next[part]

    def due(self) -> list[str]:
        """The parts whose turn has come, the longest waiting first."""
        now = self._clock()
        return sorted((p for p, t in self._next.items() if t <= now), key=self._next.__getitem__)

    def done(self, part: str) -> None:
        """``part`` was just checkpointed: its next turn is one interval after this one; a part
        that fell far behind (the worker was busy) gets half an interval from now instead, so
        late turns do not pile up into a burst."""
        if part not in self._next:
            return
        now = self._clock()
        self._next[part] = max(self._next[part] + self.interval_s, now + self.interval_s / 2)


def covers(position: ArchivePosition | None, file: str, index: npt.ArrayLike) -> np.ndarray:
    """Which of the messages at ``index`` of archive file ``file`` lie before ``position`` (so a
    checkpoint taken at ``position`` already holds their effect): a boolean array shaped like
    ``index``, all False for no position."""
    at = np.asarray(index)
    if position is None:
        return np.zeros(at.shape, dtype=bool)
    if file == position.file:
        return at < position.index
    before = archive_file_order(file) < archive_file_order(position.file)
    return np.full(at.shape, before, dtype=bool)


def earliest(positions: Iterable[ArchivePosition | None]) -> ArchivePosition | None:
    """The earliest of ``positions`` in archive order; ``None`` (replay from the archive's
    start) when there is none or one of them is ``None``."""
    items = list(positions)
    known = [p for p in items if p is not None]
    if not items or len(known) < len(items):
        return None
    return min(known, key=lambda p: (archive_file_order(p.file), p.index))


def fallback(choice: CheckpointChoice, mill_id: str) -> str:
    """What mill ``mill_id`` starts from once its damaged newer checkpoints are refused."""
    if mill_id in choice.chosen:
        return f"its previous checkpoint, written {iso_utc(choice.chosen[mill_id][1])}"
    return "the start of the archive (none of its kept checkpoints is intact)"


def refusal_message(refused: RefusedCheckpoint, store: str, choice: CheckpointChoice) -> str:
    """The log line of a refused checkpoint: mill, checkpoint, store file, what is wrong, what
    the mill starts from instead."""
    return (
        f"mill {refused.part}: its checkpoint #{refused.checkpoint_id} written "
        f"{iso_utc(refused.created_ns)} in store {store} is refused: {refused.reason}. "
        f"The mill starts from {fallback(choice, refused.part)}; the other mills are not "
        "affected"
    )
