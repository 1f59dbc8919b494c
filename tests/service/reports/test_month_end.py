"""The month-end job (issue 17 deliverable 4): every mill's finished local month written as
files, mailed over SMTP with STARTTLS and a login to a real server on 127.0.0.1 (aiosmtpd), failures
retried then alarmed, catch-up after downtime, idempotent across restarts.

The store is filled through the real pipeline (:mod:`tests.service.reports.month_store`): mill
``sag-5200-lrs`` (Johannesburg, UTC+2) in January and February 2024, and ``rod-1100-grid`` moved
to Lima (UTC−5) in January, so the two mills' Januaries end five hours apart."""

from __future__ import annotations

import email
import email.policy
import logging
import ssl
import zipfile
from pathlib import Path

import pytest
import trustme
from aiosmtpd.controller import Controller
from aiosmtpd.smtp import AuthResult, LoginPassword

from millwatch.alarms.observations import Observation
from millwatch.ingest.zenoh_session import free_loopback_port
from millwatch.reports.month_end import MonthEndJob, due_months
from millwatch.settings import ReportSettings
from millwatch.store.database import Store
from millwatch.worker.block_queue import BlockQueue
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker
from tests.service.reports.month_store import fill, mill, utc_ns

A = mill("sag-5200-lrs")
B = mill("rod-1100-grid", time_zone="America/Lima")
MILLS = {A.id: A, B.id: B}
USER, PASSWORD = "millwatch", "s3cret-smtp-pw"


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory):
    path = tmp_path_factory.mktemp("month-end") / "mw.db"
    fill(path, [(A, "2024-01-15T10:00"), (A, "2024-02-10T10:00"), (B, "2024-01-20T15:00")])
    s = Store(path)
    yield s
    s.close()


def job(
    store: Store, directory: Path, now: str, *, sink=None, in_process: bool = True, **settings
) -> MonthEndJob:
    opts = {"directory": directory, "delay_s": 900.0, "backoff_s": 0.01, **settings}
    return MonthEndJob(
        ReportSettings.model_validate(opts),
        MILLS,
        store,
        alarm=sink,
        clock=lambda: utc_ns(now),
        in_process=in_process,
    )


def files(directory: Path) -> dict[str, float]:
    return {
        str(p.relative_to(directory)): p.stat().st_mtime_ns
        for p in sorted(directory.rglob("*"))
        if p.is_file()
    }


def test_due_months_follow_each_mills_local_month_end_and_the_delay():
    # Johannesburg's January ends 2024-01-31T22:00Z, Lima's 2024-02-01T05:00Z; 15 min delay.
    assert due_months(A, utc_ns("2024-01-31T22:14"), 900, 3) == ["2023-11", "2023-12"]
    assert due_months(A, utc_ns("2024-01-31T22:15"), 900, 3)[-1] == "2024-01"
    assert due_months(B, utc_ns("2024-02-01T05:14"), 900, 3)[-1] == "2023-12"
    assert due_months(B, utc_ns("2024-02-01T05:15"), 900, 1) == ["2024-01"]


def test_the_job_writes_every_mills_finished_month_in_render_processes(store, tmp_path):
    early = job(store, tmp_path, "2024-02-01T03:00", in_process=False, jobs=2)
    summary = early.run_once()  # Johannesburg's January is over, Lima's is not yet
    assert (summary.due, summary.written, summary.failed) == (1, 1, 0)
    assert set(files(tmp_path)) == {f"{A.id}/2024-01.{e}" for e in ("html", "pdf", "zip")}
    later = job(store, tmp_path, "2024-02-01T06:00", in_process=False, jobs=2)
    assert later.run_once().written == 1  # now Lima's too; A's January is not made again
    written = files(tmp_path)
    assert set(written) == {f"{m}/2024-01.{e}" for m in MILLS for e in ("html", "pdf", "zip")}
    for m in MILLS:
        assert (tmp_path / m / "2024-01.pdf").read_bytes().startswith(b"%PDF")
        html = (tmp_path / m / "2024-01.html").read_text(encoding="utf-8")
        assert m in html and "2024-01" in html
        assert zipfile.ZipFile(tmp_path / m / "2024-01.zip").namelist()  # the CSV tables
    assert not list(tmp_path.rglob("*.tmp"))  # atomic writes leave no temporary file
    # a restart: a new job over the same directory finds nothing to do and rewrites nothing
    again = job(store, tmp_path, "2024-02-01T06:05", in_process=False)
    assert again.run_once().due == 0
    assert files(tmp_path) == written
    status = again.status()
    assert status["latest"] == {A.id: "2024-01", B.id: "2024-01"}
    assert status["failures"] == [] and status["last_run"]["due"] == 0


