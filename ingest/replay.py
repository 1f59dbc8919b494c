"""Replay archived blocks to zenoh, byte-identical, with their original pacing.

An engineer replays MCAP recordings through the pipeline to re-analyse or test it (DESIGN:
"the same analyzer object must serve ... ``millwatch replay`` of an MCAP file through zenoh").
This module is the library behind ``millwatch replay``; it has no command-line code.

Three parts, each usable alone:

- **Sources** — :func:`collect_archive_files` expands files and directories into archive files;
  :func:`archive_blocks` reads them as one stream of
  :class:`~millwatch.ingest.archive.reader.ArchivedBlock`,
  filtered by key pattern and log-time range and merged across writers in log-time order.
  Rotated files of one writer (``<prefix>_<stamp>Z.mcap`` in one directory) are read in file
  order through :class:`~millwatch.ingest.archive.reader.ArchiveReader` (which skips finished files
  outside the
  time range from their summary); other files are read alone, front to back, torn tail
  tolerated.
- **Keys** — :class:`KeyRemap` decides where replayed blocks go. By default each block goes to
  the replay key of its channel, ``millwatch/v1/@replay/<run>/<site>/<mill>/<signal>``, which no
  live subscriber (``millwatch/v1/**``) can receive. Keys are built by :mod:`millwatch.ingest.keys`
  only.
- **Pacing** — :class:`PacingClock` maps archive log time to wall time at ``speed`` × real time
  (or no waiting at all), and :class:`Replayer` publishes each block's payload, exactly as
  archived, through a gateway publisher (:mod:`millwatch.ingest.gateway`: BLOCK congestion control,
  and a
  cache of the last ``retention_s`` of each key, so a worker restarted mid-replay recovers what
  it missed) when its time comes.

Pacing follows the archived *log time* (the ingest daemon's receive time), so a replay
reproduces the arrival pattern the live pipeline saw, gaps and bursts included.
"""

from __future__ import annotations

import dataclasses
import heapq
import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import zenoh

from millwatch.ingest import keys, wire
from millwatch.ingest.archive.files import MCAP_MAGIC, ArchivePosition, list_archive_files
from millwatch.ingest.archive.reader import ArchivedBlock, ArchiveReader, TailTolerantReader
from millwatch.ingest.gateway import (
    DEFAULT_RETENTION_S,
    GatewayPublisher,
    declare_gateway_publisher,
)
from millwatch.ingest.pacing import DEFAULT_LATE_THRESHOLD_S, PacingClock

if TYPE_CHECKING:
    from millwatch.ingest.spool.store import Spool

__all__ = [
    "KeyRemap",
    "PacingClock",
    "PublisherFactory",
    "ReplayError",
    "ReplayProgress",
    "ReplayReport",
    "Replayer",
    "archive_blocks",
    "collect_archive_files",
]

log = logging.getLogger(__name__)

#: Waits shorter than this (s) are not worth a sleep: the block is published at once.
MIN_WAIT_S = 0.0002
#: Longest single wait (s), so pause/stop/speed changes are seen promptly.
MAX_WAIT_S = 0.1
#: Blocks per second assumed for a key whose first archived block does not decode (sizes its
#: cache only): 100-sample blocks at 1 kHz.
FALLBACK_BLOCKS_PER_S = 10.0
_NS_PER_S = 1_000_000_000


class ReplayError(ValueError):
    """A replay input or option is unusable; the message names the file or option."""


# --------------------------------------------------------------------------- sources


def _check_mcap(path: Path) -> Path:
    try:
        with open(path, "rb") as stream:
            head = stream.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise ReplayError(f"{path}: cannot read ({exc.strerror})") from exc
    if head != MCAP_MAGIC:
        raise ReplayError(f"{path}: not an MCAP file (bad magic)")
    return path


