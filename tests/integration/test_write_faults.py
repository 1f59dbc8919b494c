"""Faults heal and lose nothing (issue 26, deliverable 2), end to end on 127.0.0.1 with real
processes: a gateway with a spool (``millwatch simulate --publish --spool``) and ``millwatch
serve`` whose archive and store lie on a small tmpfs of their own — the plant's ``var`` disk.

The disk fills up just before the mill's start (the filler file takes every free byte: the
kernel's own ``ENOSPC``, for the archive's writes and SQLite's alike) and is freed 8 s later (32 s
of the scene at 4×), while the scene goes on. Checked, each property reported on its own:

* every block the gateway published is archived, once (the ones the worker's memory could not
  keep — ``[archive] max_unwritten_mb`` is small here — fetched again from the spool);
* the stored results (damage, samples, the start and every analysis event) equal ``millwatch
  analyze`` of the clean scene; no block counted missing;
* ``/ready`` is 503 with ``archive`` and ``store`` false while the disk is full, and 200 again
  by itself (no restart) within seconds of the space returning; the write-failure metrics count;
* the service logs one line when each episode starts and one when it ends — no tracebacks.

Mounting a tmpfs needs root (or ``CAP_SYS_ADMIN``): without it the test is skipped, saying so;
the same faults at the file layer are ``tests/service/worker/test_write_faults.py``.
"""

from __future__ import annotations

import errno
import pprint
import subprocess
import threading
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.wire import WireError, decode_block
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from millwatch.worker.runtime import ARCHIVE_PREFIX
from tests.integration.live import (
    BLOCKS_PER_CHANNEL,
    DURATION_S,
    MILL_FILE,
    SCENE_ARGS,
    Api,
    Processes,
    differences,
    offline_results,
    port_open,
    stored_results,
    wait,
    write_settings,
)

pytestmark = pytest.mark.slow

CONFIG = load_mill_config(MILL_FILE)
CHANNELS = sorted(CONFIG.channels)
SPEED = 4.0
#: From ``serve`` answering to the scene's first sample: the gateway starts meanwhile (a Python
#: start took up to 12 s on a busy 2-core machine; a late gateway skips the blocks due before).
LEAD_S = 14.0
#: The disk is full from this scene time to that one (s): the start (5-21 s) falls within.
FULL_FROM_S, FULL_UNTIL_S = 3.0, 35.0
#: ``/ready`` may take this long to follow the disk (s): a failed write is tried again every
#: second, and ``/ready`` reads a status refreshed every 0.5 s.
READY_FOLLOWS_S = 3.0
#: Lines ``serve`` may log besides two per episode and one per channel for the spool's re-fetch
#: (its banner; room for a few start-up warnings): the run logged 9 lines in all.
BASELINE_LOG_LINES = 10


class SmallDisk:
    """A tmpfs mounted at ``path`` (skips the test when that is not permitted); :meth:`fill`
    takes every free byte with a filler file, :meth:`free` deletes it."""

    def __init__(self, path: Path, size: str) -> None:
        path.mkdir()
        run = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                             capture_output=True, text=True, check=False)  # fmt: skip
        if run.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs for a full disk: {run.stderr.strip()}")
        self.path = path
        self.filler = path / "filler"

    def fill(self) -> None:
        with open(self.filler, "wb", buffering=0) as f:
            for size in (2**20, 2**12, 1):  # bounded: a 32 MiB disk takes ≤ 32 + 256 + 4096
                block = bytes(size)
                for _ in range(2**16):
                    try:
                        f.write(block)
                    except OSError as exc:
                        assert exc.errno == errno.ENOSPC, exc
                        break

    def free(self) -> None:
        self.filler.unlink()

    def unmount(self) -> None:
        subprocess.run(["umount", "-l", str(self.path)], check=False, capture_output=True)


