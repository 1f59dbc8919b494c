"""The gateway spool (millwatch.ingest.spool): runs, files, index across reopen and SIGKILL,
retention with
its exact dropped count, recovery over a real zenoh queryable on 127.0.0.1, the forwarder.

Blocks come from the simulator (``scene_blocks`` of a catalogue scene), as a gateway sends them.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from itertools import islice
from pathlib import Path

import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.cli.simulate import DEFAULT_MILL
from millwatch.ingest import keys
from millwatch.ingest.archive.files import list_archive_files
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.gateway import declare_gateway_publisher
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.forwarder import SpoolForwarder
from millwatch.ingest.spool.query import SpoolServer, fetch_spooled
from millwatch.ingest.spool.runs import SeqRuns
from millwatch.ingest.spool.store import PREFIX, Spool, SpoolError, SpoolRead, payload_seq
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)

ROOT = Path(__file__).resolve().parents[2]
CONFIG = load_mill_config(DEFAULT_MILL)
NS_PER_H = 3_600_000_000_000


def _blocks(n_per_channel: int) -> list[SceneBlock]:
    """The first ``n_per_channel`` blocks of every channel of a simulated start."""
    scene = get_scene("start-lrs", CONFIG, seed=3)
    n = n_per_channel * len(CONFIG.channels)
    return list(islice(scene_blocks(scene, block_samples=100), n))


BLOCKS = _blocks(60)
KEYS = sorted({b.key for b in BLOCKS})


class Clock:
    """A wall clock (ns) that advances ``step_ns`` each reading."""

    def __init__(self, step_ns: int = 25_000_000) -> None:
        self.now = 1_790_000_000_000_000_000
        self.step = step_ns

    def __call__(self) -> int:
        self.now += self.step
        return self.now


def _fill(spool: Spool, blocks: list[SceneBlock]) -> None:
    for b in blocks:
        assert spool.append(b.key, b.payload) == b.seq


def _seqs(payloads: list[bytes]) -> list[int]:
    return [s for s in map(payload_seq, payloads) if s is not None]


# ---------------------------------------------------------------- runs
@given(st.sets(st.integers(0, 300), max_size=120), st.integers(0, 300), st.integers(0, 300))
@settings(max_examples=200, deadline=None)
def test_runs_hold_exactly_the_numbers_added(numbers: set[int], a: int, b: int) -> None:
    runs = SeqRuns()
    for n in sorted(numbers, key=lambda x: (x * 7919) % 301):  # any order
        runs.add(n)
    lo, hi = min(a, b), max(a, b)
    assert runs.count(lo, hi) == len([n for n in numbers if lo <= n <= hi])
    assert runs.intersects(lo, hi) == any(lo <= n <= hi for n in numbers)
    assert runs.last == (max(numbers) if numbers else None)
    flat = [n for first, last in runs.runs() for n in range(first, last + 1)]
    assert flat == sorted(numbers)
    assert all(r2[0] > r1[1] + 1 for r1, r2 in zip(runs.runs(), runs.runs()[1:], strict=False))
    assert SeqRuns(runs.runs()).runs() == runs.runs()


# ---------------------------------------------------------------- files, index, reopen
def test_blocks_come_back_byte_identical_in_seq_order_and_the_index_survives_reopen(tmp_path):
    clock = Clock()
    with Spool(tmp_path, rotate_bytes=40_000, clock=clock) as spool:
        _fill(spool, BLOCKS)
        files = spool.stats()["files"]
    assert files > 2  # rotated
    by_key = {k: {b.seq: b.payload for b in BLOCKS if b.key == k} for k in KEYS}
    with Spool(tmp_path, rotate_bytes=40_000, clock=clock) as spool:
        for key in KEYS:
            assert spool.last_seq(key) == 59
            assert spool.held(key).runs() == [[0, 59]]
            got = spool.read(key, 10, 49)
            assert got.dropped == 0
            assert got.blocks == [by_key[key][s] for s in range(10, 50)]
            assert _seqs(spool.read(key, 0, 100, limit=7).blocks) == list(range(7))
        assert spool.stats()["blocks"] == len(BLOCKS)


def test_a_second_process_on_the_same_spool_is_refused(tmp_path):
    with Spool(tmp_path), pytest.raises(SpoolError, match="in use"):
        Spool(tmp_path)


def test_a_killed_writer_leaves_a_file_read_up_to_its_last_complete_record(tmp_path):
    """A real SIGKILL of a process appending, then a torn tail on top (a kill mid-write)."""
    script = (
        "import sys, time\n"
        "from millwatch.ingest.spool.store import Spool\n"
        "from tests.ingest.test_spool import BLOCKS\n"
        "spool = Spool(sys.argv[1])\n"
        "for b in BLOCKS[:100]:\n"
        "    spool.append(b.key, b.payload)\n"
        "print('spooled', flush=True)\n"
        "time.sleep(60)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)], cwd=ROOT,
                            stdout=subprocess.PIPE)  # fmt: skip
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == b"spooled"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    [path] = list_archive_files(tmp_path, PREFIX)
    reader = TailTolerantReader(path)
    assert len(list(reader.messages())) == 100 and not reader.finished  # no footer: killed
    with open(path, "ab") as f:  # half of a message record: a kill in the middle of a write
        f.write(b"\x05" + (500).to_bytes(8, "little") + b"\x01\x00" + b"x" * 40)
    with Spool(tmp_path) as spool:
        assert spool.stats()["blocks"] == 100
        for key in KEYS:
            want = [b.payload for b in BLOCKS[:100] if b.key == key]
            assert spool.read(key, 0, 1000).blocks == want
            assert spool.last_seq(key) == payload_seq(want[-1])
    assert path.with_name(path.name + ".json").exists()  # indexed once, not read again


# ---------------------------------------------------------------- retention
@pytest.mark.parametrize("by", ["size", "hours"])
def test_retention_drops_the_oldest_files_first_and_counts_exactly(tmp_path, by):
    clock = Clock(step_ns=NS_PER_H // 100 if by == "hours" else 25_000_000)
    size = 40_000
    bound = {"max_bytes": 5 * size} if by == "size" else {"hours": 1.0}
    with Spool(tmp_path, rotate_bytes=size, rotate_seconds=1200.0, clock=clock,
               **bound) as spool:  # type: ignore[arg-type]  # fmt: skip
        _fill(spool, BLOCKS)
        stats = spool.stats()
        assert stats["dropped_blocks"] > 0
        assert stats["dropped_blocks"] + stats["blocks"] == len(BLOCKS)
        if by == "size":
            assert stats["bytes"] <= 5 * size + size  # the bound, plus the file being written
    with Spool(tmp_path, rotate_bytes=size, clock=clock, **bound) as spool:  # type: ignore[arg-type]
        dropped = spool.dropped_blocks
        assert dropped >= stats["dropped_blocks"]  # (hours: time went on; counted on, not anew)
        assert dropped + spool.stats()["blocks"] == len(BLOCKS)
        for key in KEYS:
            [[first, last]] = spool.held(key).runs()  # what is left is the newest, contiguous
            assert last == 59 and first > 0
            got = spool.read(key, 0, 59)
            assert got.dropped == first  # exactly seqs 0..first-1 are gone
            assert _seqs(got.blocks) == list(range(first, 60))
            assert spool.read(key, 0, first - 1) == SpoolRead([], first)
            assert spool.last_seq(key) == 59  # the numbering continues after what was dropped
    ledger = json.loads((tmp_path / "dropped.json").read_text())
    assert ledger["dropped_blocks"] == dropped


# ---------------------------------------------------------------- over zenoh
def _pair(stack: ExitStack) -> tuple[zenoh.Session, zenoh.Session]:
    port = free_loopback_port()
    gateway = stack.enter_context(open_session(build_config(listen=[tcp_endpoint(port)])))
    worker = stack.enter_context(open_session(build_config(connect=[tcp_endpoint(port)])))
    return gateway, worker


def _answered(worker: zenoh.Session, key: str, first: int, last: int, **kw: object) -> Iterator:
    """Ask until a spool answers (the queryable is declared a moment after the link is up)."""
    for _ in range(50):
        got = fetch_spooled(worker, key, first, last, 5.0, **kw)  # type: ignore[arg-type]
        if got.answered:
            yield got
            return
        time.sleep(0.1)
    yield got


def test_a_gateway_spools_before_publishing_and_answers_ranges_in_order(tmp_path):
    key = KEYS[0]
    mine = [b for b in BLOCKS if b.key == key]
    with ExitStack() as stack:
        gateway, worker = _pair(stack)
        spool = stack.enter_context(Spool(tmp_path, max_bytes=10**9))
        server = SpoolServer(gateway, spool)
        stack.callback(server.close)
        publisher = stack.enter_context(
            declare_gateway_publisher(gateway, key, blocks_per_s=10.0, spool=spool)
        )
        for b in mine:
            publisher.put(b.payload)
        [got] = _answered(worker, key, 5, 54, page=16)  # four pages
        assert got.answered and got.dropped == 0
        assert got.blocks == [b.payload for b in mine[5:55]]
        none = fetch_spooled(worker, keys.build_key("s9", "m9", "speed"), 0, 10, 2.0)
        assert (none.blocks, none.answered) == ([], False)  # no spool of that key: no hang


def test_the_forwarder_spools_a_plain_gateway_and_serves_recovery(tmp_path):
    key = KEYS[1]
    mine = [b for b in BLOCKS if b.key == key]
    with ExitStack() as stack:
        gateway, worker = _pair(stack)
        spool = stack.enter_context(Spool(tmp_path))
        # the forwarder beside the gateway: a session linked to it (here the peer's)
        forwarder = SpoolForwarder(worker, spool, [keys.live_pattern()])
        stack.callback(forwarder.close)
        publisher = stack.enter_context(gateway.declare_publisher(key))
        deadline = time.monotonic() + 5.0
        while not publisher.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        for b in mine:
            publisher.put(b.payload)
        for _ in range(100):
            if spool.last_seq(key) == mine[-1].seq:
                break
            time.sleep(0.05)
        [got] = _answered(gateway, key, 0, 59)
        assert got.blocks == [b.payload for b in mine]


def test_replayed_keys_have_their_own_spool_keys():
    live = keys.build_key("s1", "m1", "speed")
    replayed = keys.to_replay(live, "r1")
    assert keys.spool_key(live) == live + "/@spool"
    assert keys.parse_spool_key(keys.spool_key(replayed)) == replayed
    assert not keys.key_matches(keys.live_pattern(), keys.spool_key(live))
    assert not keys.key_matches("millwatch/v1/**", keys.spool_key(live))
    with pytest.raises(keys.KeyFormatError):
        keys.parse_spool_key(live)


def test_a_file_killed_before_its_header_is_set_aside_not_fatal(tmp_path):
    clock = Clock()
    with Spool(tmp_path, clock=clock) as spool:
        _fill(spool, BLOCKS[:8])
    (tmp_path / "spool_20991231T000000Z.mcap").write_bytes(b"")  # killed right after open()
    with Spool(tmp_path, clock=clock) as spool:
        assert spool.stats()["blocks"] == 8
        _fill(spool, BLOCKS[8:16])
    assert (tmp_path / "spool_20991231T000000Z.mcap.unreadable").exists()