def _expand(path: Path) -> list[Path]:
    if path.is_dir():
        found = sorted(p for p in path.glob("*.mcap") if p.is_file())
        if not found:
            raise ReplayError(f"{path}: directory holds no .mcap files")
        return found
    if not path.exists():
        raise ReplayError(f"{path}: no such file or directory")
    if path.suffix != ".mcap":
        raise ReplayError(f"{path}: expected a .mcap file or a directory of them")
    return [path]


def collect_archive_files(paths: Iterable[str | Path]) -> list[Path]:
    """Files to replay: ``.mcap`` files as given, directories expanded to their ``*.mcap``.

    Each file is checked to exist and to start with the MCAP magic; duplicates (a file given
    both alone and through its directory) are dropped. Raises :class:`ReplayError` naming the
    first bad path. The order returned is not the replay order (see :func:`archive_blocks`).
    """
    seen: dict[Path, None] = {}
    for given in paths:
        for path in _expand(Path(given)):
            seen.setdefault(_check_mcap(path).resolve(), None)
    if not seen:
        raise ReplayError("no archive files given")
    return list(seen)


@dataclass(frozen=True, slots=True)
class _Chain:
    """Files read one after the other: rotated files of one writer, or one lone file."""

    files: tuple[Path, ...]
    prefix: str | None = None


def _chains(files: Sequence[Path]) -> list[_Chain]:
    """Group archive-named files (``<prefix>_<stamp>Z[-n].mcap``) by directory and writer
    prefix, in rotation order; every other file is a chain of its own."""
    listings: dict[tuple[Path, str], list[Path]] = {}
    groups: dict[tuple[Path, str], set[Path]] = {}
    lone: list[_Chain] = []
    for path in files:
        group = (path.parent, path.name.rpartition("_")[0])
        if group[1] and group not in listings:
            listings[group] = list_archive_files(*group)
        if path in listings.get(group, ()):
            groups.setdefault(group, set()).add(path)
        else:
            lone.append(_Chain((path,)))
    chains = [
        _Chain(tuple(p for p in listings[group] if p in chosen), group[1])
        for group, chosen in groups.items()
    ]
    return chains + lone


def _in_range(t_ns: int, start_ns: int | None, end_ns: int | None) -> bool:
    return (start_ns is None or t_ns >= start_ns) and (end_ns is None or t_ns < end_ns)


def _lone_file_blocks(
    path: Path, pattern: str | None, start_ns: int | None, end_ns: int | None
) -> Iterator[ArchivedBlock]:
    reader = TailTolerantReader(path)
    for msg in reader.messages():
        if _in_range(msg.log_time_ns, start_ns, end_ns) and (
            pattern is None or keys.key_matches(pattern, msg.key)
        ):
            yield ArchivedBlock(msg.key, msg.log_time_ns, msg.payload, path.name, msg.index)
    if reader.error:
        log.warning("replay: %s read up to byte %d: %s", path, reader.valid_bytes, reader.error)


def _chain_blocks(
    chain: _Chain, pattern: str | None, start_ns: int | None, end_ns: int | None
) -> Iterator[ArchivedBlock]:
    if chain.prefix is None:
        yield from _lone_file_blocks(chain.files[0], pattern, start_ns, end_ns)
        return
    first = chain.files[0]
    order = {p.name: i for i, p in enumerate(list_archive_files(first.parent, chain.prefix))}
    wanted = {p.name for p in chain.files}
    last = order[chain.files[-1].name]
    reader = ArchiveReader(first.parent, chain.prefix)
    for block in reader.blocks(pattern, start_ns, end_ns, after=ArchivePosition(first.name, 0)):
        if block.file in wanted:
            yield block
        elif order.get(block.file, len(order)) > last:
            return  # past the last file asked for (files not asked for in between are skipped)