class ReadyLog:
    """``GET /ready`` four times a second in a thread: (monotonic s, status, checks)."""

    def __init__(self, api: Api) -> None:
        self.api = api
        self.samples: list[tuple[float, int | None, dict[str, Any]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        for _ in range(2400):  # ≤ 10 min
            if self._stop.is_set():
                return
            r = self.api.get("/ready")
            checks = r.json().get("checks", {}) if r is not None else {}
            self.samples.append((time.monotonic(), None if r is None else r.status_code, checks))
            time.sleep(0.25)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)

    def between(self, a: float, b: float) -> list[tuple[int | None, dict[str, Any]]]:
        return [(code, checks) for t, code, checks in self.samples if a <= t < b]


def archived(directory: Path) -> dict[str, list[int]]:
    """Sequence numbers in the archive per channel, in archive order."""
    seqs: dict[str, list[int]] = defaultdict(list)
    for b in ArchiveReader(directory, ARCHIVE_PREFIX).blocks():
        try:
            seqs[b.key.rsplit("/", 1)[1]].append(decode_block(b.payload).seq)
        except WireError:
            continue
    return dict(seqs)


def _ready_faults(ready: ReadyLog, full: float, freed: float, end: float) -> dict[str, Any]:
    """What ``/ready`` said wrong: archive or store false before the fill, not 503 (archive and
    store false) while the disk was full, not 200 once the space returned (until the gateway
    ended its scene: then zenoh has no peer)."""
    broken: dict[str, Any] = {}
    before = ready.between(0.0, full)
    if not before or any(not (c.get("archive") and c.get("store")) for _, c in before):
        broken["before"] = before[-4:]
    during = ready.between(full + READY_FOLLOWS_S, freed)
    if not during or any(code != 503 or c.get("archive") or c.get("store") for code, c in during):
        broken["during"] = during[:4]
    after = ready.between(freed + READY_FOLLOWS_S, end)
    if not after or any(code != 200 for code, _ in after):
        broken["after"] = [s for s in after if s[0] != 200][:4] or "no sample"
    return broken


def test_a_full_disk_under_archive_and_store_loses_nothing(tmp_path, clean):
    disk = SmallDisk(tmp_path / "disk", "32m")
    procs = Processes(tmp_path)
    port, api_port = free_loopback_port(), free_loopback_port()
    settings = write_settings(
        disk.path, api_port=api_port, connect=(tcp_endpoint(port),), gateway_wait_s=120.0
    )  # (subscribes once the gateway is up)
    text = settings.read_text(encoding="utf-8")  # memory for ~250 blocks: most are re-fetched
    settings.write_text(text.replace("[archive]\n", "[archive]\nmax_unwritten_mb = 0.1\n"))
    api = Api(api_port)
    broken: dict[str, Any] = {}
    ready: ReadyLog | None = None
    try:
        procs.start("serve", "serve", "--config", str(settings))
        assert wait(lambda: api.up() or procs.procs["serve"].poll() is not None, 60.0)
        assert api.up(), procs.logs()
        ready = ReadyLog(api)
        anchor_ns = (time.time_ns() // 10**9 + round(LEAD_S)) * 10**9
        anchor = time.monotonic() + (anchor_ns - time.time_ns()) / 1e9
        procs.start("gateway", "simulate", *SCENE_ARGS, "--publish", "--speed", f"{SPEED:g}",
                    "--listen", tcp_endpoint(port), "--anchor-ns", str(anchor_ns),
                    "--spool", str(tmp_path / "spool"))  # fmt: skip
        assert wait(lambda: port_open(port) or procs.procs["gateway"].poll() is not None, 30.0)
        full = anchor + FULL_FROM_S / SPEED
        assert time.monotonic() < full, f"the gateway took too long to start: {procs.logs()}"
        time.sleep(full - time.monotonic())
        disk.fill()
        time.sleep(max(0.0, anchor + FULL_UNTIL_S / SPEED - time.monotonic()))
        failures = api.metrics()
        disk.free()
        freed = time.monotonic()
        end = anchor + DURATION_S / SPEED - 1.0  # (the gateway's scene ends: zenoh has no peer)
        rc = procs.procs["gateway"].wait(timeout=DURATION_S / SPEED + 30.0)
        assert rc == 0, procs.logs()

        def all_archived() -> bool:
            seqs = archived(disk.path / "archive")
            return all(len(seqs.get(c, ())) >= BLOCKS_PER_CHANNEL for c in CHANNELS)

        wait(all_archived, 30.0, every_s=0.5)
        wait(lambda: sum("writable again" in x for x in procs.log_lines("serve")) == 2, 15.0)
        ready.stop()
        broken |= _ready_faults(ready, full, freed, end)
        for target in ("archive", "store"):
            name = f'millwatch_write_failures_total{{target="{target}"}}'
            if not failures.get(name):
                broken[f"metric {target}"] = {k: v for k, v in failures.items() if "write" in k}
        missing = api.missing_per_channel()
        if any(missing.values()):
            broken["missing_blocks_total"] = missing
        assert procs.stop("serve") == 0, procs.logs()
        seqs = archived(disk.path / "archive")
        if seqs != {c: list(range(BLOCKS_PER_CHANNEL)) for c in CHANNELS}:
            broken["archive"] = {c: (len(s), len(set(s)), s == sorted(s)) for c, s in seqs.items()}
        stored = stored_results(disk.path, CONFIG)
        if stored != offline_results(clean):
            broken["results"] = differences(stored, offline_results(clean))
    finally:
        if ready is not None:
            ready.stop()
        procs.stop_all()
        disk.unmount()
    lines = procs.log_lines("serve")
    episodes = [line for line in lines if "writable" in line]
    opened = sum("not writable" in line for line in episodes)
    if (opened, len(episodes)) != (2, 4) or any("Traceback" in line for line in lines):
        broken["episode lines"] = episodes
    if len(lines) > BASELINE_LOG_LINES + 4 + len(CHANNELS):
        broken["log lines"] = len(lines)
    assert broken == {}, pprint.pformat(broken, width=100) + "\n" + "\n".join(lines[-60:])