def test_a_service_down_at_month_end_catches_up_bounded(store, tmp_path):
    # Down from late January to 5 March: January and February are made at start, for the
    # months that have data (B has nothing in February, no mill in December).
    summary = job(store, tmp_path / "all", "2024-03-05T08:00").run_once()
    assert summary.written == 3
    assert {p.rsplit(".", 1)[0] for p in files(tmp_path / "all")} == {
        f"{A.id}/2024-01",
        f"{A.id}/2024-02",
        f"{B.id}/2024-01",
    }
    bounded = job(store, tmp_path / "one", "2024-03-05T08:00", catch_up_months=1)
    assert bounded.run_once().written == 1
    assert {p.rsplit(".", 1)[0] for p in files(tmp_path / "one")} == {f"{A.id}/2024-02"}


def test_a_month_missing_one_format_gets_only_that_file(store, tmp_path):
    job(store, tmp_path, "2024-02-01T06:00", formats=["html"]).run_once()
    before = files(tmp_path)
    assert job(store, tmp_path, "2024-02-01T06:00", formats=["html", "pdf"]).run_once().written == 2
    after = files(tmp_path)
    assert {k: after[k] for k in before} == before  # the HTML files were not rewritten
    assert set(after) - set(before) == {f"{m}/2024-01.pdf" for m in MILLS}


