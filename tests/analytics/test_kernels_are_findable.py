"""Compiled code is findable: numba lives only in analytics modules named ``*_kernels.py``,
beside the plain-Python API that uses them (README "Shape of the analytics code")."""

from __future__ import annotations

import re
from pathlib import Path

import millwatch.analytics

ROOT = Path(millwatch.analytics.__file__).resolve().parent
NUMBA = re.compile(r"\b(numba|njit)\b")


def test_numba_only_in_kernel_modules() -> None:
    offenders = [
        str(path.relative_to(ROOT.parent))
        for path in sorted(ROOT.rglob("*.py"))
        if not path.name.endswith("_kernels.py") and NUMBA.search(path.read_text("utf-8"))
    ]
    assert offenders == [], f"numba/njit outside a *_kernels.py module: {offenders}"


def test_every_kernel_module_is_compiled_code() -> None:
    kernels = sorted(ROOT.rglob("*_kernels.py"))
    assert kernels, "no kernel modules found"
    for path in kernels:
        assert "@njit" in path.read_text("utf-8"), f"{path.name} holds no compiled kernel"
