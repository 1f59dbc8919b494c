"""Pacing: when a timestamped block is due on the wall clock, at ``speed`` × real time.

Shared by ``millwatch replay`` (archive log time) and ``millwatch simulate --publish``
(simulated sample time): both publish blocks "as they happened", faster or slower.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

__all__ = ["DEFAULT_LATE_THRESHOLD_S", "PacingClock", "PacingError"]

log = logging.getLogger(__name__)

#: A block later than this (s, wall time) re-anchors the clock (see PacingClock).
DEFAULT_LATE_THRESHOLD_S = 0.05
_NS_PER_S = 1_000_000_000


class PacingError(ValueError):
    """A pacing parameter is out of range (speed <= 0, negative threshold)."""


class PacingClock:
    """Maps archive log time (ns) to monotonic wall time (s) at ``speed`` × real time.

    Why an anchor and not a sleep per message: sleeping ``Δt/speed`` between consecutive
    blocks adds every sleep's overshoot (tens to hundreds of µs) and every publish's cost to
    the schedule, so the error *accumulates* — at 4 000 blocks/s a replay of one hour falls
    minutes behind. Instead each block's due time is computed from one fixed pair
    (``anchor_wall`` s, ``anchor_archive_ns``)::

        due = anchor_wall + (t_archive - anchor_archive_ns) / 1e9 / speed

    so an overshoot delays one block only and the next is still scheduled from the anchor.

    Why re-anchor: when the replayer falls behind by more than ``late_threshold_s`` (a slow
    subscriber pushing back through BLOCK congestion control, a GC pause, a suspended
    laptop), keeping the old anchor would make it publish the whole backlog at full speed to
    "catch up" — a burst the live pipeline never saw. The clock instead re-anchors at the
    late block (pacing resumes from now, the lag is accepted) and counts the event in
    ``late_resyncs``. A pause and a speed change re-anchor for the same reason: after them
    the old anchor is meaningless (a pause would look like lateness; a new speed with the
    old anchor would jump the archive position).

    ``speed=None`` means as fast as possible: nothing is ever due later than now.
    """

    def __init__(
        self,
        speed: float | None = 1.0,
        late_threshold_s: float = DEFAULT_LATE_THRESHOLD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        check_speed(speed)
        if not (math.isfinite(late_threshold_s) and late_threshold_s >= 0):
            raise PacingError(f"late threshold must be >= 0 s, got {late_threshold_s}")
        self.speed = speed
        self.late_threshold_s = late_threshold_s
        self.late_resyncs = 0
        self._clock = clock
        self._anchor_wall: float | None = None
        self._anchor_archive_ns = 0

    def anchor(self, archive_ns: int, wall: float | None = None) -> None:
        """Archive time ``archive_ns`` is (re)mapped to wall time ``wall`` (default now)."""
        self._anchor_wall = self._clock() if wall is None else wall
        self._anchor_archive_ns = archive_ns

    def position_ns(self) -> int | None:
        """Archive time that corresponds to now (None before the first anchor or at max)."""
        if self._anchor_wall is None or self.speed is None:
            return None
        elapsed = max(0.0, self._clock() - self._anchor_wall)
        return self._anchor_archive_ns + round(elapsed * self.speed * _NS_PER_S)

    def set_speed(self, speed: float | None, archive_ns: int | None = None) -> None:
        """Change speed from now on, re-anchored at the current archive position (or at
        ``archive_ns``), so the archive time neither jumps nor stalls at the change."""
        check_speed(speed)
        here = self.position_ns() if archive_ns is None else archive_ns
        self.speed = speed
        self.reanchor(here)

    def reanchor(self, archive_ns: int | None) -> None:
        """Anchor ``archive_ns`` at now; ``None`` drops the anchor, so the next block
        anchors afresh (is due at once)."""
        if archive_ns is None:
            self._anchor_wall = None
        else:
            self.anchor(archive_ns)

    def wait_s(self, archive_ns: int) -> float:
        """Seconds to wait before the block at ``archive_ns`` is due (0 = publish now).

        The first call anchors; a block late by more than ``late_threshold_s`` re-anchors
        and counts one late re-sync.
        """
        if self.speed is None:
            return 0.0
        now = self._clock()
        if self._anchor_wall is None:
            self.anchor(archive_ns, now)
            return 0.0
        due = self._anchor_wall + (archive_ns - self._anchor_archive_ns) / _NS_PER_S / self.speed
        if now - due > self.late_threshold_s:
            self.late_resyncs += 1
            log.debug("pacing: %.3f s late at %d ns, re-anchoring", now - due, archive_ns)
            self.anchor(archive_ns, now)
            return 0.0
        return max(0.0, due - now)


def check_speed(speed: float | None) -> None:
    """Raise :class:`PacingError` unless ``speed`` is a finite number > 0 or None (max)."""
    if speed is not None and not (math.isfinite(speed) and speed > 0):
        raise PacingError(f"speed must be a finite number > 0 (or max), got {speed}")
