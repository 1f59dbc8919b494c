"""The month-end job: every mill's report of each finished local month, written and mailed.

Diering 2011 §10.6 asks that "reports should be automatically generated and distributed to site
management". :class:`MonthEndJob` runs in its own thread in ``millwatch serve`` and the demo
(started by :class:`~millwatch.worker.runtime.ServiceRuntime`), never in the worker thread:

* every ``check_every_s`` (and at once on start) it looks, per mill, at the finished local
  calendar months (the mill's ``time_zone``) of the last ``catch_up_months``, ``delay_s`` after
  their end: a month with stored data whose files are missing (or whose mail receipt is, when
  mail is configured) is *due*. A service that was down at month end therefore catches up when
  it starts, and one that restarts does nothing twice: files are written atomically
  (:func:`~millwatch.reports.files.write_atomic`), so a file that exists is complete, and a mail
  leaves a receipt ``<YYYY-MM>.mailed.json`` beside the files once the server took it.
* reports are built and rendered by ``jobs`` processes started for the run (``spawn``, lowered
  priority, one per core by default), several mills at once, so the worker's real-time path
  keeps its core and its interpreter lock; with ``in_process`` (``millwatch report``, tests)
  the job's own thread renders.
* each stage (``files``: build, render, write; ``mail``) is tried ``attempts`` times, waiting
  ``backoff_s`` doubled each time (at most ``backoff_max_s``). What still fails is logged with
  its cause, kept in :meth:`status` (``GET /reports/status``) and raised as the
  ``report_delivery`` alarm of the mill (``alarm`` sink: the worker's
  :meth:`~millwatch.worker.worker.Worker.request_observations`, so it is stored, shown by
  ``GET /alarms`` and published like any alarm). The month is tried again after
  ``retry_failed_after_s``; a later success sends a clean observation (the latched alarm then
  waits for an acknowledgement). A mail the server took for some recipients and refused for
  others is delivered, not retried (a retry would give the others another copy): its receipt
  lists the refused addresses, and the ``report_delivery`` alarm names them, once.
"""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from millwatch.alarms.observations import Observation
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.reports.files import EXTENSIONS, render_files, report_path, write_atomic
from millwatch.reports.starts import current_month, month_bounds_ns, month_days
from millwatch.store.database import Store

if TYPE_CHECKING:
    from millwatch.settings import ReportSettings

__all__ = ["Failure", "MonthEndJob", "RunSummary", "due_months", "write_report"]

log = logging.getLogger(__name__)

#: ``nice`` increment of the render processes: the live worker wins the CPU when both want it.
RENDER_NICENESS = 10
#: How often a waiting job thread checks whether it is asked to stop, s.
POLL_S = 0.5
RECEIPT = "mailed.json"

AlarmSink = Callable[[list[Observation]], None]


@dataclass(frozen=True, slots=True)
class Failure:
    """A stage of one mill's month that failed all its attempts; ``error`` the last cause."""

    mill: str
    month: str
    stage: str
    attempts: int
    error: str
    t_ns: int
    retry_after_ns: int


@dataclass(frozen=True, slots=True)
class RunSummary:
    """One pass of the job: months due, files written and mails sent, failures."""

    started_ns: int
    finished_ns: int
    due: int
    written: int
    mailed: int
    failed: int


# ----------------------------------------------------------------------------- one report
def write_report(
    store: Store, config: MillConfig, month: str, formats: Iterable[str], directory: Path
) -> dict[str, str]:
    """Build ``config``'s mill's report of ``month`` from ``store``, render it in ``formats``
    and write each file atomically under ``directory``; extension → path written."""
    from millwatch.reports.monthly import build_monthly_report

    (directory / config.id).mkdir(parents=True, exist_ok=True)  # fails before the work if it must
    report = build_monthly_report(store, config, month)
    written: dict[str, str] = {}
    for ext, data in render_files(report, formats).items():
        path = report_path(directory, config.id, month, ext)
        write_atomic(path, data)
        written[ext] = str(path)
    return written


def _write_report_job(
    store_path: str, config: dict[str, Any], month: str, formats: tuple[str, ...], directory: str
) -> dict[str, str]:
    """:func:`write_report` in a render process (opens the store itself)."""
    with Store(store_path) as store:
        return write_report(store, MillConfig.model_validate(config), month, formats,
                            Path(directory))  # fmt: skip


def _lower_priority() -> None:
    """Render-process initializer: below the worker's priority (module docstring)."""
    with contextlib.suppress(OSError):  # not permitted here: the normal priority, then
        os.nice(RENDER_NICENESS)


