"""The month-end job inside the running service (``ServiceRuntime``, as ``millwatch serve``
runs it): at start it catches up on a finished month of stored data, writes the files in a
render process, and a mail server that refuses connections becomes a stored
``report_delivery`` alarm raised by the worker thread, shown by the API's board and
``/reports/status``."""

from __future__ import annotations

import time
import zoneinfo
from datetime import UTC, datetime, timedelta

from millwatch.api.local_backend import LocalBackend
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from millwatch.settings import ServiceSettings
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime
from tests.service.reports.month_store import MILLS_DIR, fill, mill

A = mill("sag-5200-lrs")


def _wait(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.1)
    return predicate()


def test_the_service_catches_up_writes_the_files_and_alarms_a_mail_it_cannot_send(tmp_path):
    then = datetime.now(UTC) - timedelta(days=40)  # in a finished month, whatever today is
    month = then.astimezone(zoneinfo.ZoneInfo(A.time_zone)).strftime("%Y-%m")
    fill(tmp_path / "mw.db", [(A, then.strftime("%Y-%m-%dT%H:%M"))])
    settings = ServiceSettings.model_validate({
        "zenoh": {"listen": [tcp_endpoint(free_loopback_port())]},
        "archive": {"directory": str(tmp_path / "archive")},
        "store": {"path": str(tmp_path / "mw.db")},
        "reports": {"directory": str(tmp_path / "reports"), "attempts": 2, "backoff_s": 0.05,
                    "jobs": 1, "mail": {"host": "127.0.0.1", "port": free_loopback_port(),
                                        "sender": "mw@plant.example", "timeout_s": 2,
                                        "recipients": ["manager@plant.example"]}},
        "mills": {"files": [str(MILLS_DIR / f"{A.id}.toml")]},
    })  # fmt: skip
    runtime = ServiceRuntime(settings, settings.load_mills(), MillJob)
    runtime.start()
    try:
        backend = LocalBackend(runtime)
        assert runtime.store is not None

        def raised():
            return [a for a in runtime.store.alarms(mill_id=A.id) if a.rule == "report_delivery"]

        assert _wait(lambda: raised(), 120.0), "no report_delivery alarm"
        (alarm,) = raised()
        assert alarm.subject == "mail" and alarm.state == "raised"
        assert month in alarm.message and "connect failed" in alarm.advice
        assert alarm.alarm_id in {r.alarm_id for r in backend.alarm_board().rows(A.id)}
        for ext in ("html", "pdf", "zip"):
            assert (tmp_path / "reports" / A.id / f"{month}.{ext}").is_file()
        (status,) = backend.reports_status()["workers"].values()
        assert [(f["mill"], f["month"], f["stage"]) for f in status["failures"]] == [
            (A.id, month, "mail")
        ]
        assert status["latest"] == {A.id: month}
    finally:
        runtime.stop()