def archive_blocks(
    files: Sequence[Path],
    pattern: str | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> Iterator[ArchivedBlock]:
    """Archived blocks of ``files`` whose key matches ``pattern`` and log time is in
    ``[start_ns, end_ns)`` (ns since the Unix epoch, UTC; ``None`` = open).

    Order: files of one writer are read in rotation order; different writers (prefixes or
    directories) and lone files are merged by log time. Within a writer the archive order is
    kept, so blocks of one key come out in the order they were archived.
    """
    if pattern is not None:
        keys.key_matches(pattern, keys.ROOT)  # raises KeyFormatError now, not mid-replay
    streams = [_chain_blocks(c, pattern, start_ns, end_ns) for c in _chains(files)]
    if len(streams) == 1:
        return streams[0]
    return heapq.merge(*streams, key=lambda b: b.log_time_ns)


# --------------------------------------------------------------------------- keys


@dataclass(frozen=True, slots=True)
class KeyRemap:
    """Where replayed blocks go: replay run ``run`` (``None`` = live keys) and site ``site``
    (``None`` = the archived site).

    ``apply(key)`` keeps mill and signal and replaces the rest:

    ================================  =====================================================
    remap                             archived ``millwatch/v1/s1/m1/speed`` goes to
    ================================  =====================================================
    ``KeyRemap(run="r1")`` (default)  ``millwatch/v1/@replay/r1/s1/m1/speed``
    ``KeyRemap(run="r1", site="lab")``  ``millwatch/v1/@replay/r1/lab/m1/speed``
    ``KeyRemap(site="lab")``          ``millwatch/v1/lab/m1/speed`` (live keys of site ``lab``)
    ================================  =====================================================

    Live output keys need a site: ``KeyRemap()`` is refused, and a block whose remapped key
    equals its own live key raises :class:`ReplayError` — replayed data never lands on the
    live key it was recorded from.
    """

    run: str | None = None
    site: str | None = None

    def __post_init__(self) -> None:
        if self.run is None and self.site is None:
            raise ReplayError(
                "remap: replaying onto the recorded live keys would mix with live data; "
                "give a replay run or another site"
            )
        for name, value in (("run", self.run), ("site", self.site)):
            if value in (keys.WILD, keys.WILD_ANY):
                raise ReplayError(f"remap {name} {value!r}: wildcards are not allowed")
        try:  # validates both segments; the error names the bad one
            keys.site_pattern(self.site or keys.WILD, replay_run=self.run)
        except keys.KeyFormatError as exc:
            raise ReplayError(f"remap: {exc}") from exc

    @classmethod
    def from_prefix(cls, prefix: str) -> KeyRemap:
        """Parse ``--remap PREFIX``; three forms, each validated by :mod:`millwatch.ingest.keys`:

        - ``millwatch/v1/<site>`` — live keys, site replaced by ``<site>`` (a test site);
        - ``millwatch/v1/@replay/<run>`` — replay run ``<run>``, archived site kept;
        - ``millwatch/v1/@replay/<run>/<site>`` — replay run ``<run>``, site replaced.
        """
        chunks = prefix.strip("/").split("/")
        if chunks[:2] != [keys.ROOT, keys.LAYOUT_VERSION]:
            raise ReplayError(f"remap prefix {prefix!r}: {_PREFIX_FORMS}")
        rest = chunks[2:]
        if rest[:1] == [keys.REPLAY_TAG] and len(rest) in (2, 3):
            return cls(run=rest[1], site=rest[2] if len(rest) == 3 else None)
        if len(rest) == 1 and rest[0] != keys.REPLAY_TAG:
            return cls(run=None, site=rest[0])
        raise ReplayError(f"remap prefix {prefix!r}: {_PREFIX_FORMS}")

    def apply(self, key: str) -> str:
        """The output key of archived ``key``; raises :class:`millwatch.ingest.keys.KeyFormatError`
        if ``key`` is not a channel key, :class:`ReplayError` if it would land on itself live."""
        channel = keys.parse_key(key)
        out = dataclasses.replace(channel, site=self.site or channel.site, replay_run=self.run).expr
        if out == channel.as_live().expr:
            raise ReplayError(f"remap would publish {key!r} on its own live key {out!r}")
        return out

    def subscription(self) -> str:
        """The key expression that receives everything this remap publishes."""
        return keys.mill_pattern(self.site or keys.WILD, keys.WILD, replay_run=self.run)


_PREFIX_FORMS = (
    "expected millwatch/v1/<site>, millwatch/v1/@replay/<run> or millwatch/v1/@replay/<run>/<site>"
)


# --------------------------------------------------------------------------- pacing


# --------------------------------------------------------------------------- replayer


@dataclass(frozen=True, slots=True)
class ReplayProgress:
    """Progress so far: blocks and payload bytes published, archive log time reached (ns)."""

    blocks: int
    bytes: int
    archive_time_ns: int | None


@dataclass(frozen=True, slots=True)
class ReplayReport:
    """Outcome of :meth:`Replayer.run`.

    ``blocks_by_key`` counts published blocks per *output* key; ``skipped_by_key`` counts
    archived blocks whose key is not a channel key (not published). Log times are ns since
    the Unix epoch (UTC). ``wall_s`` runs from the first to the last publish, so
    ``x_real_time`` = archive span / ``wall_s`` is the pacing actually achieved;
    ``elapsed_s`` is the whole run (reading, waiting for subscribers). ``speed`` is the
    speed asked for last (``None`` = max).
    """

    blocks: int
    bytes: int
    blocks_by_key: dict[str, int]
    skipped_by_key: dict[str, int]
    first_log_time_ns: int | None
    last_log_time_ns: int | None
    wall_s: float
    elapsed_s: float
    late_resyncs: int
    speed: float | None
    stopped: bool

    @property
    def archive_span_s(self) -> float:
        """Log time from the first to the last block published, s."""
        if self.first_log_time_ns is None or self.last_log_time_ns is None:
            return 0.0
        return (self.last_log_time_ns - self.first_log_time_ns) / _NS_PER_S

    @property
    def x_real_time(self) -> float:
        """Archive seconds replayed per wall second (0 if nothing or one instant replayed)."""
        return self.archive_span_s / self.wall_s if self.wall_s > 0 else 0.0

    def summary(self) -> str:
        """A few human-readable lines for the CLI."""
        pace = "max" if self.speed is None else f"{self.speed:g}x"
        lines = [
            f"replayed {self.blocks} blocks ({self.bytes / 1e6:.3f} MB) on "
            f"{len(self.blocks_by_key)} keys, speed {pace}"
            + (" (stopped early)" if self.stopped else ""),
            f"  archive span {self.archive_span_s:.3f} s in {self.wall_s:.3f} s wall: "
            f"{self.x_real_time:.3g}x real time, {self.late_resyncs} late re-syncs",
        ]
        lines += [f"  {key}  {n}" for key, n in sorted(self.blocks_by_key.items())]
        lines += [f"  skipped (not a channel key) {k}  {n}" for k, n in self.skipped_by_key.items()]
        return "\n".join(lines)


@dataclass(slots=True)
class _Tally:
    blocks: int = 0
    bytes: int = 0
    by_key: Counter[str] = field(default_factory=Counter)
    skipped: Counter[str] = field(default_factory=Counter)
    first_ns: int | None = None
    last_ns: int | None = None
    first_wall: float | None = None
    last_wall: float | None = None

    def add(self, key: str, block: ArchivedBlock, wall: float) -> None:
        self.blocks += 1
        self.bytes += len(block.payload)
        self.by_key[key] += 1
        if self.first_ns is None:
            self.first_ns, self.first_wall = block.log_time_ns, wall
        self.last_ns, self.last_wall = block.log_time_ns, wall

    def progress(self) -> ReplayProgress:
        return ReplayProgress(self.blocks, self.bytes, self.last_ns)


ProgressCallback = Callable[[ReplayProgress], None]
#: ``(key, blocks_per_s) -> publisher``: how the replayer declares the publisher of an output
#: key (default: a gateway publisher on its session; tests of pacing pass a fake).
PublisherFactory = Callable[[str, float], GatewayPublisher]


class Replayer:
    """Publish archived blocks on ``session``, paced by their log time.

    ``blocks`` is any iterable of :class:`~millwatch.ingest.archive.reader.ArchivedBlock` (usually
    :func:`archive_blocks`); payloads go out exactly as archived, malformed ones included
    (the receiver counts them, as it would live). ``remap`` chooses the output keys;
    ``speed`` is × real time (``None`` = as fast as possible); ``late_threshold_s`` see
    :class:`PacingClock`. ``on_progress`` is called at most every ``progress_interval_s`` s
    and once at the end, on the replaying thread. Before the first block,
    ``wait_subscribers_s`` s at most are spent waiting for a subscriber to match (then the
    replay goes on regardless, with a warning). ``retention_s``: sample time each output key
    keeps for recovery (its cache is sized from the key's first block: fs / samples).
    ``spool``: every block is written to it before it is published (:mod:`millwatch.ingest.spool`).

    :meth:`pause`, :meth:`resume`, :meth:`set_speed` and :meth:`stop` may be called from any
    thread (or from ``on_progress``). One :meth:`run` per instance.
    """

    def __init__(
        self,
        session: zenoh.Session,
        blocks: Iterable[ArchivedBlock],
        remap: KeyRemap,
        *,
        speed: float | None = 1.0,
        late_threshold_s: float = DEFAULT_LATE_THRESHOLD_S,
        on_progress: ProgressCallback | None = None,
        progress_interval_s: float = 0.1,
        wait_subscribers_s: float = 0.0,
        retention_s: float = DEFAULT_RETENTION_S,
        publisher_factory: PublisherFactory | None = None,
        clock: Callable[[], float] = time.monotonic,
        spool: Spool | None = None,
    ) -> None:
        self._session = session
        self._spool = spool
        self._retention_s = retention_s
        self._declare = publisher_factory or self._declare_gateway_publisher
        self._blocks = blocks
        self._remap = remap
        self._pacer = PacingClock(speed, late_threshold_s, clock)
        self._clock = clock
        self._on_progress = on_progress
        self._progress_interval_s = progress_interval_s
        self._wait_subscribers_s = wait_subscribers_s
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stopped = threading.Event()
        self._paused_at: int | None = None
        self._paused = False
        self._resync = False
        self._publishers: dict[str, GatewayPublisher] = {}
        self._out_keys: dict[str, str | None] = {}
        self._tally = _Tally()
        self._next_progress = 0.0

    # -- control (any thread)

    def pause(self) -> None:
        """Hold publishing; the archive position reached is kept for :meth:`resume`."""
        with self._lock:
            if not self._paused:
                self._paused = True
                self._paused_at = self._pacer.position_ns()
        self._wake.set()

    def resume(self) -> None:
        """Continue after :meth:`pause`, re-anchored where the pause began (no burst, no
        skipped gap)."""
        with self._lock:
            if self._paused:
                self._paused = False
                self._resync = True
        self._wake.set()

    def set_speed(self, speed: float | None) -> None:
        """Change the speed (× real time, ``None`` = max) from now on; re-anchors."""
        with self._lock:
            self._pacer.set_speed(speed, self._paused_at if self._paused else None)
        self._wake.set()

    def stop(self) -> None:
        """Stop after the block being published; :meth:`run` returns its report."""
        self._stopped.set()
        self._wake.set()

    # -- the replay

    def run(self) -> ReplayReport:
        """Replay every block; returns the report. Publishers are undeclared on exit."""
        started = self._clock()
        try:
            for block in self._blocks:
                if self._stopped.is_set():
                    break
                self._replay_one(block)
        finally:
            self._undeclare()
        self._report_progress(force=True)
        return self._report(self._clock() - started)

    def _replay_one(self, block: ArchivedBlock) -> None:
        key = self._out_key(block.key)
        if key is None:
            self._tally.skipped[block.key] += 1
            return
        publisher = self._publisher(key, block.payload)
        if not self._wait_until_due(block.log_time_ns):
            return
        publisher.put(block.payload)
        self._tally.add(key, block, self._clock())
        self._report_progress()

    def _out_key(self, key: str) -> str | None:
        if key not in self._out_keys:
            try:
                self._out_keys[key] = self._remap.apply(key)
            except keys.KeyFormatError as exc:
                log.warning("replay: skipping archived key %r: %s", key, exc)
                self._out_keys[key] = None
        return self._out_keys[key]

    def _publisher(self, key: str, payload: bytes) -> GatewayPublisher:
        publisher = self._publishers.get(key)
        if publisher is None:
            publisher = self._publishers[key] = self._declare(key, _blocks_per_s(payload))
            if len(self._publishers) == 1 and self._wait_subscribers_s > 0:
                self._await_subscriber(publisher, key)
        return publisher

    def _declare_gateway_publisher(self, key: str, blocks_per_s: float) -> GatewayPublisher:
        return declare_gateway_publisher(
            self._session, key, blocks_per_s=blocks_per_s, retention_s=self._retention_s,
            spool=self._spool,
        )  # fmt: skip

    def _await_subscriber(self, publisher: GatewayPublisher, key: str) -> None:
        if not publisher.wait_for_subscribers(self._wait_subscribers_s):
            log.warning("replay: no subscriber matches %s after %.1f s; replaying anyway",
                        key, self._wait_subscribers_s)  # fmt: skip

    def _wait_until_due(self, archive_ns: int) -> bool:
        """Wait (interruptibly) until ``archive_ns`` is due; False if stopped meanwhile."""
        while not self._stopped.is_set():
            self._wake.clear()  # before reading the state: a later set() cuts the wait short
            with self._lock:
                wait = self._wait_s_locked(archive_ns)
            if wait < MIN_WAIT_S:
                return True
            self._wake.wait(min(wait, MAX_WAIT_S))
        return False

    def _wait_s_locked(self, archive_ns: int) -> float:
        if self._paused:
            return math.inf
        if self._resync:  # first block after a pause: resume where the pause began
            self._resync = False
            at = self._paused_at
            self._pacer.reanchor(None if at is None else min(at, archive_ns))
        return self._pacer.wait_s(archive_ns)

    def _report_progress(self, *, force: bool = False) -> None:
        if self._on_progress is None:
            return
        now = self._clock()
        if force or now >= self._next_progress:
            self._next_progress = now + self._progress_interval_s
            self._on_progress(self._tally.progress())

    def _undeclare(self) -> None:
        for publisher in self._publishers.values():
            try:
                publisher.undeclare()
            except zenoh.ZError as exc:  # a closed session already undeclared it
                log.debug("replay: undeclare failed: %s", exc)
        self._publishers.clear()

    def _report(self, elapsed_s: float) -> ReplayReport:
        t = self._tally
        wall = 0.0 if t.first_wall is None or t.last_wall is None else t.last_wall - t.first_wall
        return ReplayReport(
            blocks=t.blocks, bytes=t.bytes, blocks_by_key=dict(t.by_key),
            skipped_by_key=dict(t.skipped), first_log_time_ns=t.first_ns,
            last_log_time_ns=t.last_ns, wall_s=wall, elapsed_s=elapsed_s,
            late_resyncs=self._pacer.late_resyncs, speed=self._pacer.speed,
            stopped=self._stopped.is_set(),
        )  # fmt: skip


def _blocks_per_s(payload: bytes) -> float:
    """Block rate of a key from one of its blocks (fs / samples per block), for cache sizing."""
    try:
        block = wire.decode_block(payload)
    except wire.WireError:
        return FALLBACK_BLOCKS_PER_S
    n = block.samples.shape[0]
    return block.fs / n if n > 0 else FALLBACK_BLOCKS_PER_S
