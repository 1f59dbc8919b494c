"""Replay: archive sources, key remapping, anchored pacing, and real zenoh round trips.

Zenoh runs on 127.0.0.1 only (the subscriber's session listens on a free loopback port, the
replayer's dials it), multicast scouting off; every wait is bounded and every session closed.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np
import pytest
import zenoh

from millwatch.ingest import keys, wire
from millwatch.ingest.archive.files import list_archive_files
from millwatch.ingest.archive.reader import ArchivedBlock
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.gateway import GatewayPublisher
from millwatch.ingest.pacing import PacingClock, PacingError
from millwatch.ingest.replay import (
    KeyRemap,
    PublisherFactory,
    Replayer,
    ReplayError,
    ReplayProgress,
    ReplayReport,
    archive_blocks,
    collect_archive_files,
)
from millwatch.ingest.zenoh_session import (
    build_config,
    declare_block_publisher,
    declare_block_subscriber,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)

T0 = 1_763_767_800_000_000_000  # 2025-11-21T23:30:00Z
MS = 1_000_000
WAIT_S = 5.0
KEYS = [keys.build_key("s1", "m1", s) for s in ("motor_torque", "pinion_torque", "speed")]
PROBE = b"probe"
Item = tuple[str, bytes]


# ---------------------------------------------------------------- archive fixtures


def payload(i: int, n: int = 10) -> bytes:
    """A block whose samples and seq identify ``i``."""
    samples = np.arange(n, dtype=np.float32) + i
    return wire.encode_block(samples, T0 + i * 2 * MS, 1000.0, i, wire.Unit.KILONEWTON_METRE)


def write_archive(
    directory: Path, count: int = 300, step_ns: int = 2 * MS, prefix: str = "m1", **kw: float
) -> list[tuple[str, int, bytes]]:
    """``count`` blocks round-robin on KEYS, log times T0 + i·step_ns; returns what was written."""
    written = []
    with ArchiveWriter(directory, prefix, **kw) as writer:
        for i in range(count):
            item = (KEYS[i % len(KEYS)], T0 + i * step_ns, payload(i))
            writer.write(item[0], item[2], item[1])
            written.append(item)
    return written


def by_key(items: list[Item]) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    for key, data in items:
        out.setdefault(key, []).append(data)
    return out


# ---------------------------------------------------------------- zenoh helpers


@dataclass
class Loopback:
    """Two peers on 127.0.0.1: ``listener`` (subscriber side) and ``dialer`` (replayer side)."""

    endpoint: str
    listener: zenoh.Session
    dialer: zenoh.Session
    inbox: queue.Queue[Item] = field(default_factory=queue.Queue)

    def subscribe(self, pattern: str) -> zenoh.Subscriber:
        return declare_block_subscriber(
            self.listener, pattern, lambda k, p: self.inbox.put((k, p), timeout=WAIT_S)
        )

    def ready(self, key: str) -> None:
        """End-to-end readiness: probes on ``key`` (every 20 ms, ≤ WAIT_S s) until one arrives."""
        publisher = declare_block_publisher(self.dialer, key)
        try:
            for _ in range(int(WAIT_S / 0.02)):
                publisher.put(PROBE)
                try:
                    if self.inbox.get(timeout=0.02)[1] == PROBE:
                        return
                except queue.Empty:
                    continue
            raise AssertionError("no probe delivered")
        finally:
            publisher.undeclare()

    def drain(self, count: int, timeout_s: float = WAIT_S) -> list[Item]:
        """The next ``count`` non-probe messages, each waited for at most ``timeout_s`` s."""
        return drain(self.inbox, count, timeout_s)


def drain(inbox: queue.Queue[Item], count: int, timeout_s: float = WAIT_S) -> list[Item]:
    received: list[Item] = []
    for _ in range(count + 1000):  # bounded: at most 1000 stray probes
        if len(received) == count:
            break
        item = inbox.get(timeout=timeout_s)
        if item[1] != PROBE:
            received.append(item)
    return received


def leftovers(inbox: queue.Queue[Item], quiet_s: float = 0.2) -> list[Item]:
    """Non-probe messages arriving within ``quiet_s`` s of silence (expected: none)."""
    extra = []
    for _ in range(100_000):
        try:
            item = inbox.get(timeout=quiet_s)
        except queue.Empty:
            break
        if item[1] != PROBE:
            extra.append(item)
    return extra


@contextmanager
def loopback() -> Iterator[Loopback]:
    endpoint = tcp_endpoint(free_loopback_port())
    with ExitStack() as stack:
        listener = stack.enter_context(
            open_session(build_config(listen=[endpoint], loopback_only=True))
        )
        dialer = stack.enter_context(
            open_session(build_config(connect=[endpoint], loopback_only=True))
        )
        yield Loopback(endpoint, listener, dialer)
    assert listener.is_closed() and dialer.is_closed()


# ---------------------------------------------------------------- sources


def test_collect_expands_directories_and_names_bad_paths(tmp_path: Path) -> None:
    write_archive(tmp_path / "a", 30, rotate_seconds=0.02)
    files = collect_archive_files([tmp_path / "a", *sorted((tmp_path / "a").glob("*.mcap"))])
    assert len(files) == len(list((tmp_path / "a").glob("*.mcap"))) > 1  # duplicates dropped
    (tmp_path / "empty").mkdir()
    (tmp_path / "x.mcap").write_bytes(b"not mcap at all")
    (tmp_path / "x.txt").write_text("hello")
    cases = {
        tmp_path / "missing.mcap": "no such file",
        tmp_path / "empty": "no .mcap files",
        tmp_path / "x.mcap": "not an MCAP file",
        tmp_path / "x.txt": "expected a .mcap file",
    }
    for path, message in cases.items():
        with pytest.raises(ReplayError, match=message) as err:
            collect_archive_files([path])
        assert str(path) in str(err.value)


def test_rotated_files_of_several_writers_merge_in_log_time_order(tmp_path: Path) -> None:
    m1 = write_archive(tmp_path, 200, step_ns=4 * MS, prefix="m1", rotate_seconds=0.1)
    m2 = [(keys.to_replay(k, "x"), t + MS, p) for k, t, p in m1]  # other keys, interleaved
    with ArchiveWriter(tmp_path, "m2", rotate_seconds=0.1) as writer:
        for key, t, data in m2:
            writer.write(key, data, t)
    files = collect_archive_files([tmp_path])
    assert len(list_archive_files(tmp_path, "m1")) > 5  # really rotated
    got = [(b.key, b.log_time_ns, b.payload) for b in archive_blocks(files)]
    assert got == sorted(m1 + m2, key=lambda item: item[1])


def test_a_subset_of_rotated_files_and_a_lone_file(tmp_path: Path) -> None:
    written = write_archive(tmp_path / "d", 100, step_ns=10 * MS, rotate_seconds=0.2)
    rotated = list_archive_files(tmp_path / "d", "m1")
    chosen = collect_archive_files([rotated[1], rotated[3]])
    got = [b.log_time_ns for b in archive_blocks(chosen)]
    in_files = {t for t in range(T0 + 200 * MS, T0 + 400 * MS, 10 * MS)}
    in_files |= set(range(T0 + 600 * MS, T0 + 800 * MS, 10 * MS))
    assert got == sorted(in_files)
    lone = tmp_path / "copy.mcap"
    lone.write_bytes(rotated[0].read_bytes())
    blocks = list(archive_blocks(collect_archive_files([lone]), KEYS[1]))
    assert [(b.key, b.payload) for b in blocks] == [
        (k, p) for k, _, p in written[:20] if k == KEYS[1]
    ]


def test_time_range_and_key_pattern_filters(tmp_path: Path) -> None:
    written = write_archive(tmp_path, 300)
    files = collect_archive_files([tmp_path])
    start, end = T0 + 100 * MS, T0 + 300 * MS
    got = list(archive_blocks(files, keys.mill_pattern("s1", "m1"), start, end))
    assert [b.payload for b in got] == [p for _, t, p in written if start <= t < end]
    speed_only = list(archive_blocks(files, "millwatch/v1/*/m1/speed", start))
    assert {b.key for b in speed_only} == {KEYS[2]}
    assert len(speed_only) == len([1 for k, t, _ in written if k == KEYS[2] and t >= start])
    assert list(archive_blocks(files, keys.replay_pattern())) == []  # @replay never matched by *
    with pytest.raises(keys.KeyFormatError):
        archive_blocks(files, "millwatch/v1/s$*/**")


# ---------------------------------------------------------------- keys


def test_remap_forms_build_keys_through_the_keys_module() -> None:
    key = KEYS[2]
    assert KeyRemap(run="r1").apply(key) == keys.to_replay(key, "r1")
    assert KeyRemap.from_prefix("millwatch/v1/@replay/r1").apply(key) == keys.to_replay(key, "r1")
    lab_replay = KeyRemap.from_prefix("millwatch/v1/@replay/r1/lab")
    assert lab_replay.apply(key) == keys.build_key("lab", "m1", "speed", replay_run="r1")
    assert KeyRemap.from_prefix("millwatch/v1/lab/").apply(key) == keys.build_key(
        "lab", "m1", "speed"
    )
    assert KeyRemap(run="r1").subscription() == keys.replay_pattern("r1")
    replayed = keys.to_replay(key, "old")  # an archive of a replay: the run is replaced
    assert KeyRemap(run="r2").apply(replayed) == keys.to_replay(key, "r2")


@pytest.mark.parametrize(
    "prefix",
    ["millwatch/v2/lab", "other/v1/lab", "millwatch/v1", "millwatch/v1/@replay",
     "millwatch/v1/lab/m1", "millwatch/v1/Lab", "millwatch/v1/*", "millwatch/v1/@replay/R1",
     "millwatch/v1/@replay/r1/s1/m1"],
)  # fmt: skip
def test_bad_remap_prefixes_are_refused(prefix: str) -> None:
    with pytest.raises(ReplayError, match="remap"):
        KeyRemap.from_prefix(prefix)


def test_remap_never_lands_on_the_recorded_live_key() -> None:
    with pytest.raises(ReplayError, match="live"):
        KeyRemap()
    with pytest.raises(ReplayError, match="own live key"):
        KeyRemap(site="s1").apply(KEYS[0])
    with pytest.raises(keys.KeyFormatError):
        KeyRemap(run="r1").apply("somewhere/else")


# ---------------------------------------------------------------- pacing clock


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_pacing_schedules_against_the_anchor() -> None:
    clock = FakeClock()
    pacer = PacingClock(speed=2.0, clock=clock)
    assert pacer.wait_s(T0) == 0.0  # first block anchors
    assert pacer.wait_s(T0 + 100 * MS) == pytest.approx(0.05)
    clock.now += 0.03
    assert pacer.wait_s(T0 + 200 * MS) == pytest.approx(0.07)
    assert PacingClock(speed=None, clock=clock).wait_s(T0 + 10**12) == 0.0


def test_sleep_overshoot_does_not_accumulate() -> None:
    """1000 blocks 10 ms apart, every wait overshooting by 1 ms and every publish costing
    0.1 ms: a sleep per message would take 11.1 s; the anchored schedule takes 10 s."""
    clock = FakeClock()
    pacer = PacingClock(speed=1.0, late_threshold_s=0.05, clock=clock)
    start = clock.now
    for i in range(1000):
        wait = pacer.wait_s(T0 + i * 10 * MS)
        clock.now += (wait + 0.001 if wait > 0 else 0.0) + 0.0001
    assert clock.now - start == pytest.approx(9.99 + 0.0011, abs=1e-6)
    assert pacer.late_resyncs == 0


def test_late_blocks_reanchor_and_are_counted() -> None:
    clock = FakeClock()
    pacer = PacingClock(speed=1.0, late_threshold_s=0.05, clock=clock)
    pacer.wait_s(T0)
    clock.now += 0.04  # 0.03 s late for the block at +10 ms: under the threshold
    assert pacer.wait_s(T0 + 10 * MS) == 0.0
    assert pacer.late_resyncs == 0
    clock.now += 1.0  # a stall: the block at +20 ms is ~1 s late
    assert pacer.wait_s(T0 + 20 * MS) == 0.0
    assert pacer.late_resyncs == 1
    assert pacer.wait_s(T0 + 30 * MS) == pytest.approx(0.01)  # paced again from the new anchor


def test_speed_change_keeps_the_archive_position() -> None:
    clock = FakeClock()
    pacer = PacingClock(speed=1.0, clock=clock)
    pacer.wait_s(T0)
    clock.now += 0.5
    pacer.set_speed(10.0)
    assert pacer.position_ns() == T0 + 500 * MS
    assert pacer.wait_s(T0 + 1500 * MS) == pytest.approx(0.1)
    pacer.set_speed(None)
    assert pacer.wait_s(T0 + 10**12) == 0.0
    pacer.set_speed(1.0)  # from max: the next block anchors afresh, not "late"
    assert pacer.wait_s(T0 + 2000 * MS) == 0.0
    assert pacer.late_resyncs == 0
    with pytest.raises(PacingError, match="speed"):
        pacer.set_speed(0.0)


# ---------------------------------------------------------------- replayer (fake zenoh)


class FakePublisher:
    def __init__(self, key: str, log: list[tuple[str, bytes, float]]) -> None:
        self.key, self.log, self.undeclared = key, log, False
        self.matching_status = True

    def put(self, data: bytes) -> None:
        self.log.append((self.key, data, time.monotonic()))

    def undeclare(self) -> None:
        self.undeclared = True


class FakeSession:
    """Stands in for a zenoh session where only pacing/control logic is under test."""

    def __init__(self) -> None:
        self.log: list[tuple[str, bytes, float]] = []
        self.publishers: list[FakePublisher] = []

    def declare_publisher(self, key: str, **_: object) -> FakePublisher:
        self.publishers.append(FakePublisher(key, self.log))
        return self.publishers[-1]


def fake_factory(session: FakeSession) -> PublisherFactory:
    """Publishers of the fake session in place of gateway publishers (pacing tests only)."""
    return lambda key, _rate: cast(GatewayPublisher, session.declare_publisher(key))


def blocks_every(step_ms: int, count: int, key: str = KEYS[0]) -> list[ArchivedBlock]:
    return [ArchivedBlock(key, T0 + i * step_ms * MS, payload(i), "f", i) for i in range(count)]


def replay_with(
    session: FakeSession,
    blocks: list[ArchivedBlock],
    speed: float | None,
    at: int,
    action: Callable[[Replayer], None],
    late_threshold_s: float = 0.15,
) -> ReplayReport:
    """Replay on the fake session; ``action(replayer)`` runs once ``at`` blocks are out. A block
    is late after ``late_threshold_s``: under the 0.2 s pause (a pause counted as lateness is
    caught) and over a busy 2-core machine's scheduling stalls (the default 0.05 s is not)."""
    box: list[Replayer] = []

    def on_progress(p: ReplayProgress) -> None:
        if p.blocks == at:
            action(box[0])

    fake = cast(zenoh.Session, session)
    remap = KeyRemap(run="r1")
    box.append(Replayer(fake, blocks, remap, speed=speed, on_progress=on_progress,
                        progress_interval_s=0.0, late_threshold_s=late_threshold_s,
                        publisher_factory=fake_factory(session)))  # fmt: skip
    return box[0].run()


