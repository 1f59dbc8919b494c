"""Memory of the gateway cache per channel-minute (issue 16 target: <= 1 MB).

Each configuration runs in a fresh process: a zenoh peer session (listening nowhere, no
subscriber) declares one gateway publisher per channel with a cache of N minutes and fills it
with 100-sample float32 blocks at 1 kHz (10 blocks/s, the default wire format); the process's
RSS is read before and after. Run::

    .venv/bin/python -m tests.bench.bench_gateway_cache
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from millwatch.ingest import keys, wire
from millwatch.ingest.gateway import declare_gateway_publisher
from millwatch.ingest.zenoh_session import build_config, open_session

RATE = 10.0  # blocks/s
CONFIGS = [(1, 4), (5, 4), (10, 4), (10, 16)]  # (minutes, channels)


def _rss_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def measure(minutes: int, channels: int) -> dict[str, float]:
    """RSS growth of filling ``channels`` caches of ``minutes`` each (one process, call once)."""
    n = int(minutes * 60 * RATE)
    samples = np.linspace(-1, 1, 100, dtype=np.float32)
    unit = wire.Unit.KILONEWTON_METRE
    with open_session(build_config()) as session:
        pubs = [
            declare_gateway_publisher(
                session,
                keys.build_key("bench", f"m{c}", "pinion_torque"),
                blocks_per_s=RATE,
                retention_s=minutes * 60.0,
            )
            for c in range(channels)
        ]
        payloads = [wire.encode_block(samples, i * 100_000_000, 1e3, i, unit) for i in range(n)]
        before = _rss_mb()
        for i in range(n):
            for pub in pubs:
                pub.put(payloads[i])
        after = _rss_mb()
        for pub in pubs:
            pub.undeclare()
    block_bytes = len(payloads[0])
    growth = after - before
    return {
        "minutes": minutes, "channels": channels, "blocks": n * channels,
        "block_bytes": block_bytes, "payload_mb_per_ch_min": block_bytes * 60 * RATE / 2**20,
        "rss_growth_mb": growth, "mb_per_ch_min": growth / (minutes * channels),
    }  # fmt: skip


def main() -> None:
    if len(sys.argv) == 3:
        print(json.dumps(measure(int(sys.argv[1]), int(sys.argv[2]))))
        return
    print("| cache | channels | blocks cached | block bytes | payload MB/ch·min "
          "| RSS growth MB | **MB per channel-minute** |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for minutes, channels in CONFIGS:
        out = subprocess.run(
            [sys.executable, "-m", "tests.bench.bench_gateway_cache", str(minutes), str(channels)],
            capture_output=True, text=True, check=True, timeout=600,
        )  # fmt: skip
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"| {minutes} min | {channels} | {r['blocks']} | {r['block_bytes']} "
              f"| {r['payload_mb_per_ch_min']:.3f} | {r['rss_growth_mb']:.1f} "
              f"| **{r['mb_per_ch_min']:.3f}** |")  # fmt: skip


if __name__ == "__main__":
    main()
