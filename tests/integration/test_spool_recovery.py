"""Nothing the gateway published is lost to outages its in-memory cache cannot cover (issue 25):
real processes on 127.0.0.1 — a gateway with a spool (``millwatch simulate --publish --spool``),
``millwatch serve``, and (c) a ``millwatch router`` between them.

(b) ``serve`` SIGKILLed; 10 s later the gateway SIGKILLed and restarted with the same ``--spool``
    (no ``--anchor-ns``: the spool keeps the scene's anchor), publishing again within 2 s of its
    port opening; ``serve`` restarted: every block the gateway spooled (hence published) is
    archived, and the only blocks missing are those that fell due while the gateway itself was
    down — reported once per channel with their exact count. What the gateway published and
    when it was down are read from its spool, observed, not assumed.
(c) The link (the router) down longer than the gateway's cache retention (2 s of sample time,
    shortened for the test): every block comes back, from the spool.

Bounds come from observed events (ports open, blocks archived, the spool's contents); every
wait is bounded. The gateway is stopped by the test once the worker caught up (the scene is
longer than the test needs), so a slow machine cannot end the scene during an outage.
"""

from __future__ import annotations

import signal
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

from millwatch.ingest.archive.files import list_archive_files
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.spool.store import PREFIX, Spool, payload_seq
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from tests.integration.live import (
    MILL_FILE,
    Api,
    Processes,
    data_quality,
    port_open,
    published,
    wait,
    write_settings,
)

pytestmark = pytest.mark.slow

CONFIG = load_mill_config(MILL_FILE)
CHANNELS = sorted(CONFIG.channels)
SPEED = 2.0
#: Longer than any run of the test: the test stops the gateway itself.
SCENE_ARGS = ("--scene", "start-lrs", "--mill", str(MILL_FILE), "--seed", "7",
              "--duration", "600s", "--dtype", "float32", "--no-progress")  # fmt: skip


def channel_of(key: str) -> str:
    return key.rsplit("/", 1)[1]


def archived_seqs(directory: Path) -> dict[str, set[int]]:
    seqs: dict[str, set[int]] = defaultdict(set)
    for key, seq in published(directory):
        seqs[channel_of(key)].add(seq)
    return dict(seqs)


def spooled_seqs(spool_dir: Path) -> dict[str, set[int]]:
    """What the spool holds per channel (open only while no gateway holds it)."""
    with Spool(spool_dir) as spool:
        return {
            channel_of(k): {s for a, b in spool.held(k).runs() for s in range(a, b + 1)}
            for k in spool.spooled_keys()
        }


def first_spooled_ns(spool_dir: Path, before: dict[str, set[int]]) -> int | None:
    """When the first block not in ``before`` was spooled (ns, UTC; spooled = published)."""
    times = [
        msg.log_time_ns
        for path in list_archive_files(spool_dir, PREFIX)
        for msg in TailTolerantReader(path).messages()
        if payload_seq(msg.payload) not in before.get(channel_of(msg.key), set())
    ]
    return min(times, default=None)


class Site:
    """A spooling gateway, ``serve`` and optionally a router, on loopback ports."""

    def __init__(self, directory: Path, *, router: bool = False) -> None:
        self.procs = Processes(directory)
        self.directory = directory
        self.spool = directory / "spool"
        self.port, api_port = free_loopback_port(), free_loopback_port()
        self.router_port = free_loopback_port() if router else None
        self.endpoint = tcp_endpoint(self.router_port or self.port)
        self.settings = write_settings(directory, api_port=api_port, connect=(self.endpoint,))
        if router:  # serve a client of the router (the plant layout, README "Scale-out")
            text = self.settings.read_text(encoding="utf-8")
            self.settings.write_text(text.replace("[zenoh]\n", '[zenoh]\nmode = "client"\n'))
        self.api = Api(api_port)

    def start_router(self) -> None:
        assert self.router_port is not None
        self.procs.start("router", "router", "--listen", tcp_endpoint(self.router_port))
        assert wait(lambda: port_open(self.router_port) or self.gone("router"), 30.0)
        assert not self.gone("router"), self.procs.logs()

    def start_gateway(self, *extra: str) -> float:
        """Start the gateway; returns when its port opened (monotonic s)."""
        where = ("--connect", self.endpoint) if self.router_port else ()
        self.procs.start("gateway", "simulate", *SCENE_ARGS, "--publish", "--speed", f"{SPEED:g}",
                         "--listen", tcp_endpoint(self.port), *where, "--spool", str(self.spool),
                         *extra)  # fmt: skip
        assert wait(lambda: port_open(self.port) or self.gone("gateway"), 30.0)
        assert not self.gone("gateway"), self.procs.logs()
        return time.monotonic()

    def start_serve(self) -> None:
        self.procs.start("serve", "serve", "--config", str(self.settings))
        assert wait(lambda: self.api.up() or self.gone("serve"), 30.0)
        assert not self.gone("serve"), self.procs.logs()

    def gone(self, name: str) -> bool:
        return self.procs.procs[name].poll() is not None

    def archived_more(self, than: int, timeout_s: float = 30.0) -> None:
        """Wait until every channel's archive holds more than ``than`` blocks."""

        def more() -> bool:
            seqs = archived_seqs(self.directory)
            return len(seqs) == len(CHANNELS) and all(len(s) > than for s in seqs.values())

        assert wait(more, timeout_s, every_s=0.5), self.procs.logs()

    def stop_gateway(self) -> None:
        """Ctrl-C the gateway (it finishes its spool) and wait for it."""
        proc = self.procs.procs["gateway"]
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)

    def caught_up(self, spooled: dict[str, set[int]], timeout_s: float = 30.0) -> bool:
        """Wait until the archive holds the spool's last block of every channel."""

        def done() -> bool:
            seqs = archived_seqs(self.directory)
            return all(max(s) in seqs.get(c, ()) for c, s in spooled.items())

        return bool(wait(done, timeout_s, every_s=0.5))