def test_pause_resumes_where_it_stopped_without_counting_late() -> None:
    session = FakeSession()

    def pause_for_200ms(replayer: Replayer) -> None:
        replayer.pause()
        threading.Timer(0.2, replayer.resume).start()

    report = replay_with(session, blocks_every(10, 21), 1.0, 10, pause_for_200ms)  # 0.2 s
    times = [t for _, _, t in session.log]
    assert report.blocks == 21 and report.late_resyncs == 0
    assert 0.2 <= times[10] - times[9] <= 0.35  # the pause, plus one 10 ms step
    assert times[-1] - times[10] == pytest.approx(0.1, abs=0.05)  # pacing resumed, no burst
    assert all(p.undeclared for p in session.publishers)


def test_speed_change_mid_replay() -> None:
    session = FakeSession()
    report = replay_with(session, blocks_every(10, 41), 1.0, 11, lambda r: r.set_speed(4.0))
    times = [t for _, _, t in session.log]
    assert times[10] - times[0] == pytest.approx(0.1, abs=0.05)
    assert times[40] - times[10] == pytest.approx(0.3 / 4, abs=0.05)  # not 0.3 s at 1x
    assert report.speed == 4.0 and report.late_resyncs == 0


def test_stop_mid_replay() -> None:
    session = FakeSession()
    report = replay_with(session, blocks_every(10, 41), None, 5, lambda r: r.stop())
    assert report.blocks == 5 and report.stopped and len(session.log) == 5


