"""What the per-mill endpoints answer: life, starts of a month, latest spectrum.

The service layer between the routes (:mod:`millwatch.api.routes.mills`) and the store/runtime: it
finds
the mill (or raises :class:`~millwatch.api.errors.NotFound` naming it and the mills that exist),
reads the store, and reads live values only from ``runtime.status`` — the snapshot the worker
thread refreshes every 0.5 s — never from the analyzer itself.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.errors import NotFound, Unavailable
from millwatch.reports.history import life_inputs
from millwatch.reports.life import LifeReport, compute_life
from millwatch.reports.monthly import MonthlyReport, build_monthly_report
from millwatch.reports.starts import MonthStarts, current_month, starts_in_month
from millwatch.status import NO_STATUS, MillStatus
from millwatch.store.database import Store
from millwatch.worker.runtime import ServiceRuntime

__all__ = [
    "UNREACHABLE",
    "config_of",
    "mill_config",
    "mill_detail",
    "mill_life",
    "mill_spectrum",
    "mill_starts",
    "mill_summary",
    "site_mills",
    "store_of",
]

UNREACHABLE = "unreachable"
"""The state of a mill whose worker is gone (``millwatch api``): every channel counts as stale."""


def config_of(mills: Mapping[str, MillConfig], mill_id: str) -> MillConfig:
    """The configuration of a known mill; :class:`NotFound` naming it and the known ones."""
    config = mills.get(mill_id)
    if config is None:
        known = ", ".join(sorted(mills)) or "(none)"
        raise NotFound("Unknown mill", f"No mill {mill_id!r} is configured here; mills: {known}.")
    return config


def site_mills(mills: Mapping[str, MillConfig], site: str) -> dict[str, MillConfig]:
    """The configured mills of ``site``; :class:`NotFound` naming the sites there are."""
    found = {m: c for m, c in mills.items() if c.site == site}
    if not found:
        sites = ", ".join(sorted({c.site for c in mills.values()})) or "(none)"
        raise NotFound("Unknown site", f"No mill of site {site!r} is configured here; sites: "
                       f"{sites}.")  # fmt: skip
    return found


def mill_summary(
    config: MillConfig, status: MillStatus | None, worker: str | None
) -> dict[str, Any]:
    """One line of ``GET /mills``: state, stale channels and why the mill is held (if it is)
    from the worker's status; a mill without status (``None``: its worker is gone) is
    ``unreachable`` with every channel stale."""
    simulated = config.simulated
    if status is None:
        state, stale, held = UNREACHABLE, list(config.channels), None
    else:
        state, stale, held = status.state, status.stale_channels, status.held_reason
        if status.simulated is not None:
            simulated = status.simulated  # the worker's config decides
    return {
        "id": config.id,
        "site": config.site,
        "simulated": simulated,
        "drive": config.drive.layout,
        "starter": config.drive.starter,
        "state": state,
        "stale_channels": stale,
        "worker": worker,
        "held_reason": held,
    }


def mill_detail(
    config: MillConfig, status: MillStatus | None, worker: Mapping[str, Any]
) -> dict[str, Any]:
    """``GET /mills/{id}``: the summary, rated torques, the worker's status of the mill (as
    JSON data: what the worker set, ``{}`` without a status), and the worker that analyses it
    (name, partition, counters; ``live`` False when it is gone)."""
    return {
        **mill_summary(config, status, worker.get("name")),
        "rated_torque_knm": {
            "motor": config.motor_rated_torque_knm,
            "pinion": config.pinion_rated_torque_knm,
        },
        "status": {} if status is None else status.to_json(),
        "worker_status": dict(worker),
    }


def mill_config(runtime: ServiceRuntime, mill_id: str) -> MillConfig:
    """The configuration of a mill served here; :class:`NotFound` otherwise."""
    return config_of(runtime.mills, mill_id)


def store_of(runtime: ServiceRuntime) -> Store:
    """The open store; :class:`Unavailable` while the service starts or stops."""
    store = runtime.store
    if store is None:
        raise Unavailable(
            "Store closed",
            "The store is not open (the service is starting or "
            "stopping); try again in a few seconds.",
        )
    return store


def mill_life(runtime: ServiceRuntime, mill_id: str) -> LifeReport:
    """Damage so far and remaining life per component (:mod:`millwatch.reports.life`), with the
    worker's live damage (closed cycles not yet stored, the open residue)."""
    config = mill_config(runtime, mill_id)
    store = store_of(runtime)
    status = runtime.status.get(mill_id, NO_STATUS)
    with store.read_snapshot():
        report = compute_life(life_inputs(store, config, time.time_ns(),
                                          live=status.live_damage(),
                                          last_sample_ns=status.last_sample_ns))  # fmt: skip
    return report


def mill_month(runtime: ServiceRuntime, config: MillConfig) -> str:
    """The mill's current month: the local calendar month of its last analysed sample, as
    ``status.starts_this_month`` counts it (a replayed or recovering mill's month is its data's,
    not the wall clock's); the wall clock's month before any sample."""
    last = runtime.status.get(config.id, NO_STATUS).last_sample_ns
    return current_month(config, time.time_ns() if last is None else last)


def mill_starts(runtime: ServiceRuntime, mill_id: str, month: str | None) -> MonthStarts:
    """The starts of ``month`` (default: the mill's current month, :func:`mill_month`)."""
    config = mill_config(runtime, mill_id)
    month = month or mill_month(runtime, config)
    return starts_in_month(store_of(runtime), config, month)


def mill_monthly_report(runtime: ServiceRuntime, mill_id: str, month: str | None) -> MonthlyReport:
    """The monthly report of ``month`` (default: the mill's current month,
    :func:`mill_month`); a malformed month is a :class:`~millwatch.reports.starts.MonthError`
    (422)."""
    config = mill_config(runtime, mill_id)
    month = month or mill_month(runtime, config)
    return build_monthly_report(store_of(runtime), config, month)


def mill_spectrum(runtime: ServiceRuntime, mill_id: str) -> dict[str, Any]:
    """The latest stored harmonic table; :class:`NotFound` when none was computed yet."""
    mill_config(runtime, mill_id)
    latest = store_of(runtime).records(mill_id, "harmonics", limit=1)
    if not latest:
        raise NotFound(
            "No spectrum yet",
            f"Mill {mill_id!r} has no harmonic table yet: spectra "
            "are computed only in steady running, once per Welch window.",
        )
    t_ns, data = latest[0]
    config = mill_config(runtime, mill_id)
    return {"mill": mill_id, "simulated": config.simulated, "t_ns": t_ns, "harmonics": data}
