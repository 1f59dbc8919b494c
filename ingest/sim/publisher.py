"""A simulated mill on zenoh: scene blocks published live, on the mill's live keys.

This is a stand-in for a plant's sensor gateway (``millwatch simulate --publish`` and the demo).
The scene is re-timed to start *now*, so its samples carry current timestamps, and each block is
published when it is complete — at ``speed`` × real time (``speed`` 60 shows an hour a minute;
the samples' timestamps then run ahead of the wall clock by the same factor). Publishers use
congestion control BLOCK: a slow subscriber slows the simulator instead of losing blocks.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

import zenoh

from ingest import wire
from ingest.pacing import PacingClock
from ingest.sim.blocks import scene_blocks
from ingest.sim.renderer import Scene
from ingest.sim.spec import SceneSpec
from ingest.zenoh_session import declare_block_publisher, wait_for_subscribers

__all__ = ["PublishReport", "ScenePublisher", "starting_now"]

log = logging.getLogger(__name__)


def starting_now(scene: Scene, now_ns: int | None = None) -> Scene:
    """The same scene with its first sample at ``now_ns`` (default: now, whole ms)."""
    t0 = (time.time_ns() if now_ns is None else now_ns) // 1_000_000 * 1_000_000
    spec = SceneSpec.model_validate({**scene.spec.model_dump(), "t0_ns": t0})
    return Scene(scene.config, spec)


@dataclass(frozen=True)
class PublishReport:
    blocks: int
    samples_per_channel: int
    wall_s: float
    stopped_early: bool


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
    ) -> None:
        """``wait_subscribers_s``: before its first block, wait up to this long for someone to
        subscribe (a gateway publishes regardless; a test wants every block delivered)."""
        self.scene = scene
        self._wait_subscribers_s = wait_subscribers_s
        self._session = session
        self._pacer = PacingClock(speed, late_threshold_s=0.5)
        self._block_samples = block_samples
        self._dtype = dtype
        self._publishers: dict[str, zenoh.Publisher] = {}
        self.published = 0

    def run(self, stop: threading.Event | None = None) -> PublishReport:
        """Publish until the scene ends or ``stop`` is set; undeclares its publishers."""
        stop = stop or threading.Event()
        started = time.monotonic()
        samples = 0
        blocks = scene_blocks(self.scene, block_samples=self._block_samples, dtype=self._dtype)
        try:
            for block in blocks:
                if stop.wait(self._pacer.wait_s(block.t_end_ns)):
                    break
                self._publisher(block.key).put(block.payload)
                self.published += 1
                samples = max(samples, block.t_end_ns)
        finally:
            for publisher in self._publishers.values():
                publisher.undeclare()
            self._publishers.clear()
        n = round((samples - self.scene.t_ns(0)) * self.scene.fs / 1e9) if samples else 0
        return PublishReport(self.published, n, time.monotonic() - started, stop.is_set())

    def _publisher(self, key: str) -> zenoh.Publisher:
        publisher = self._publishers.get(key)
        if publisher is None:
            publisher = declare_block_publisher(self._session, key, archived=True)
            if self._wait_subscribers_s > 0 and not wait_for_subscribers(
                publisher, self._wait_subscribers_s
            ):
                log.warning(
                    "no subscriber for %s after %.1f s; publishing anyway",
                    key,
                    self._wait_subscribers_s,
                )
            self._publishers[key] = publisher
        return publisher
