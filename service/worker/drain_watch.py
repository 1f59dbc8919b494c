"""Whether each mill's blocks are still being analysed: the ``draining`` check of ``/ready``.

Issue 16: a flood of clock-faulted duplicates once stopped a mill's analysis while ``/ready``
still answered ready. :class:`DrainWatch` looks at what the worker's status shows twice a second
— blocks accepted and samples analysed per mill — and calls a mill *stalled* when blocks kept
arriving for it but its analysed samples did not move for ``stall_after_s`` seconds of wall
time. A mill that receives nothing (stopped gateway, outage) is not stalled: staleness says that.
A silent channel does not stall the others either: the worker stops waiting for it after
``stale_after_s`` (:meth:`millwatch.worker.worker.Worker.check_staleness`), so the default bound is
twice that.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from millwatch.status import MillStatus

__all__ = ["DrainWatch"]


@dataclass
class _Progress:
    blocks: int
    samples: int
    since: float  # monotonic time the samples last moved (or the watch first saw the mill)


class DrainWatch:
    """Per mill: stalled or not (see the module docstring); feed it every status refresh."""

    def __init__(self, stall_after_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.stall_after_s = stall_after_s
        self._clock = clock
        self._progress: dict[str, _Progress] = {}
        #: Stalled mills: mill id → what the operator should read.
        self.stalled: dict[str, str] = {}

    def update(self, status: Mapping[str, MillStatus]) -> None:
        """Take the worker's status (``Worker.status``: the channels' blocks and the samples
        analysed per mill; held mills are not analysed on purpose and are skipped)."""
        now = self._clock()
        for mill_id, s in status.items():
            if s.held_reason:
                self._progress.pop(mill_id, None)
                self.stalled.pop(mill_id, None)
                continue
            blocks = sum(c.blocks for c in s.channel_health.values())
            samples = s.samples or 0
            last = self._progress.get(mill_id)
            if last is None or samples != last.samples or blocks == last.blocks:
                # analysis moving, or nothing new to analyse: not stalled; the clock restarts
                self._progress[mill_id] = _Progress(blocks, samples, now)
                self.stalled.pop(mill_id, None)
                continue
            last.blocks = blocks
            waited = now - last.since
            if waited > self.stall_after_s:
                self.stalled[mill_id] = (
                    f"mill {mill_id}: blocks keep arriving but none of its samples were analysed "
                    f"for {waited:.0f} s (analysis stuck at {samples} samples)"
                )