def test_keys_that_are_not_channel_keys_are_skipped_and_counted() -> None:
    session = FakeSession()
    blocks = [*blocks_every(1, 3), ArchivedBlock("some/other/key", T0, b"x", "f", 9)]
    report = Replayer(
        cast(zenoh.Session, session),
        blocks,
        KeyRemap(run="r1"),
        speed=None,
        publisher_factory=fake_factory(session),
    ).run()
    assert report.blocks == 3 and report.skipped_by_key == {"some/other/key": 1}
    assert {k for k, _, _ in session.log} == {keys.to_replay(KEYS[0], "r1")}


# ---------------------------------------------------------------- real zenoh on loopback


def test_replay_at_max_delivers_every_block_once_in_order_byte_identical(tmp_path: Path) -> None:
    written = write_archive(tmp_path, 300)
    remap = KeyRemap(run="t1")
    with loopback() as net:
        subscriber = net.subscribe(remap.subscription())
        net.ready(remap.apply(KEYS[0]))
        blocks = archive_blocks(collect_archive_files([tmp_path]))
        report = Replayer(net.dialer, blocks, remap, speed=None).run()
        received = net.drain(len(written))
        extra = leftovers(net.inbox)
        subscriber.undeclare()
    expected = [(keys.to_replay(k, "t1"), p) for k, _, p in written]
    assert by_key(received) == by_key(expected)  # each key: all blocks, in order, same bytes
    assert extra == []  # and nothing twice
    assert report.blocks == 300 and report.bytes == sum(len(p) for _, _, p in written)
    assert report.blocks_by_key == {keys.to_replay(k, "t1"): 100 for k in KEYS}
    assert all(keys.parse_key(k).replay_run == "t1" for k, _ in received)


