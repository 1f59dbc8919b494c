"""A simulated mill on zenoh: scene blocks published live, on the mill's live keys.

This is a stand-in for a plant's sensor gateway (``millwatch simulate --publish`` and the demo).
The scene is re-timed to start *now* (or at an anchor), so its samples carry current timestamps,
and each block is published when it is complete — at ``speed`` × real time (``speed`` 60 shows
an hour a minute; the samples' timestamps then run ahead of the wall clock by the same factor).
Blocks go out through gateway publishers (:mod:`millwatch.ingest.gateway`): congestion control
BLOCK, and
a cache of the last ``retention_s`` of each channel from which a restarted worker recovers.

**Resuming as a restarted gateway would** (``anchored=True``): the scene's first sample is due
on the wall clock at the scene's ``t0`` (sample time ``t`` is due at
``t0 + (t - t0) / speed``). Blocks that fell due before :meth:`ScenePublisher.run` started are
*not* published — they are lost, as for a real DAQ that was off — and the next block keeps its
scene sequence number and timestamps. Sequence numbers are per channel and count from the
scene's start (:func:`millwatch.ingest.sim.blocks.scene_blocks`), so a gateway restarted with the
same anchor and seed continues the numbering and the lost span is exactly the blocks that fell due
while it was down.

**With a spool** (``spool=``, :mod:`millwatch.ingest.spool`): each block is spooled before it is
published, and blocks the spool already holds (published before a restart) are not published
again, so the numbering continues from the spool's last ``seq`` per channel.

**Never ahead of the wall clock** (``never_ahead=True``, the demo): a block waits until its last
sample's time has passed on the wall clock, so a scene re-timed to start in the past replays at
``speed`` until it meets the present and then runs live (1×); a receiver's lag stays ≥ 0.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import zenoh

from millwatch.ingest import keys, wire
from millwatch.ingest.gateway import (
    DEFAULT_RETENTION_S,
    GatewayPublisher,
    declare_gateway_publisher,
)
from millwatch.ingest.pacing import PacingClock
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.spec import SceneSpec
from millwatch.ingest.spool.resume import unspooled

if TYPE_CHECKING:
    from millwatch.ingest.spool.store import Spool

__all__ = ["PublishReport", "ScenePublisher", "starting_now"]

log = logging.getLogger(__name__)

_NS_PER_S = 1_000_000_000


def starting_now(scene: Scene, now_ns: int | None = None) -> Scene:
    """The same scene with its first sample at ``now_ns`` (default: now, whole ms)."""
    t0 = (time.time_ns() if now_ns is None else now_ns) // 1_000_000 * 1_000_000
    spec = SceneSpec.model_validate({**scene.spec.model_dump(), "t0_ns": t0})
    return Scene(scene.config, spec)


@dataclass(frozen=True)
class PublishReport:
    """``blocks`` published; ``skipped`` blocks that fell due before the run started
    (``anchored`` only); ``first_seq``: the scene sequence number of the first block published
    (None if none was)."""

    blocks: int
    samples_per_channel: int
    wall_s: float
    stopped_early: bool
    skipped: int = 0
    first_seq: int | None = None


class ScenePublisher:
    """Publish every block of ``scene`` on ``session``, paced by sample time."""

    def __init__(
        self,
        session: zenoh.Session,
        scene: Scene,
        *,
        speed: float | None = 1.0,
        block_samples: int = 100,
        dtype: wire.DType = wire.DType.FLOAT32,
        wait_subscribers_s: float = 0.0,
        retention_s: float = DEFAULT_RETENTION_S,
        anchored: bool = False,
        spool: Spool | None = None,
        never_ahead: bool = False,
    ) -> None:
        """``wait_subscribers_s``: before its first block, wait up to this long for someone to
        subscribe (a gateway publishes regardless; a test wants every block delivered).
        ``retention_s``: sample time kept per channel for recovery. ``anchored``: the scene's
        ``t0`` is its wall-clock start; blocks already due are skipped (see module docstring);
        needs a finite ``speed``. ``spool``: blocks are spooled before they are published, and
        those it holds already are not published again (module docstring). ``never_ahead``: no
        block goes out before its last sample's time on the wall clock (a replay started in
        the past runs at ``speed`` until it catches up, then live), so a receiver's lag is
        never negative and no event lies in the future (the demo)."""
        if anchored and speed is None:
            raise ValueError("anchored publishing needs a finite speed")
        self.scene = scene
        self._wait_subscribers_s = wait_subscribers_s
        self._session = session
        self._pacer = PacingClock(speed, late_threshold_s=0.5)
        self._block_samples = block_samples
        self._dtype = dtype
        self._retention_s = retention_s
        self._anchored = anchored
        self._spool = spool
        self._never_ahead = never_ahead
        #: Blocks not published because the spool holds them (published before a restart).
        self.spooled_before: Counter[str] = Counter()
        self._publishers: dict[str, GatewayPublisher] = {}
        self.published = 0
        self.skipped = 0

    def run(self, stop: threading.Event | None = None) -> PublishReport:
        """Publish until the scene ends or ``stop`` is set; undeclares its publishers."""
        stop = stop or threading.Event()
        started = time.monotonic()
        last_end, first_seq = 0, None
        blocks = scene_blocks(self.scene, block_samples=self._block_samples, dtype=self._dtype)
        if self._anchored:
            blocks = self._skip_due(blocks)
        if self._spool is not None:
            blocks = unspooled(blocks, self._spool, _block_key, _block_seq, self.spooled_before)
        try:
            for block in blocks:
                if not self._publishers:  # once the first block is known (anchored: skips)
                    self._declare_all()
                if stop.wait(self._wait_s(block.t_end_ns)):
                    break
                self._publisher(block.key).put(block.payload)
                first_seq = block.seq if first_seq is None else first_seq
                self.published += 1
                last_end = max(last_end, block.t_end_ns)
        finally:
            self._undeclare()
        n = round((last_end - self.scene.t_ns(0)) * self.scene.fs / 1e9) if last_end else 0
        wall = time.monotonic() - started
        return PublishReport(
            self.published, n, wall, stop.is_set(), self.skipped, first_seq
        )  # fmt: skip

    def _wait_s(self, t_end_ns: int) -> float:
        """Seconds until the block ending at ``t_end_ns`` is due: paced, and with
        ``never_ahead`` not before that sample time on the wall clock."""
        wait = self._pacer.wait_s(t_end_ns)
        if self._never_ahead:
            wait = max(wait, (t_end_ns - time.time_ns()) / _NS_PER_S)
        return wait

    def _skip_due(self, blocks: Iterator[SceneBlock]) -> Iterator[SceneBlock]:
        """Anchor pacing on the wall clock at the scene's t0; drop blocks already due."""
        t0 = self.scene.t_ns(0)
        speed = self._pacer.speed
        assert speed is not None
        now_ns, now = time.time_ns(), time.monotonic()
        # the scene's t0 falls at wall-clock time t0 (in the past or the future); from there
        # scene time runs ``speed`` × wall time, so the anchor is t0 on the monotonic clock
        self._pacer.anchor(t0, now - (now_ns - t0) / _NS_PER_S)
        due_from = t0 + round(max(0, now_ns - t0) * speed)  # sample time due now
        for block in blocks:
            if block.t_end_ns < due_from:
                self.skipped += 1
                continue
            self._log_resume(block.seq, due_from - t0)
            yield block
            yield from blocks
            return
        self._log_resume(None, due_from - t0)

    def _log_resume(self, seq: int | None, behind_ns: int) -> None:
        level = logging.WARNING if self.skipped else logging.INFO
        log.log(level, "gateway starts %.1f s (scene time) after the scene's anchor: %d blocks "
                "fell due before it started and are not published (lost); next sequence %s",
                max(0, behind_ns) / _NS_PER_S, self.skipped,
                "none (scene over)" if seq is None else seq)  # fmt: skip

    def _declare_all(self) -> None:
        """Declare every channel's publisher before the first block, then wait (at most
        ``wait_subscribers_s``) for a subscriber: a worker subscribes a mill once a gateway
        publisher of each of its channels is up (issue 16), so declaring them one by one,
        waiting after the first, would stall both."""
        config = self.scene.config
        for key in keys.mill_channel_keys(config).values():
            self._publisher(key)
        first = next(iter(self._publishers.values()), None)
        waits = first is not None and self._wait_subscribers_s > 0
        if waits and first is not None and not first.wait_for_subscribers(self._wait_subscribers_s):
            log.warning("no subscriber for %s after %.1f s; publishing anyway",
                        first.key, self._wait_subscribers_s)  # fmt: skip

    def _publisher(self, key: str) -> GatewayPublisher:
        publisher = self._publishers.get(key)
        if publisher is None:
            publisher = declare_gateway_publisher(
                self._session,
                key,
                blocks_per_s=self.scene.fs / self._block_samples,
                retention_s=self._retention_s,
                spool=self._spool,
            )
            self._publishers[key] = publisher
        return publisher

    def _undeclare(self) -> None:
        for publisher in self._publishers.values():
            try:
                publisher.undeclare()
            except zenoh.ZError as exc:  # a closed session already undeclared it
                log.debug("undeclare failed: %s", exc)
        self._publishers.clear()


def _block_key(block: SceneBlock) -> str:
    return block.key


def _block_seq(block: SceneBlock) -> int:
    return block.seq
