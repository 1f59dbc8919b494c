"""Crash recovery: SIGKILL the worker process at random moments, restart it, and its results
still equal the offline analysis of the archive — nothing counted twice, nothing skipped — with
the archive losing at most what was in flight at the kill."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.cli.analyze import analyze_recording, recording_files
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.keys import channel_key
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.publisher import starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import DType
from millwatch.ingest.zenoh_session import (
    build_config,
    declare_block_publisher,
    free_loopback_port,
    open_session,
    tcp_endpoint,
    wait_for_subscribers,
)
from millwatch.settings import load_service_settings
from millwatch.store.database import Store
from millwatch.worker.runtime import ARCHIVE_PREFIX

ROOT = Path(__file__).resolve().parents[3]
MILL = ROOT / "deploy" / "mills" / "sag-5200-lrs.toml"
PACE_S = 0.0005  # between blocks: 2000 blocks/s, 500 per channel, about 50x real time


def write_settings(tmp_path: Path, port: int) -> Path:
    path = tmp_path / "plant.toml"
    path.write_text(
        f'[zenoh]\nlisten = ["{tcp_endpoint(port)}"]\n'
        '[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        "[worker]\ncheckpoint_seconds = 0.5\ngateway_wait_s = 0\n"  # plain publisher
        f'[mills]\nfiles = ["{MILL}"]\n'
    )
    return path


def start_worker(settings: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "millwatch.cli.main", "serve", "--config", str(settings),
         "--no-api"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )  # fmt: skip


def publish(session, blocks, publishers, pace_s: float) -> None:
    for block in blocks:
        pub = publishers.get(block.key)
        if pub is None:
            pub = publishers[block.key] = declare_block_publisher(session, block.key)
            assert wait_for_subscribers(pub, 20.0), "the worker never subscribed"
        pub.put(block.payload)
        time.sleep(pace_s)


@pytest.mark.slow
def test_sigkill_at_random_moments_then_restart_equals_offline_analysis(tmp_path):
    rng = random.Random(20261121)
    port = free_loopback_port()
    settings_path = write_settings(tmp_path, port)
    settings = load_service_settings(settings_path)
    config = settings.load_mills()["sag-5200-lrs"]
    scene = starting_now(get_scene("start-lrs", config, seed=11, duration_s=60.0))
    blocks = list(scene_blocks(scene, block_samples=100, dtype=DType.FLOAT32))
    cuts = sorted(rng.sample(range(200, len(blocks) - 200), 3))
    worker = start_worker(settings_path)
    try:
        with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
            start = 0
            for cut in [*cuts, len(blocks)]:
                publishers: dict = {}
                publish(session, blocks[start:cut], publishers, pace_s=PACE_S)
                for p in publishers.values():
                    p.undeclare()
                start = cut
                if cut == len(blocks):
                    break
                time.sleep(rng.uniform(0.0, 0.3))  # the worker is mid-batch or idle
                worker.send_signal(signal.SIGKILL)
                worker.wait(timeout=30)
                worker = start_worker(settings_path)
            time.sleep(1.5)  # let the last blocks reach the archive and the worker
        worker.send_signal(signal.SIGTERM)
        assert worker.wait(timeout=60) == 0, worker.stderr.read().decode()
    finally:
        if worker.poll() is None:
            os.kill(worker.pid, signal.SIGKILL)
            worker.wait(timeout=30)

    archived = Counter(b.key for b in ArchiveReader(settings.archive.directory, ARCHIVE_PREFIX)
                       .blocks())  # fmt: skip
    published = Counter(b.key for b in blocks)
    lost = {k: published[k] - archived[k] for k in published}
    # Each kill loses at most what reached the worker in the last ~0.1 s of *wall* time (the
    # archive's max latency) plus scheduling slack: 0.25 s at this publish rate, per channel.
    per_channel_rate = 1.0 / (PACE_S * len(published))
    assert all(0 <= n <= len(cuts) * 0.25 * per_channel_rate for n in lost.values()), lost
    assert set(archived) == {
        channel_key(config.site, config.id, c.key) for c in config.channels.values()
    }

    with Store(settings.store.path) as store:
        _, state = store.latest_checkpoints()[config.id]
        starts = store.events(config.id, "start")
    live = MillAnalyzer.restore(config, state["pipelines"][config.id]["monitor"])
    live.flush()
    offline, _ = analyze_recording(recording_files(settings.archive.directory), config)
    live_report, offline_report = live.report(), offline.report()
    assert json.dumps(live_report["damage"], sort_keys=True) == json.dumps(
        offline_report["damage"], sort_keys=True
    )
    assert live_report["samples"] == offline_report["samples"]
    assert [s.t_ns for s in starts] == [s["t_ns"] for s in offline_report["starts"]]
