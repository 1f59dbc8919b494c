"""Which mills a worker analyses when several workers share a zenoh router (README "Scale").

A worker's ``[worker] partition`` is a list of zenoh key expressions. The worker analyses exactly
the configured mills whose live key expression (``millwatch/v1/<site>/<mill>/*``, see
:func:`millwatch.ingest.keys.mill_pattern`) *intersects* one of them, using zenoh's own
:meth:`zenoh.KeyExpr.intersects`, so a partition means what it would mean to a zenoh subscriber:
``millwatch/v1/rustenburg/**`` is every mill of site ``rustenburg``,
``millwatch/v1/*/sag-5200-lrs/**`` one mill wherever it is. An empty partition keeps every
configured mill (one worker does it all). A partition entry that matches no configured mill is
an error naming it: a typo would otherwise leave mills unanalysed without a word.

Two workers must not analyse the same mill: :func:`check_exclusive` asks the router for the
mills' liveliness tokens (:func:`millwatch.ingest.keys.worker_token_key`) before a worker declares
its own. The exception is a hot standby (``[worker] standby = true``, README "Scale-out"): its
tokens are ``…/@standby/<name>``, which the check does not see, so a primary starts (and
recovers) while a standby holds its mills, and a standby starts beside a live primary.
"""

from __future__ import annotations

import socket

import zenoh

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.keys import (
    mill_pattern,
    parse_worker_token_key,
    worker_name,
    worker_token_pattern,
)
from millwatch.settings import ServiceSettings, SettingsError

__all__ = ["check_exclusive", "partition_mills", "worker_identity"]

TOKEN_QUERY_TIMEOUT_S = 2.0


def partition_mills(
    mills: dict[str, MillConfig], partition: tuple[str, ...] | list[str]
) -> dict[str, MillConfig]:
    """The mills whose live keys intersect ``partition`` (all of them when it is empty);
    raises :class:`SettingsError` naming a partition entry that matches none of them."""
    if not partition:
        return dict(mills)
    exprs = {p: zenoh.KeyExpr(p) for p in partition}
    chosen: dict[str, MillConfig] = {}
    for entry, expr in exprs.items():
        hits = {m: c for m, c in mills.items() if expr.intersects(mill_pattern(c.site, c.id))}
        if not hits:
            known = ", ".join(sorted(f"{c.site}/{m}" for m, c in mills.items())) or "(none)"
            raise SettingsError(
                f"worker.partition: {entry!r} matches none of the configured mills ({known}); "
                "expected e.g. 'millwatch/v1/<site>/**'"
            )
        chosen.update(hits)
    return {m: mills[m] for m in mills if m in chosen}  # configuration order


def worker_identity(settings: ServiceSettings) -> str:
    """The worker's name: ``[worker] name``, else the host name made into a key segment."""
    return settings.worker.name or worker_name(socket.gethostname())


def check_exclusive(session: zenoh.Session, mills: dict[str, MillConfig], me: str) -> None:
    """Raise :class:`SettingsError` when another live primary worker holds a token of one of
    ``mills`` (its partition overlaps ours); ``me``: this worker's name, whose own old tokens (a
    restart before the router noticed the crash) are not a conflict. Standbys' tokens are not
    asked for: they never conflict (module docstring)."""
    taken: list[str] = []
    for config in mills.values():
        pattern = worker_token_pattern(config.site, config.id)
        for reply in session.liveliness().get(pattern, timeout=TOKEN_QUERY_TIMEOUT_S):
            if reply.ok is None:
                continue
            _, mill, other = parse_worker_token_key(str(reply.ok.key_expr))
            if other != me:
                taken.append(f"{mill} (worker {other!r})")
    if taken:
        raise SettingsError(
            "worker.partition: another worker already analyses "
            + ", ".join(sorted(taken))
            + "; make the workers' partitions disjoint (each mill exactly once), or make this "
            "worker a hot standby of them ([worker] standby = true)"
        )
