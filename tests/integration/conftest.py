"""The clean run every integration test compares with: ``millwatch simulate --out`` of the
scene, then ``millwatch analyze --json`` (once per session)."""

from __future__ import annotations

from typing import Any

import pytest

from tests.integration.live import clean_report


@pytest.fixture(scope="session")
def clean(tmp_path_factory) -> dict[str, Any]:
    return clean_report(tmp_path_factory.mktemp("clean"))