# ----------------------------------------------------------------------------- which months
def _month_before(month: str, k: int = 1) -> str:
    year, mon = int(month[:4]), int(month[5:])
    index = year * 12 + (mon - 1) - k
    return f"{index // 12:04d}-{index % 12 + 1:02d}"


def due_months(config: MillConfig, now_ns: int, delay_s: float, back: int) -> list[str]:
    """The finished local months of ``config``'s mill among the last ``back``, oldest first,
    whose end lies at least ``delay_s`` before ``now_ns`` (candidates; data and files are
    checked by the job)."""
    this = current_month(config, now_ns)
    out = []
    for k in range(back, 0, -1):
        month = _month_before(this, k)
        end = month_bounds_ns(month, config.time_zone)[1]
        if end + delay_s * 1e9 <= now_ns:
            out.append(month)
    return out


def has_data(store: Store, config: MillConfig, month: str) -> bool:
    """The store holds something of the mill in the month (an event, a damage row or a
    steady-state window): an empty month gets no report."""
    start, end = month_bounds_ns(month, config.time_zone)
    if store.events(config.id, since_ns=start, until_ns=end, limit=1):
        return True
    days = month_days(month)
    if store.damage(config.id, days[0], days[-1]):
        return True
    return bool(store.records(config.id, "steady", since_ns=start, until_ns=end, limit=1))


