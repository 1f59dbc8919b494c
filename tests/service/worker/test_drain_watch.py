"""The readiness check that a mill's blocks are still being analysed."""

from __future__ import annotations

from millwatch.status import ChannelStatus, MillHealthStatus, MillStatus
from millwatch.worker.drain_watch import DrainWatch
from millwatch.worker.health import ChannelHealth


def status(blocks: int, samples: int, held: str | None = None) -> MillStatus:
    """A mill's status with one channel (its health as the worker's health reports it)."""
    channel = ChannelStatus.model_validate(ChannelHealth().as_dict(0, 10.0) | {"blocks": blocks})
    health = MillHealthStatus(stale_channels=[], channels={"a": channel})
    return MillStatus(health=health, samples=samples, held_reason=held)


def test_a_mill_whose_blocks_arrive_but_are_not_analysed_is_named() -> None:
    now = [0.0]
    watch = DrainWatch(20.0, clock=lambda: now[0])
    for k in range(30):  # 15 s of blocks, analysis moving
        now[0] = k * 0.5
        watch.update({"m1": status(10 * k, 100 * k), "m2": status(10 * k, 100 * k)})
    assert watch.stalled == {}
    for k in range(30, 90):  # then m1 stops analysing while its blocks keep coming
        now[0] = k * 0.5
        watch.update({"m1": status(10 * k, 2900), "m2": status(10 * k, 100 * k)})
    assert list(watch.stalled) == ["m1"] and "m1" in watch.stalled["m1"]
    now[0] += 0.5
    watch.update({"m1": status(900, 3000), "m2": status(900, 9000)})
    assert watch.stalled == {}


def test_a_mill_that_receives_nothing_or_is_held_is_not_stalled() -> None:
    now = [0.0]
    watch = DrainWatch(5.0, clock=lambda: now[0])
    for k in range(100):
        now[0] = k * 0.5
        watch.update({"idle": status(7, 700), "held": status(10 * k, 0, held="config changed")})
    assert watch.stalled == {}
