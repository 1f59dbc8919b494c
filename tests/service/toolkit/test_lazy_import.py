"""``import millwatch`` is light: the notebook API (pandas, the analysis) loads on first use."""

from __future__ import annotations

import subprocess
import sys

import pytest

_PROBE = """
import sys
import millwatch
before = {m.split(".")[0] for m in sys.modules}
analyze = millwatch.analyze
print(sorted(before & {"pandas", "numpy", "numba"}), "pandas" in sys.modules,
      analyze.__module__, millwatch.read_archive.__module__)
"""


def test_import_millwatch_loads_the_toolkit_only_when_asked():
    done = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                          timeout=120, check=True)  # fmt: skip
    assert done.stdout.split() == [
        "[]", "True", "millwatch.toolkit.analysis", "millwatch.toolkit.archive"]  # fmt: skip


def test_an_unknown_name_is_an_attribute_error():
    import millwatch

    with pytest.raises(AttributeError, match="no attribute 'analyse'"):
        millwatch.analyse  # noqa: B018