# ----------------------------------------------------------------------------- the job
class MonthEndJob:
    """Writes and mails the monthly reports (module docstring)."""

    def __init__(
        self,
        settings: ReportSettings,
        mills: Mapping[str, MillConfig],
        store: Store,
        *,
        alarm: AlarmSink | None = None,
        clock: Callable[[], int] = time.time_ns,
        in_process: bool = False,
    ) -> None:
        self.settings = settings
        self.mills = dict(mills)
        self.store = store
        self.alarm = alarm
        self._clock = clock
        self.in_process = in_process
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._failures: dict[tuple[str, str, str], Failure] = {}
        #: Mails delivered to some recipients and refused for others: task → the alarm's text.
        self._refused: dict[tuple[str, str], str] = {}
        self.last_run: RunSummary | None = None
        self.busy = False
        self.next_check_ns: int | None = None
        self.runs = 0

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        self._thread = threading.Thread(target=self._loop, name="millwatch-reports", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 30.0) -> None:
        """Ask the thread to stop (between reports, or while waiting) and join it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout_s)
            if self._thread.is_alive():
                log.warning("report job still busy after %.0f s; leaving it", timeout_s)
            self._thread = None

    def _loop(self) -> None:
        every = self.settings.check_every_s
        while not self._stop.is_set():
            try:
                self.run_once()
            except Exception:  # a bug of ours: logged, the next pass tries again
                log.exception("month-end report job failed; trying again in %.0f s", every)
            self.next_check_ns = self._clock() + int(every * 1e9)
            self._stop.wait(every)

    # ------------------------------------------------------------------ one pass
    def run_once(self) -> RunSummary:
        """Make every due report (module docstring); what it did."""
        started = self._clock()
        self.busy = True
        try:
            due = self._due(started)
            renders = [t for t in due if self._missing(*t)]
            written = self._stage("files", renders, self._render_round)
            mailed: list[tuple[str, str]] = []
            if self.settings.mail is not None:
                mails = [t for t in due
                         if not self._missing(*t) and not self._receipt(*t).exists()]  # fmt: skip
                mailed = self._stage("mail", mails, self._mail_round)
        finally:
            self.busy = False
        failed = sum(1 for f in self.failures() if f.t_ns >= started)
        summary = RunSummary(started, self._clock(), len(due), len(written), len(mailed), failed)
        self.last_run = summary
        self.runs += 1
        if due:
            log.info("month-end reports: %d due, %d written, %d mailed, %d failed",
                     summary.due, summary.written, summary.mailed, summary.failed)  # fmt: skip
        return summary

    def _due(self, now: int) -> list[tuple[str, str]]:
        s = self.settings
        out = []
        for mill_id, config in self.mills.items():
            for month in due_months(config, now, s.delay_s, s.catch_up_months):
                if not self._missing(mill_id, month) and (
                    s.mail is None or self._receipt(mill_id, month).exists()
                ):
                    continue
                if self._waiting(mill_id, month, now) or not has_data(self.store, config, month):
                    continue
                out.append((mill_id, month))
        return out

    def _waiting(self, mill_id: str, month: str, now: int) -> bool:
        """A stage of the month failed recently: not before ``retry_failed_after_s``."""
        return any(
            f.mill == mill_id and f.month == month and now < f.retry_after_ns
            for f in self._failures.values()
        )

    def _missing(self, mill_id: str, month: str) -> list[str]:
        d = self.settings.directory
        return [f for f in self.settings.formats
                if not report_path(d, mill_id, month, EXTENSIONS[f]).exists()]  # fmt: skip

    def _receipt(self, mill_id: str, month: str) -> Path:
        return self.settings.directory / mill_id / f"{month}.{RECEIPT}"

    # ------------------------------------------------------------------ retries and alarms
    def _stage(
        self,
        stage: str,
        tasks: list[tuple[str, str]],
        round_: Callable[[list[tuple[str, str]]], dict[tuple[str, str], str | None]],
    ) -> list[tuple[str, str]]:
        """Try ``tasks`` in rounds (``round_``: task → error or None) with backoff between
        rounds; the tasks that succeeded. Final failures are recorded and alarmed."""
        s = self.settings
        done: list[tuple[str, str]] = []
        pending, errors = list(tasks), {}
        for attempt in range(1, s.attempts + 1):
            if not pending or self._stop.is_set():
                break
            if attempt > 1:
                delay = min(s.backoff_s * 2 ** (attempt - 2), s.backoff_max_s)
                log.warning("report %s: %d failed, attempt %d of %d in %.0f s", stage,
                            len(pending), attempt, s.attempts, delay)  # fmt: skip
                if self._stop.wait(delay):
                    break
            results = round_(pending)
            errors.update({t: e for t, e in results.items() if e is not None})
            ok = [t for t in pending if t in results and results[t] is None]
            done += ok
            pending = [t for t in pending if t not in ok]
            if ok:
                self._succeeded(stage, ok)
        if not self._stop.is_set():
            for task in pending:
                self._failed(stage, task, s.attempts, errors.get(task, "not attempted"))
        return done

    def _succeeded(self, stage: str, tasks: list[tuple[str, str]]) -> None:
        now = self._clock()
        partial = {t: self._refused.pop(t) for t in tasks if t in self._refused}
        with self._lock:
            for mill_id, month in tasks:
                self._failures.pop((mill_id, month, stage), None)
        self._alarm([Observation(m, "report_failures", 0.0, now,
                                 {"stage": stage, "month": mo, "error": ""})
                     for m, mo in tasks if (m, mo) not in partial])  # fmt: skip
        for task, error in partial.items():  # delivered, but not to everyone: alarmed once
            self._failed(stage, task, 1, error, retry=False)

    def _failed(
        self, stage: str, task: tuple[str, str], attempts: int, error: str, retry: bool = True
    ) -> None:
        """Record and alarm a failure; ``retry``: the month is tried again later (not for a
        mail that some recipients received: its receipt stops a re-send)."""
        mill_id, month = task
        now = self._clock()
        after = now + int(self.settings.retry_failed_after_s * 1e9) if retry else now
        failure = Failure(mill_id, month, stage, attempts, error, now, after)
        with self._lock:
            self._failures[(mill_id, month, stage)] = failure
        again = f"tried again in {self.settings.retry_failed_after_s:.0f} s" if retry else \
            "not sent again"  # fmt: skip
        log.error("monthly report of mill %s for %s: %s failed after %d attempts: %s "
                  "(alarm report_delivery raised; %s)", mill_id, month, stage, attempts, error,
                  again)  # fmt: skip
        self._alarm([Observation(mill_id, "report_failures", float(attempts), now,
                                 {"stage": stage, "month": month, "error": error})])  # fmt: skip

    def _alarm(self, observations: list[Observation]) -> None:
        if self.alarm is None or not observations:
            return
        try:
            self.alarm(observations)
        except Exception:
            log.exception("could not hand the report_delivery observations to the alarms")

    # ------------------------------------------------------------------ files
    def _render_round(self, tasks: list[tuple[str, str]]) -> dict[tuple[str, str], str | None]:
        """Build, render and write the missing files of each task; task → error or None."""
        if self.in_process:
            out: dict[tuple[str, str], str | None] = {}
            for mill_id, month in tasks:
                if self._stop.is_set():
                    break
                try:
                    missing = self._missing(mill_id, month)
                    config = self.mills[mill_id]
                    write_report(self.store, config, month, missing, self.settings.directory)
                    out[(mill_id, month)] = None
                except Exception as exc:
                    out[(mill_id, month)] = _cause(exc)
            return out
        return self._render_in_processes(tasks)

    def _render_in_processes(
        self, tasks: list[tuple[str, str]]
    ) -> dict[tuple[str, str], str | None]:
        jobs = self.settings.jobs or len(os.sched_getaffinity(0))
        out: dict[tuple[str, str], str | None] = {}
        pool = ProcessPoolExecutor(
            max_workers=min(jobs, len(tasks)),
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_lower_priority,
        )
        try:
            futures: dict[Future[dict[str, str]], tuple[str, str]] = {
                pool.submit(_write_report_job, str(self.store.path),
                            self.mills[m].stored_form(), mo,
                            tuple(self._missing(m, mo)), str(self.settings.directory)): (m, mo)
                for m, mo in tasks
            }  # fmt: skip
            pending = set(futures)
            while pending and not self._stop.is_set():
                finished, pending = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
                for future in finished:
                    exc = future.exception()
                    out[futures[future]] = None if exc is None else _cause(exc)
        finally:
            pool.shutdown(wait=not self._stop.is_set(), cancel_futures=True)
        return out

    # ------------------------------------------------------------------ mail
    def _mail_round(self, tasks: list[tuple[str, str]]) -> dict[tuple[str, str], str | None]:
        from millwatch.reports.mail import report_message, send_message

        mail = self.settings.mail
        assert mail is not None
        out: dict[tuple[str, str], str | None] = {}
        for mill_id, month in tasks:
            if self._stop.is_set():
                break
            config = self.mills[mill_id]
            d = self.settings.directory
            paths = {EXTENSIONS[f]: report_path(d, mill_id, month, EXTENSIONS[f])
                     for f in self.settings.formats}  # fmt: skip
            attach = {EXTENSIONS[f] for f in mail.attach}
            try:
                files = {ext: p.read_bytes() for ext, p in paths.items() if ext in attach}
                where = {e: str(p) for e, p in paths.items()}
                msg = report_message(
                    mail, mill_id=mill_id, site=config.site, month=month, files=files, paths=where
                )
                refused = send_message(mail, msg)
                receipt = {"t_ns": self._clock(), "host": mail.host, "port": mail.port,
                           "recipients": [r for r in mail.recipients if r not in refused],
                           "refused": refused, "message_id": msg["Message-ID"],
                           "attached": sorted(files)}  # fmt: skip
                write_atomic(self._receipt(mill_id, month), json.dumps(receipt).encode())
                out[(mill_id, month)] = None
                if refused:
                    who = "; ".join(f"{r} ({why})" for r, why in sorted(refused.items()))
                    self._refused[(mill_id, month)] = (
                        f"recipients refused: {who}; the others received it"
                    )
            except Exception as exc:
                out[(mill_id, month)] = _cause(exc)
        return out

    # ------------------------------------------------------------------ status
    def failures(self) -> list[Failure]:
        with self._lock:
            return sorted(self._failures.values(), key=lambda f: (f.mill, f.month, f.stage))

    def status(self, *, latest: bool = True) -> dict[str, Any]:
        """What ``GET /reports/status`` shows (no password: only where mail goes);
        ``latest``: each mill's newest complete month, read from the directory."""
        s = self.settings
        mail = s.mail
        return {
            "enabled": True,
            "running": self._thread is not None and self._thread.is_alive(),
            "busy": self.busy,
            "directory": str(s.directory),
            "formats": list(s.formats),
            "mail": None if mail is None else {
                "host": mail.host, "port": mail.port, "starttls": mail.starttls,
                "username": mail.username, "sender": mail.sender,
                "recipients": list(mail.recipients), "attach": list(mail.attach),
            },
            "delay_s": s.delay_s,
            "catch_up_months": s.catch_up_months,
            "runs": self.runs,
            "last_run": None if self.last_run is None else asdict(self.last_run),
            "next_check_ns": self.next_check_ns,
            "failures": [asdict(f) for f in self.failures()],
        } | ({"latest": self.latest()} if latest else {})  # fmt: skip

    def latest(self) -> dict[str, str | None]:
        """Each mill's newest month with every format written (from the directory)."""
        out: dict[str, str | None] = {}
        for mill_id in self.mills:
            folder = self.settings.directory / mill_id
            months = sorted({p.name[:7] for p in folder.glob("????-??.*")}, reverse=True) \
                if folder.is_dir() else []  # fmt: skip
            out[mill_id] = next((m for m in months if not self._missing(mill_id, m)), None)
        return out


def _cause(exc: BaseException) -> str:
    """One line naming the error (the mail module's messages carry no password)."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
