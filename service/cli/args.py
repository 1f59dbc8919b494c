"""Argument types for the command line: each names the rule the value broke."""

from __future__ import annotations

import argparse
import math
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # (imported when used: the TLS module loads cryptography)
    from millwatch.analytics.drivetrain.mill_config import MillConfig
    from millwatch.ingest.zenoh_tls import TlsFiles

__all__ = [
    "add_tls_arguments",
    "duration_seconds",
    "mill_option",
    "non_negative_float",
    "positive_float",
    "positive_int",
    "tls_files",
    "utc_time_ns",
]

_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
_INT64_MAX = 2**63 - 1


def positive_int(text: str) -> int:
    """A whole number > 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number > 0, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a whole number > 0, got {text}")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0."""
    value = _float(text, "> 0")
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def non_negative_float(text: str) -> float:
    """A finite number >= 0."""
    value = _float(text, ">= 0")
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text}")
    return value


def _float(text: str, rule: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number {rule}, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number {rule}, got {text}")
    return value


_DURATION_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}


def duration_seconds(text: str) -> float:
    """A duration > 0: seconds, or a number with unit s, m, h or d (``90s``, ``10m``, ``30d``)."""
    unit = text[-1:].lower()
    scale = _DURATION_UNITS.get(unit)
    number = text[:-1] if scale is not None else text
    try:
        value = float(number) * (scale or 1.0)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be a duration such as 90s, 10m, 2h or 30d, got {text!r}"
        ) from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a duration > 0, got {text!r}")
    return value


def utc_time_ns(text: str) -> int:
    """ISO-8601 with a zone (``2026-11-21T23:30:00Z``, ``...+01:00``) or integer ns since the
    Unix epoch; returns int ns (UTC)."""
    if text.strip().isdigit():
        if int(text) > _INT64_MAX:
            raise argparse.ArgumentTypeError(f"{text} ns does not fit int64")
        return int(text)
    try:
        moment = datetime.fromisoformat(text.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected ISO-8601 UTC like 2026-11-21T23:30:00Z or ns since the epoch, got {text!r}"
        ) from None
    if moment.tzinfo is None:
        raise argparse.ArgumentTypeError(f"{text!r} has no time zone; add Z for UTC")
    delta = moment - _EPOCH  # exact: days, seconds, microseconds
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000


def add_tls_arguments(group: argparse._ActionsContainer, name_help: str) -> None:
    """``--tls-dir`` and ``--tls-name``: mutual TLS to a plant router (``deploy/zenoh``)."""
    group.add_argument(
        "--tls-dir",
        type=Path,
        metavar="DIR",
        help="connect over mutual TLS with the certificates in DIR (ca.pem, NAME.pem, "
        "NAME-key.pem; made by 'millwatch zenoh-certs')",
    )
    group.add_argument("--tls-name", metavar="NAME", help=name_help)


def tls_files(args: argparse.Namespace, default_name: str | None) -> TlsFiles | None:
    """The TLS files ``--tls-dir``/``--tls-name`` name (None without ``--tls-dir``);
    :class:`ValueError` when no name is given and there is no default."""
    from millwatch.ingest.zenoh_tls import TlsFiles

    if args.tls_dir is None:
        return None
    name = args.tls_name or default_name
    if not name:
        raise ValueError("--tls-dir needs --tls-name: the certificate's name (e.g. "
                         "gateway.rustenburg.sag-5200-lrs)")  # fmt: skip
    d = args.tls_dir
    return TlsFiles(d / "ca.pem", d / f"{name}.pem", d / f"{name}-key.pem")


def mill_option(path: Path) -> MillConfig:
    """The mill file ``path`` given to ``--mill``, loaded; a bad one is a ValueError that names
    the option and the file's problem (the command's usual error line)."""
    from millwatch.ingest.mill_files import load_mill_config  # (pydantic: only when run)

    try:
        return load_mill_config(path)
    except ValueError as exc:
        raise ValueError(f"--mill {exc}") from exc
