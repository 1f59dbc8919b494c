"""Benchmark: the cost of a block's admission with the plausibility rule (not a test).

Run::

    .venv/bin/python tests/bench/bench_admission.py [--blocks 100000] [--repeat 5]

:meth:`millwatch.worker.health.ChannelHealth.accept` of ``--blocks`` regular 100-sample blocks
one by one (the live worker's path), and
:meth:`~millwatch.worker.health.ChannelHealth.follows_on` of the same blocks as one run (the
batch lane's test); best of ``--repeat``, µs a block. What the rule costs: run the same script
on the tree before it (``git archive 50878d5 | tar -x -C /tmp/before`` and
``PYTHONPATH=/tmp/before .venv/bin/python tests/bench/bench_admission.py``).
"""

from __future__ import annotations

import argparse
import inspect
import time

import numpy as np

from millwatch.ingest.wire import Unit, decode_block, encode_block
from millwatch.worker.health import ChannelHealth

STEP_NS = 100_000_000  # 100 samples at 1 kHz
T0_NS = 1_790_000_000 * 10**9


def _best(repeat: int, run: object) -> float:
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        run()  # type: ignore[operator]
        times.append(time.perf_counter() - started)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    n = args.blocks
    blocks = [
        decode_block(encode_block(np.zeros(100, np.float32), T0_NS + s * STEP_NS, 1000.0, s,
                                  Unit.RPM))
        for s in range(n)
    ]  # fmt: skip
    recv = [T0_NS + (k + 1) * STEP_NS for k in range(n)]

    def one_by_one() -> None:
        h = ChannelHealth()
        for b, r in zip(blocks, recv, strict=True):
            h.accept(b, r)

    seq = np.arange(n, dtype=np.uint64)
    t0 = T0_NS + np.arange(n, dtype=np.int64) * STEP_NS
    recv_arr = np.array(recv, dtype=np.int64)
    takes_recv = "recv_ns" in inspect.signature(ChannelHealth.follows_on).parameters

    def as_run() -> None:
        h = ChannelHealth()
        args_ = (seq, t0, STEP_NS, recv_arr) if takes_recv else (seq, t0, STEP_NS)
        assert h.follows_on(*args_)

    print(f"accept, one by one: {_best(args.repeat, one_by_one) / n * 1e6:.2f} µs a block")
    print(f"follows_on, one run: {_best(args.repeat, as_run) / n * 1e6:.4f} µs a block")


if __name__ == "__main__":
    main()
