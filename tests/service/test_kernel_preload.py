"""millwatch.kernel_preload: the cached kernels run without numba's compiler registries, and
count exactly as the ``rainflow`` package does (cycles bitwise, the same damage).

Each check runs in fresh processes with a numba cache of its own (``NUMBA_CACHE_DIR``): the first
process finds the cache empty and compiles (numba's ordinary path), the second preloads — and
must then never load numba's compiler registries (``numba.np.arraymath``) nor ``scipy.linalg``,
which proves every call went to the preloaded code."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
import rainflow

from millwatch import kernel_preload
from millwatch.analytics.fatigue.sn_models import build_sn_curve
from millwatch.kernel_preload import preload

#: numba's release is one the preload was checked with (else it must load nothing).
CHECKED = ".".join(numba.__version__.split(".")[:2]) in kernel_preload.CHECKED_NUMBA

#: One process: preload, then hypothesis examples through RecordCount in half mode against
#: rainflow.extract_cycles (writable and read-only blocks, as the CLI's memory-mapped file gives).
_CHECK = """
import json, sys
import numpy as np
import rainflow
from hypothesis import assume, given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from millwatch.analytics.fatigue.record_count import KERNELS, RecordCount
from millwatch.analytics.fatigue.sn_models import build_sn_curve
from millwatch.kernel_preload import preload

installed = preload(KERNELS)
curve = build_sn_curve("shigley")
# tenths of MPa: plateaus and repeated values occur, differences never underflow
values = st.integers(-4000, 4000).map(lambda v: v / 10.0)

def compare(x, cut, readonly):
    count = RecordCount(curve, scale=2.0, capacity=cut)
    got = []
    for s in range(0, len(x), cut):
        block = np.array(x[s : s + cut])
        block.setflags(write=not readonly)
        got += count.feed(block).as_tuples()
    closing, totals = count.close()
    got += closing.as_tuples()
    ref = [(float(r), float(m), c, i, j) for r, m, c, i, j in rainflow.extract_cycles(x)]
    assert got == ref
    ranges = np.array([r for r, *_ in ref]) * 2.0
    assert totals.damage == curve.damage(ranges, [c for _, _, c, _, _ in ref])

@settings(max_examples={examples}, deadline=None, database=None, derandomize=True)
@given(x=arrays(np.float64, st.integers(0, 300), elements=values),
       cut=st.integers(1, 80), readonly=st.booleans())
def check(x, cut, readonly):
    assume(len(x) != 2 and (len(x) == 0 or x.min() < x.max()))  # rainflow's degenerate cases
    compare(x, cut, readonly)

compare(np.array([0.0, 5.0, 1.0, 4.0, -2.0, 3.0]), 2, False)  # both block kinds, whatever
compare(np.array([0.0, 5.0, 1.0, 4.0, -2.0, 3.0]), 2, True)  # hypothesis draws below
check()
json.dump({{"installed": installed, "compiler": "numba.np.arraymath" in sys.modules,
           "scipy_linalg": "scipy.linalg" in sys.modules}}, sys.stdout)
"""

#: One ``millwatch rainflow`` run in-process; the modules it loaded go to stderr.
_CLI = """
import sys
from millwatch.cli.main import main
main({argv!r})
sys.stderr.write("\\n".join(sorted(sys.modules)))
"""


@pytest.fixture(scope="module")
def numba_cache(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    return {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path_factory.mktemp("numba-cache"))}


def run(
    code: str, env: dict[str, str], *, script: Path | None = None
) -> subprocess.CompletedProcess[str]:
    """``python -c code`` (or ``python script``) in a fresh process; fails with its stderr."""
    argv = [sys.executable, str(script)] if script is not None else [sys.executable, "-c", code]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-4000:]
    return done


def test_preloaded_kernels_count_exactly_without_the_compiler(numba_cache):
    first = json.loads(run(_CHECK.format(examples=20), numba_cache).stdout)
    assert first == {"installed": 0, "compiler": True, "scipy_linalg": first["scipy_linalg"]}
    second = json.loads(run(_CHECK.format(examples=150), numba_cache).stdout)
    if not CHECKED:  # exact all the same, on numba's ordinary path
        assert second == {**first, "scipy_linalg": second["scipy_linalg"]}
        return
    # feed (writable and read-only blocks), close_half, stresses, log_damage, book
    assert second["installed"] >= 6
    assert not second["compiler"] and not second["scipy_linalg"]


def test_cli_rainflow_preloads_and_matches_the_rainflow_package(numba_cache, tmp_path):
    rng = np.random.default_rng(5)
    t = np.arange(30_000) / 1000.0
    x = 50.0 * np.sin(2 * np.pi * 3.1 * t) + 70.0 + rng.normal(0, 4.0, t.shape)
    np.save(tmp_path / "s.npy", x)
    code = _CLI.format(argv=["rainflow", str(tmp_path / "s.npy"), "--kt", "2", "--json"])
    run(code, numba_cache)  # fills the cache if the other test did not
    done = run(code, numba_cache)
    loaded = set(done.stderr.split())
    assert ("numba.np.arraymath" in loaded) is not CHECKED
    summary = json.loads(done.stdout)
    ref = list(rainflow.extract_cycles(x))
    counts = np.array([c for _, _, c, _, _ in ref])
    full = int(np.count_nonzero(counts == 1.0))
    assert (summary["full_cycles"], summary["half_cycles"]) == (full, len(ref) - full)
    curve = build_sn_curve("shigley")
    assert summary["damage"] == curve.damage(np.array([r for r, *_ in ref]) * 2.0, counts)


def test_a_numba_release_not_checked_is_left_alone(monkeypatch, caplog):
    from millwatch.analytics.fatigue.record_count import KERNELS

    caplog.set_level("DEBUG", logger="millwatch.kernel_preload")
    monkeypatch.setattr(kernel_preload, "CHECKED_NUMBA", frozenset({"0.0"}))
    assert kernel_preload.preload(KERNELS) == 0
    assert "is not one preloading was checked with" in caplog.text


def test_what_is_not_a_cached_kernel_is_skipped(caplog):
    caplog.set_level("DEBUG", logger="millwatch.kernel_preload")
    assert preload([len, object()]) == 0
    assert "not preloaded" in caplog.text


def test_a_kernel_with_no_cache_is_left_to_numba(tmp_path: Path):
    script = tmp_path / "plus_one.py"
    script.write_text(
        "from numba import njit\n"
        "from millwatch.kernel_preload import preload\n"
        "@njit(cache=True)\n"
        "def plus_one(a):\n"
        "    return a + 1\n"
        "assert preload([plus_one]) == 0 and plus_one(1) == 2\n"  # compiled and cached now
        "assert preload([plus_one]) == 0  # already installed: nothing to load\n"
    )
    run("", {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}, script=script)
