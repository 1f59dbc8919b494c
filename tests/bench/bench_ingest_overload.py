"""Benchmark: ``replay --max`` into ``serve`` — what is archived, analysed, lost, and how fast
the analysis catches up (not a test; issue 25).

    .venv/bin/python tests/bench/bench_ingest_overload.py --mill ball-dual-lrs --hours 3

1. The archive-first ingest alone, in this process: the archiving thread's work for each block
   (:meth:`millwatch.worker.archive_first.ArchiveFirst.take`: MCAP write, feed or fall behind) on
   real 100-sample float32 blocks with no analysis taking any; CPU time of the thread, so
   blocks/s per core.
2. End to end, real processes on 127.0.0.1: ``millwatch simulate --out`` of the scene, then one
   ``millwatch serve`` (``[worker] queue_blocks`` as given) fed by ``millwatch replay --max``:
   blocks sent (messages in the recording), archived (messages in serve's archive after a clean
   stop), handled (``millwatch_blocks_handled_total``: analysed, or dropped by the admission as
   a repeat — the gateway cache's answer to the recovering subscriber brings a few again:
   ``millwatch_repeated_blocks_total``), the replay's wall time, and the catch-up
   time from the replay's end until ``millwatch_queue_depth_blocks`` is 0 and every mill's
   ``status.samples`` stopped moving (bounded by ``--catch-up-s``).

``--root DIR`` runs step 2 with another checkout's ``millwatch`` (its own ``.venv``), e.g. the
code before the archive-first ingest, for the before/after table in the README.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.store import payload_seq
from millwatch.ingest.wire import DType
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from millwatch.worker.archive_first import ArchivedSeqs, ArchiveFirst, SharedArchive
from millwatch.worker.block_queue import BlockQueue, QueuedBlock
from millwatch.worker.health import MillHealth

ROOT = Path(__file__).resolve().parents[2]


def archive_rate(mill: str, seconds: float, feed: int) -> tuple[int, float]:
    """(blocks, blocks per CPU second of the archiving thread) with no analysis."""
    config = load_mill_config(ROOT / "deploy" / "mills" / f"{mill}.toml")
    scene = get_scene("steady", config, seed=1, duration_s=seconds)
    blocks = [QueuedBlock(b.key, b.payload, b.t_end_ns)
              for b in scene_blocks(scene, dtype=DType.FLOAT32)]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        shared = SharedArchive(ArchiveWriter(tmp, "millwatch"))
        seqs = ArchivedSeqs.of({config.id: MillHealth.for_channels(list(config.channels))})
        names = {k: k.rsplit("/", 1)[-1] for k in {b.key for b in blocks}}
        ingest = ArchiveFirst(shared, BlockQueue(10), feed, lambda k: (config.id, names[k]), seqs)
        started = time.thread_time()
        for item in blocks:
            ingest.take(item)
        shared.close()
        cpu = time.thread_time() - started
    return len(blocks), len(blocks) / cpu


def metric(url: str, family: str) -> float | None:
    try:
        text = httpx.get(url + "/metrics", timeout=5.0).text
    except httpx.HTTPError:
        return None
    return sum(float(line.rpartition(" ")[2]) for line in text.splitlines()
               if line.startswith(family) and line[len(family)] in " {")  # fmt: skip


def samples(url: str, mills: list[str]) -> list[int]:
    out = []
    for m in mills:
        try:
            body = httpx.get(f"{url}/mills/{m}", timeout=5.0).json()
        except (httpx.HTTPError, ValueError):
            return []
        out.append(int((body.get("status") or {}).get("samples") or 0))
    return out


def end_to_end(args: argparse.Namespace, d: Path) -> dict[str, float | int]:
    root = Path(args.root).resolve()
    python = str(root / ".venv" / "bin" / "python") if args.root else sys.executable
    mill_file = ROOT / "deploy" / "mills" / f"{args.mill}.toml"
    config = load_mill_config(mill_file)
    lab = d / "lab.toml"
    lab.write_text(mill_file.read_text().replace(f'site = "{config.site}"', 'site = "lab"', 1))
    recording = d / "rec.mcap"
    run = [python, "-m", "millwatch.cli.main"]
    subprocess.run([*run, "simulate", "--scene", "steady", "--mill", str(lab), "--duration",
                    f"{args.hours * 3600:g}s", "--out", str(recording), "--dtype", "float32",
                    "--no-progress"], cwd=root, check=True)  # fmt: skip
    sent = sum(1 for _ in TailTolerantReader(recording).messages())
    zport, aport = free_loopback_port(), free_loopback_port()
    (d / "plant.toml").write_text(
        f'[zenoh]\nlisten = ["{tcp_endpoint(zport)}"]\n[archive]\ndirectory = "archive"\n'
        f'[store]\npath = "mw.db"\n[worker]\nstale_after_s = 600\ngateway_wait_s = 0\n'
        f"queue_blocks = {args.queue_blocks}\n[api]\nport = {aport}\n"
        f"[mills]\nfiles = {json.dumps([str(mill_file)])}\n"
    )
    url = f"http://127.0.0.1:{aport}"
    with (d / "serve.log").open("wb") as log:
        serve = subprocess.Popen([*run, "serve", "--config", str(d / "plant.toml")], cwd=d,
                                 stdout=log, stderr=subprocess.STDOUT)  # fmt: skip
    try:
        for _ in range(600):
            if metric(url, "millwatch_blocks_handled_total") is not None:
                break
            time.sleep(0.1)
        started = time.monotonic()
        subprocess.run([*run, "replay", str(recording), "--max", "--remap",
                        f"millwatch/v1/{config.site}", "--connect", tcp_endpoint(zport),
                        "--wait-subscribers", "30", "--no-progress"], cwd=root, check=True,
                       stdout=subprocess.DEVNULL)  # fmt: skip
        replay_s = time.monotonic() - started
        done = caught = time.monotonic()
        last: list[int] = []
        still = 0  # polls in a row with nothing waiting and the samples not moving
        for _ in range(int(args.catch_up_s / 0.5)):
            now = samples(url, [config.id])
            depth = metric(url, "millwatch_queue_depth_blocks")
            still = still + 1 if depth == 0 and now and now == last else 0
            if still == 4:  # (the status is refreshed every 0.5 s)
                break
            if still == 0:
                caught = time.monotonic()
            last = now
            time.sleep(0.5)
        catch_up_s = caught - done
        analysed = int(metric(url, "millwatch_blocks_handled_total") or 0)
        dropped = int(metric(url, "millwatch_queue_dropped_blocks_total") or 0)
        repeats = int(metric(url, "millwatch_repeated_blocks_total") or 0)
        missing = int(metric(url, "millwatch_missing_blocks_total") or 0)
    finally:
        serve.terminate()
        serve.wait(timeout=120)
    messages = [(m.key, payload_seq(m.payload)) for p in sorted((d / "archive").glob("*.mcap"))
                for m in TailTolerantReader(p).messages()]  # fmt: skip
    archived, distinct = len(messages), len(set(messages))
    return {"sent": sent, "archived": archived, "analysed": analysed, "dropped": dropped,
            "repeats": repeats, "missing": missing, "distinct": distinct,
            "replay_s": replay_s, "catch_up_s": catch_up_s}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mill", default="ball-dual-lrs")
    p.add_argument("--hours", type=float, default=3.0)
    p.add_argument("--queue-blocks", type=int, default=200_000)
    p.add_argument("--catch-up-s", type=float, default=900.0)
    p.add_argument("--root", default="", help="another checkout's millwatch for step 2")
    p.add_argument("--skip-archive", action="store_true", help="step 2 only")
    p.add_argument("--keep", action="store_true", help="keep the run's directory")
    args = p.parse_args()
    if not args.skip_archive:
        n, rate = archive_rate(args.mill, 600.0, feed=1000)
        print(
            f"archive-first ingest alone ({args.mill}, {n} blocks): {rate:,.0f} blocks/s per core"
        )
    d = Path(tempfile.mkdtemp(prefix="mw-overload-"))
    try:
        r = end_to_end(args, d)
    finally:
        if not args.keep:
            shutil.rmtree(d, ignore_errors=True)
    where = f", {args.root}" if args.root else ""
    print(f"replay --max of {args.hours:g} h of {args.mill} into serve "
          f"(queue_blocks {args.queue_blocks}{where}):")  # fmt: skip
    print(
        f"  sent {r['sent']}  archived {r['archived']}  handled {r['analysed']}  "
        f"(distinct {r['distinct']})  dropped {r['dropped']}  missing {r['missing']}  "
        f"repeats {r['repeats']}  replay {r['replay_s']:.1f} s "
        f"({r['sent'] / r['replay_s']:,.0f} blocks/s)  catch-up after it {r['catch_up_s']:.1f} s"
    )


if __name__ == "__main__":
    main()
