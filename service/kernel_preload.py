"""Load the cached machine code of compiled kernels without starting numba's compiler.

Why (measured, ``millwatch rainflow`` on 12 M samples; README "Command line"): the first call of
a cached ``@njit(cache=True)`` kernel in a process makes numba's dispatcher initialise its whole
compiler — every typing and lowering registry of numpy implementations, and with them an import
of ``scipy.linalg`` to check for BLAS — *before* it looks in the cache: ~0.3 s of CPU without
scipy installed, ~0.5 s with it, while loading the machine code itself takes a few milliseconds.
Only compiling needs the registries; running cached code needs numba's runtime (NRT) and the
code.

:func:`preload` does what numba's cache does on a first call minus the registries: start the
runtime, read each kernel's cache index, load every signature cached for this machine (numba's
own checks: source file stamp, bytecode hash, CPU and numba version) and install it in the
dispatcher as an overload. A later call with one of those signatures dispatches straight to it.

Exactness: the code run is the very machine code numba itself would load from the same cache
file, so results are bitwise what they are without the preload. Anything the preload does not
cover (no cache yet — the first run after installing —, an edited kernel, another CPU, a
signature not cached) takes numba's ordinary path, which initialises the compiler and compiles
or loads as always.

Numba internals used: the dispatcher's cache object, ``add_overload`` and ``rtsys.initialize``.
Their misuse would not always raise (running cached code before the runtime is started crashes
the process), so the preload runs only on the numba releases it was checked with
(:data:`CHECKED_NUMBA`; ``tests/service/test_kernel_preload.py``); on any other it loads nothing
and the command is only slower (``bench_cli_rainflow.py --stages`` shows by how much), never
different. A failure on a checked release is logged at DEBUG and leaves that kernel to numba.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

__all__ = ["CHECKED_NUMBA", "preload"]

log = logging.getLogger(__name__)

#: numba releases (major.minor) whose internals the preload was checked against.
CHECKED_NUMBA = frozenset({"0.68"})


def preload(kernels: Iterable[Any]) -> int:
    """Install every cached signature of each numba dispatcher in ``kernels`` that is valid on
    this machine; returns how many were installed (a kernel numba's internals did not allow
    adds 0, and the reason is logged at DEBUG)."""
    try:
        import numba
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.runtime import rtsys
    except ImportError as exc:
        log.debug("compiled kernels not preloaded: %r", exc)
        return 0
    release = ".".join(numba.__version__.split(".")[:2])
    if release not in CHECKED_NUMBA:
        log.debug("numba %s is not one preloading was checked with: ordinary path", release)
        return 0
    loaded = 0
    with global_compiler_lock:
        for kernel in kernels:
            try:
                rtsys.initialize(kernel.targetctx)  # numba's runtime, as a first call starts it
                loaded += _install_cached(kernel)
            except Exception as exc:  # any failure here means "numba's ordinary path"
                log.debug("%r not preloaded (numba's ordinary path is used): %r", kernel, exc)
    return loaded


def _install_cached(kernel: Any) -> int:
    """Load and install the cached signatures of one dispatcher; returns how many."""
    cache = kernel._cache
    index = cache._cache_file._load_index()  # {(signature, machine, bytecode hashes): file}
    installed = 0
    for key in index:
        signature = key[0]
        if tuple(signature) in kernel.overloads:
            continue
        compiled = cache._load_overload(signature, kernel.targetctx)  # None: not for here/now
        if compiled is not None:
            kernel.add_overload(compiled)
            installed += 1
    log.debug("%s: %d cached signatures preloaded", kernel.py_func.__qualname__, installed)
    return installed
