"""Fixtures of the report tests: the store of :mod:`tests.service.reports.month_scene`, filled
once per session, and its January report."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from millwatch.reports.monthly import MonthlyReport, build_monthly_report
from millwatch.store.database import Store
from tests.service.reports.month_scene import CONFIG, MONTH, fill_store


@pytest.fixture(scope="session")
def store(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Store]:
    path = tmp_path_factory.mktemp("report") / "mw.db"
    fill_store(path)
    s = Store(path)
    yield s
    s.close()


@pytest.fixture(scope="session")
def report(store: Store) -> MonthlyReport:
    return build_monthly_report(store, CONFIG, MONTH)