# ----------------------------------------------------------------------------- mail
class Inbox:
    """aiosmtpd handler and authenticator: keeps each message and each login attempt."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, list[str], bytes, bool]] = []
        self.logins: list[tuple[str, bytes, bool]] = []

    async def handle_DATA(self, server, session, envelope) -> str:
        self.messages.append(
            (
                envelope.mail_from,
                list(envelope.rcpt_tos),
                envelope.content,
                bool(session.authenticated),
            )
        )
        return "250 OK"

    def __call__(self, server, session, envelope, mechanism, auth_data) -> AuthResult:
        ok = isinstance(auth_data, LoginPassword) and (auth_data.login, auth_data.password) == (
            USER.encode(),
            PASSWORD.encode(),
        )
        self.logins.append((mechanism, getattr(auth_data, "login", b""), ok))
        return AuthResult(success=ok, handled=False)  # not handled: aiosmtpd answers 535


@pytest.fixture
def smtp_server(tmp_path):
    """A STARTTLS-only SMTP server on 127.0.0.1 that requires a login over TLS; its CA file."""
    ca = trustme.CA()
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ca.issue_cert("127.0.0.1").configure_cert(context)
    ca_file = tmp_path / "ca.pem"
    ca.cert_pem.write_to_path(str(ca_file))
    inbox = Inbox()
    controller = Controller(
        inbox,
        hostname="127.0.0.1",
        port=free_loopback_port(),
        tls_context=context,
        require_starttls=True,
        authenticator=inbox,
        auth_require_tls=True,
    )
    controller.start()
    try:
        yield inbox, controller.port, ca_file
    finally:
        controller.stop()


def mail_settings(port: int, ca_file: Path, password_file: Path) -> dict:
    password_file.write_text(PASSWORD + "\n", encoding="utf-8")
    return {
        "host": "127.0.0.1",
        "port": port,
        "username": USER,
        "password_file": password_file,
        "ca_file": ca_file,
        "sender": "millwatch@plant.example",
        "recipients": ["manager@plant.example", "maint@plant.example"],
        "timeout_s": 10,
    }


def test_each_report_is_mailed_once_over_starttls_with_the_pdf_attached(
    store, tmp_path, smtp_server, caplog
):
    inbox, port, ca_file = smtp_server
    mail = mail_settings(port, ca_file, tmp_path / "secret")
    caplog.set_level(logging.DEBUG)
    summary = job(store, tmp_path / "r", "2024-02-01T06:00", mail=mail).run_once()
    assert (summary.written, summary.mailed, summary.failed) == (2, 2, 0)
    assert len(inbox.messages) == 2
    assert inbox.logins and all(ok and login == USER.encode() for _, login, ok in inbox.logins)
    for sender, rcpts, content, authenticated in inbox.messages:
        assert authenticated and sender == "millwatch@plant.example"
        assert rcpts == ["manager@plant.example", "maint@plant.example"]
        msg = email.message_from_bytes(content, policy=email.policy.default)
        mill_id = next(m for m in MILLS if m in msg["Subject"])
        attached = {p.get_filename(): p.get_content() for p in msg.iter_attachments()}
        pdf = (tmp_path / "r" / mill_id / "2024-01.pdf").read_bytes()
        assert attached[f"{mill_id}-2024-01.pdf"] == pdf
        assert f"{mill_id}-2024-01.html" in attached
        assert "2024-01" in msg.get_body(("plain",)).get_content()
    assert PASSWORD not in caplog.text
    assert all((tmp_path / "r" / m / "2024-01.mailed.json").is_file() for m in MILLS)
    # a restart sends nothing again
    assert job(store, tmp_path / "r", "2024-02-01T07:00", mail=mail).run_once().due == 0
    assert len(inbox.messages) == 2


def test_a_wrong_password_is_retried_then_alarmed_without_showing_it(
    store, tmp_path, smtp_server, caplog
):
    inbox, port, ca_file = smtp_server
    mail = mail_settings(port, ca_file, tmp_path / "secret")
    (tmp_path / "secret").write_text("wrong-pw", encoding="utf-8")
    seen: list[Observation] = []
    caplog.set_level(logging.DEBUG)
    j = job(store, tmp_path / "r", "2024-02-01T06:00", mail=mail, attempts=2, sink=seen.extend)
    assert j.run_once().failed == 2
    assert inbox.messages == []
    # 2 mills × 2 attempts, each trying PLAIN then LOGIN (smtplib), all refused
    assert [m for m, _, _ in inbox.logins].count("PLAIN") == 4
    assert not any(ok for _, _, ok in inbox.logins)
    failed = [o for o in seen if o.value > 0]
    assert {(o.mill_id, o.context["stage"], o.value) for o in failed} == {
        (m, "mail", 2.0) for m in MILLS
    }
    assert all("login as 'millwatch' refused (535)" in o.context["error"] for o in failed)
    assert "wrong-pw" not in caplog.text


def test_a_closed_smtp_port_is_retried_with_backoff_then_alarmed(store, tmp_path, caplog):
    mail = {
        "host": "127.0.0.1",
        "port": free_loopback_port(),
        "sender": "mw@plant.example",
        "recipients": ["manager@plant.example"],
        "timeout_s": 2,
    }
    seen: list[Observation] = []
    now = ["2024-02-01T06:00"]
    j = MonthEndJob(
        ReportSettings.model_validate(
            {
                "directory": tmp_path,
                "mail": mail,
                "attempts": 3,
                "backoff_s": 0.05,
                "retry_failed_after_s": 3600,
            }
        ),
        MILLS,
        store,
        alarm=seen.extend,
        clock=lambda: utc_ns(now[0]),
        in_process=True,
    )
    with caplog.at_level(logging.WARNING):
        summary = j.run_once()
    assert (summary.written, summary.mailed, summary.failed) == (2, 0, 2)
    assert "attempt 2 of 3" in caplog.text and "attempt 3 of 3" in caplog.text
    assert "ConnectionRefusedError" in caplog.text  # the cause is logged
    failures = j.status()["failures"]
    assert sorted((f["mill"], f["stage"], f["attempts"]) for f in failures) == sorted(
        (m, "mail", 3) for m in MILLS
    )
    assert all("connect failed" in f["error"] for f in failures)
    alarms = [o for o in seen if o.value > 0]
    assert len(alarms) == 2 and all(o.quantity == "report_failures" for o in alarms)
    # files were written; the month is not tried again before retry_failed_after_s …
    assert j.run_once().due == 0
    now[0] = "2024-02-01T07:01"  # … and then it is: still failing, alarmed again
    assert j.run_once().failed == 2


def test_a_directory_that_cannot_be_written_alarms_the_files_stage(store, tmp_path):
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("a file where the reports directory should be")
    seen: list[Observation] = []
    j = job(store, blocker, "2024-02-01T06:00", attempts=2, sink=seen.extend)
    assert j.run_once().failed == 2
    assert {(o.mill_id, o.context["stage"]) for o in seen if o.value > 0} == {
        (m, "files") for m in MILLS
    }
    assert all("NotADirectoryError" in f["error"] for f in j.status()["failures"])


def test_the_alarm_reaches_the_store_through_the_worker_thread(tmp_path):
    """The job's observation, handed to a real worker, becomes a stored ``report_delivery``
    alarm whose message names the month, the stage and the cause; a later success clears its
    condition (latched: it stays raised until acknowledged)."""
    with Store(tmp_path / "w.db") as store:
        worker = Worker({A.id: A}, {A.id: MillJob(A)}, store, None)
        t = utc_ns("2024-02-01T06:00")
        worker.request_observations(
            [
                Observation(
                    A.id,
                    "report_failures",
                    4.0,
                    t,
                    {
                        "stage": "mail",
                        "month": "2024-01",
                        "error": "SMTP server x:587: connect failed",
                    },
                )
            ]
        )
        worker.step(BlockQueue(10), timeout_s=0.0)
        (alarm,) = store.alarms(mill_id=A.id)
        assert (alarm.rule, alarm.subject, alarm.severity, alarm.state) == (
            "report_delivery",
            "mail",
            "alarm",
            "raised",
        )
        assert "2024-01" in alarm.message and "connect failed" in alarm.advice
        assert "4 attempts" in alarm.message
        worker.request_observations(
            [
                Observation(
                    A.id, "report_failures", 0.0, t + 10**9, {"stage": "mail", "month": "2024-01"}
                )
            ]
        )
        worker.step(BlockQueue(10), timeout_s=0.0)
        (alarm,) = store.alarms(mill_id=A.id)
        assert alarm.state == "raised" and not alarm.condition  # latched until acknowledged


class RefusingInbox:
    """A plain SMTP handler that refuses one recipient (550) and keeps each message."""

    def __init__(self, refuse: str) -> None:
        self.refuse = refuse
        self.messages: list[tuple[list[str], bytes]] = []

    async def handle_RCPT(self, server, session, envelope, address, rcpt_options) -> str:
        if address == self.refuse:
            return "550 5.1.1 no such mailbox"
        envelope.rcpt_tos.append(address)
        return "250 OK"

    async def handle_DATA(self, server, session, envelope) -> str:
        self.messages.append((list(envelope.rcpt_tos), envelope.content))
        return "250 OK"


@pytest.fixture
def refusing_server():
    inbox = RefusingInbox("gone@plant.example")
    controller = Controller(inbox, hostname="127.0.0.1", port=free_loopback_port())
    controller.start()
    try:
        yield inbox, controller.port
    finally:
        controller.stop()


def plain_mail(port: int, **extra) -> dict:
    return {
        "host": "127.0.0.1",
        "port": port,
        "starttls": False,
        "sender": "millwatch@plant.example",
        "recipients": ["manager@plant.example", "gone@plant.example"],
        "timeout_s": 10,
        **extra,
    }


def test_a_refused_recipient_is_alarmed_once_and_the_others_get_one_copy(
    store, tmp_path, refusing_server
):
    inbox, port = refusing_server
    seen: list[Observation] = []
    j = job(store, tmp_path, "2024-02-01T06:00", mail=plain_mail(port), attempts=3,
            sink=seen.extend)  # fmt: skip
    summary = j.run_once()
    assert (summary.written, summary.mailed) == (2, 2)
    assert sorted(r for r, _ in inbox.messages) == [["manager@plant.example"]] * 2
    raised = [o for o in seen if o.value > 0]
    assert {o.mill_id for o in raised} == set(MILLS) and len(raised) == 2
    assert all("gone@plant.example" in o.context["error"] and "550" in o.context["error"]
               for o in raised)  # fmt: skip
    # no clean mail observation clears it at once
    assert not [o for o in seen if o.value == 0 and o.context["stage"] == "mail"]
    # neither a retry round, a later pass nor a restart sends it again
    assert j.run_once().due == 0
    assert job(store, tmp_path, "2024-02-02T06:00", mail=plain_mail(port)).run_once().due == 0
    assert len(inbox.messages) == 2
    receipt = (tmp_path / A.id / "2024-01.mailed.json").read_text()
    assert "gone@plant.example" in receipt


def test_the_csv_zip_is_attached_when_the_csv_format_is_asked(store, tmp_path, refusing_server):
    inbox, port = refusing_server
    mail = plain_mail(port, recipients=["manager@plant.example"], attach=["csv", "pdf"])
    assert job(store, tmp_path, "2024-02-01T06:00", mail=mail).run_once().mailed == 2
    for _, content in inbox.messages:
        msg = email.message_from_bytes(content, policy=email.policy.default)
        mill_id = next(m for m in MILLS if m in msg["Subject"])
        attached = {p.get_filename(): p.get_content() for p in msg.iter_attachments()}
        assert set(attached) == {f"{mill_id}-2024-01.zip", f"{mill_id}-2024-01.pdf"}
        zipped = attached[f"{mill_id}-2024-01.zip"]
        assert zipped == (tmp_path / mill_id / "2024-01.zip").read_bytes()
        assert "ZIP" in msg.get_body(("plain",)).get_content()