def losses(directory: Path) -> dict[str, list[tuple[int, int, int]]]:
    out: dict[str, list[tuple[int, int, int]]] = defaultdict(list)
    for e in data_quality(directory):
        if e.get("missing_blocks") and e.get("channel"):
            out[e["channel"]].append((e["first_seq"], e["last_seq"], e["missing_blocks"]))
    return dict(out)


def missing_reported(api: Api) -> dict[str, Any]:
    channels = api.mill().get("status", {}).get("health", {}).get("channels", {})
    mill = {c: float(h.get("missing_blocks", -1)) for c, h in channels.items()}
    return {"metrics": api.missing_per_channel(), "mill": mill}


def test_a_gateway_restarted_on_its_spool_during_a_worker_outage_loses_only_its_own_downtime(
    tmp_path,
):
    site = Site(tmp_path)
    try:
        site.start_gateway()
        site.start_serve()
        site.archived_more(20)
        site.procs.kill("serve")
        time.sleep(10.0)  # the worker's outage before the gateway's (the scenario)
        site.procs.kill("gateway")
        before = spooled_seqs(site.spool)  # everything it published (spooled first)
        site.start_gateway()  # the same --spool, no anchor: it resumes its scene
        port_open_ns = time.time_ns()
        site.start_serve()
        site.archived_more(max(len(s) for s in before.values()) + 20)
        site.stop_gateway()
        spooled = spooled_seqs(site.spool)
        assert site.caught_up(spooled), site.procs.logs()
        archived = archived_seqs(tmp_path)
        resumed_ns = first_spooled_ns(site.spool, before)
        assert resumed_ns is not None and resumed_ns - port_open_ns < 2e9, "resumed late"
        down: dict[str, tuple[int, int, int]] = {}
        for c in CHANNELS:
            assert before[c] <= archived[c], f"{c}: published before the kill, not archived"
            assert archived[c] == spooled[c], c  # every spooled block, nothing else
            first_after = min(spooled[c] - before[c])
            # (from its first block: a gateway that starts late skips what fell due before)
            gap = sorted(set(range(min(spooled[c]), max(spooled[c]) + 1)) - spooled[c])
            # only what fell due while the gateway was down: between its last spooled block
            # before the kill and its first after the restart
            assert gap == list(range(max(before[c]) + 1, first_after)), (c, gap[:5], gap[-5:])
            assert gap, "the gateway's restart took no time at all?"
            down[c] = (gap[0], gap[-1], len(gap))
        expected = {c: float(n) for c, (_, _, n) in down.items()}
        want = {"metrics": expected, "mill": expected}
        assert wait(lambda: missing_reported(site.api) == want, 15.0), missing_reported(site.api)
        assert losses(tmp_path) == {c: [d] for c, d in down.items()}  # once, exact
        assert site.procs.stop("serve") == 0, site.procs.logs()
    finally:
        site.procs.stop_all()


def test_a_link_outage_longer_than_the_cache_recovers_from_the_spool(tmp_path):
    site = Site(tmp_path, router=True)
    try:
        site.start_router()
        site.start_gateway("--retention", "2s")  # 20 blocks a channel in memory
        site.start_serve()
        site.archived_more(40)  # (whichever phase the worker's subscriber is in: the spool fills)
        site.procs.kill("router")
        before = max(len(s) for s in archived_seqs(tmp_path).values())
        time.sleep(6.0)  # 6 s at 2x: 120 blocks a channel, six times the cache
        site.start_router()
        site.archived_more(before + 200, timeout_s=45.0)
        site.stop_gateway()
        spooled = spooled_seqs(site.spool)
        assert site.caught_up(spooled), site.procs.logs()
        archived = archived_seqs(tmp_path)
        # (a fresh worker starts at its first block: the 2 s cache held the last 20 at most)
        since = {c: {n for n in spooled[c] if n >= min(archived[c])} for c in CHANNELS}
        assert archived == since
        assert all(s == set(range(min(s), max(s) + 1)) for s in archived.values())  # no gap
        assert losses(tmp_path) == {}
        recovered = [line for line in site.procs.log_lines("serve") if "from the gateway's spool"
                     in line]  # fmt: skip
        assert recovered, "the outage was covered by the cache alone: make it longer"
        zero = dict.fromkeys(CHANNELS, 0.0)
        assert wait(lambda: missing_reported(site.api) == {"metrics": zero, "mill": zero}, 10.0)
        assert site.procs.stop("serve") == 0, site.procs.logs()
    finally:
        site.procs.stop_all()
