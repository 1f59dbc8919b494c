"""Service settings: one validated TOML file for ``millwatch serve``, read at the CLI entry.

Relative paths in the file are relative to the file itself, so a plant directory can be moved
as a whole. Errors name the file and the field (``archive.rotate_seconds: must be > 0``).
Nothing is read at import time: :func:`load_service_settings` is called by the command, and
tests build :class:`ServiceSettings` directly.

Example (``deploy/plant.toml``)::

    [zenoh]
    listen = ["tcp/127.0.0.1:7447"]      # loopback by default; plants connect to a router

    [archive]
    directory = "../var/archive"

    [store]
    path = "../var/millwatch.db"

    [mills]
    files = ["mills/sag-5200-lrs.toml"]  # or: directory = "mills"

Scale-out (``deploy/worker-*.toml``, ``deploy/api.toml``): ``[zenoh] mode = "client"`` with
``connect`` = the router, ``[worker] partition`` = the key expressions of this worker's mills,
``[api] query_timeout_s`` for ``millwatch api``.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Literal

import zenoh
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from analytics.drivetrain.mill_config import MillConfig, describe_validation_error
from ingest.keys import LAYOUT_VERSION, ROOT
from ingest.mill_files import load_mill_config, load_mill_configs

__all__ = ["ServiceSettings", "SettingsError", "load_service_settings"]


_LIVE_PREFIX = "/".join([ROOT, LAYOUT_VERSION, ""])


class SettingsError(ValueError):
    """Unusable service settings; the message names the file and the fields."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ZenohSettings(_Strict):
    """Zenoh session: loopback peer by default; ``connect`` to a router in a plant."""

    mode: Literal["peer", "client"] = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()


class ArchiveSettings(_Strict):
    """MCAP archive: hourly, 256 MiB files, 64 KiB chunks flushed at least every 0.1 s."""

    directory: Path = Path("var/archive")
    rotate_seconds: Annotated[float, Field(gt=0)] = 3600.0
    rotate_bytes: Annotated[int, Field(gt=0)] = 256 * 2**20
    chunk_size: Annotated[int, Field(gt=0)] = 64 * 2**10
    max_latency_s: Annotated[float, Field(gt=0)] = 0.1


class StoreSettings(_Strict):
    path: Path = Path("var/millwatch.db")


class WorkerSettings(_Strict):
    """Queue between zenoh callbacks and the worker, how often to checkpoint, and which mills
    this worker analyses when several share a zenoh router (scale-out):

    * ``partition``: zenoh key expressions; the worker analyses exactly the configured mills
      whose live keys (``millwatch/v1/<site>/<mill>/*``) intersect one of them, e.g.
      ``["millwatch/v1/rustenburg/**"]``. Empty (default): every configured mill.
    * ``name``: the worker's name in its liveliness tokens and in API errors
      (``[a-z0-9][a-z0-9_-]*``); default: the host name.
    * ``recovery_jobs``: processes that replay a long archive tail at start, the mills split
      between them (0, the default: one per available core; 1: the worker alone). A tail under
      32 MB is always replayed by the worker alone.
    * ``gateway_wait_s``: at start, each mill is subscribed once a gateway publisher of every
      one of its channels is up (so their caches come, in order, before live blocks: issue 16),
      or after this many seconds with whatever is up (default 10 s: 2.5 times zenoh's longest
      connect retry period, 4 s). Gateways with plain publishers are never seen as up: their
      mills are subscribed after the wait (0: subscribe at once, no recovery wait).
    """

    queue_blocks: Annotated[int, Field(gt=0)] = 200_000
    checkpoint_seconds: Annotated[float, Field(gt=0)] = 60.0
    stale_after_s: Annotated[float, Field(gt=0)] = 10.0
    name: Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_-]{0,63}$")] | None = None
    partition: tuple[str, ...] = ()
    recovery_jobs: Annotated[int, Field(ge=0, le=256)] = 0
    gateway_wait_s: Annotated[float, Field(ge=0, le=600)] = 10.0

    @field_validator("partition")
    @classmethod
    def _key_expressions(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        for expr in value:
            try:
                zenoh.KeyExpr(expr)
            except zenoh.ZError as exc:
                reason = str(exc).split(" at /")[0]
                raise ValueError(f"{expr!r} is not a zenoh key expression ({reason})") from None
            if not expr.startswith(_LIVE_PREFIX):
                raise ValueError(f"{expr!r} must start with {_LIVE_PREFIX} (the live key layout)")
        return value


class ApiSettings(_Strict):
    """The REST API; ``query_timeout_s``: how long the API waits for a worker's answer over
    zenoh (``millwatch api``) before it answers 504."""

    host: str = "127.0.0.1"
    port: Annotated[int, Field(ge=0, le=65535)] = 8080
    api_key: str | None = None
    query_timeout_s: Annotated[float, Field(gt=0, le=600)] = 10.0


class MillSettings(_Strict):
    """Which mill configuration files this worker analyses."""

    files: tuple[Path, ...] = ()
    directory: Path | None = None


class ServiceSettings(_Strict):
    zenoh: ZenohSettings = ZenohSettings()
    archive: ArchiveSettings = ArchiveSettings()
    store: StoreSettings = StoreSettings()
    worker: WorkerSettings = WorkerSettings()
    api: ApiSettings = ApiSettings()
    mills: MillSettings = MillSettings()

    def resolved(self, base: Path) -> ServiceSettings:
        """The same settings with relative paths made relative to ``base``."""

        def at(p: Path) -> Path:
            return p if p.is_absolute() else (base / p).resolve()

        mills = MillSettings(
            files=tuple(at(p) for p in self.mills.files),
            directory=None if self.mills.directory is None else at(self.mills.directory),
        )
        return self.model_copy(
            update={
                "archive": self.archive.model_copy(
                    update={"directory": at(self.archive.directory)}
                ),
                "store": StoreSettings(path=at(self.store.path)),
                "mills": mills,
            }
        )

    def load_mills(self) -> dict[str, MillConfig]:
        """The configured mills by id; raises naming the file and field of a bad one."""
        mills = load_mill_configs(self.mills.directory) if self.mills.directory else {}
        for path in self.mills.files:
            config = load_mill_config(path)
            if config.id in mills:
                raise SettingsError(f"{path}: mill id {config.id!r} is configured twice")
            mills[config.id] = config
        if not mills:
            raise SettingsError("mills: no mill configured (set mills.files or mills.directory)")
        return mills


def load_service_settings(path: str | Path) -> ServiceSettings:
    """Read and validate a service settings TOML file."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise SettingsError(f"{path}: cannot read ({exc})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError(f"{path}: TOML syntax error: {exc}") from exc
    try:
        settings = ServiceSettings.model_validate(data)
    except ValidationError as exc:
        raise SettingsError(f"{path}: " + "; ".join(describe_validation_error(exc))) from exc
    return settings.resolved(path.parent.resolve())