def test_replay_at_speed_two_takes_half_the_archive_span(tmp_path: Path) -> None:
    written = write_archive(tmp_path, 300)  # log times span 0.598 s
    remap = KeyRemap(run="t2")
    arrivals: list[float] = []

    def stamp(key: str, data: bytes) -> None:
        if data != PROBE:
            arrivals.append(time.monotonic())

    with loopback() as net:
        subscriber = net.subscribe(remap.subscription())
        timer = declare_block_subscriber(net.listener, remap.subscription(), stamp)
        net.ready(remap.apply(KEYS[0]))
        t = time.monotonic()
        report = Replayer(
            net.dialer, archive_blocks(collect_archive_files([tmp_path])), remap, speed=2.0
        ).run()
        wall = time.monotonic() - t
        assert len(net.drain(len(written))) == len(written)
        timer.undeclare()
        subscriber.undeclare()
    assert report.archive_span_s == pytest.approx(0.598)
    # paced at 2x: 0.3 s (unpaced would be ~0, 1x 0.6 s); a loaded machine may stall ~0.1 s
    assert report.wall_s == pytest.approx(0.299, abs=0.1)
    assert 0.29 <= wall <= 0.5
    assert arrivals[-1] - arrivals[0] == pytest.approx(0.299, abs=0.1)  # seen by the subscriber
    assert report.x_real_time == pytest.approx(2.0, rel=0.3)
    assert report.late_resyncs <= 1  # a loaded CI machine may stall once
