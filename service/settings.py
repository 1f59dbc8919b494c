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

    [reports]                            # monthly reports, written after each local month end
    directory = "../var/reports"         # <directory>/<mill>/<YYYY-MM>.html|pdf|zip

    [reports.mail]                       # optional: mail each report (SMTP, STARTTLS)
    host = "smtp.example.com"
    username = "millwatch"
    password_file = "/run/secrets/smtp"  # or the environment variable MILLWATCH_SMTP_PASSWORD
    sender = "millwatch@example.com"
    recipients = ["site.manager@example.com"]

    [opcua]                              # optional OPC UA server (off by default)
    enabled = true
    endpoint = "opc.tcp://127.0.0.1:4840/millwatch"
    [[opcua.users]]
    name = "operator"                    # may acknowledge alarms
    password_file = "/run/secrets/opcua-operator"   # or password_env = "MILLWATCH_OPCUA_PASSWORD"

    [[api.users]]                        # per-user REST keys: actions recorded as this user
    name = "j.perez"
    role = "operator"                    # or "viewer": may not act on alarms
    key_file = "/run/secrets/api-j.perez"   # or key_env = "MILLWATCH_API_KEY_JPEREZ"

Scale-out (``deploy/worker-*.toml``, ``deploy/api.toml``): ``[zenoh] mode = "client"`` with
``connect`` = the router, ``[worker] partition`` = the key expressions of this worker's mills,
``[api] query_timeout_s`` for ``millwatch api``.
"""

from __future__ import annotations

import ipaddress
import os
import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Annotated, Any, Literal

import zenoh
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from millwatch.alarms.actions import DEFAULT_MAX_SHELVE_S
from millwatch.analytics.drivetrain.mill_config import MillConfig, describe_validation_error
from millwatch.ingest.keys import LAYOUT_VERSION, ROOT
from millwatch.ingest.mill_files import load_mill_config, load_mill_configs
from millwatch.ingest.zenoh_session import build_config
from millwatch.ingest.zenoh_tls import TlsFiles

__all__ = [
    "REPORT_FORMATS",
    "ApiSettings",
    "ApiUser",
    "MailSettings",
    "OpcUaSettings",
    "OpcUaUser",
    "ReportSettings",
    "ServiceSettings",
    "SettingsError",
    "ZenohSettings",
    "ZenohTls",
    "check_writable",
    "load_service_settings",
    "parse_formats",
]


_LIVE_PREFIX = "/".join([ROOT, LAYOUT_VERSION, ""])


class SettingsError(ValueError):
    """Unusable service settings; the message names the file and the fields."""


#: Monthly report formats written as files (:mod:`millwatch.reports.files`), in render order.
REPORT_FORMATS: tuple[str, ...] = ("html", "pdf", "csv")


def parse_formats(text: str | Iterable[str]) -> tuple[str, ...]:
    """Report formats from ``"html,pdf"`` or a list, checked against :data:`REPORT_FORMATS`,
    duplicates dropped; :class:`ValueError` naming an unknown one."""
    known = ", ".join(REPORT_FORMATS)
    items = text.split(",") if isinstance(text, str) else list(text)
    out: list[str] = []
    for item in (i.strip().lower() for i in items):
        if item not in REPORT_FORMATS:
            raise ValueError(f"report format {item!r} is not one of {known}")
        if item not in out:
            out.append(item)
    if not out:
        raise ValueError(f"no report format given (choose from {known})")
    return tuple(out)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ZenohTls(_Strict):
    """Mutual TLS of the zenoh session (:mod:`millwatch.ingest.zenoh_tls`): the files made by
    ``millwatch zenoh-certs`` in ``directory`` — ``ca.pem``, ``<name>.pem``, ``<name>-key.pem``
    — where ``name`` is this process's role, the certificate's common name the router's access
    control knows (``worker``, ``api``)."""

    directory: Path = Path("/etc/millwatch/tls")
    name: Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_.-]{0,127}$")]

    def files(self) -> TlsFiles:
        d = self.directory
        return TlsFiles(d / "ca.pem", d / f"{self.name}.pem", d / f"{self.name}-key.pem")


def _host_of(endpoint: str) -> str:
    address = endpoint.partition("/")[2].split("#")[0].split("?")[0]
    return address.rsplit(":", 1)[0].strip("[]")


def _plain_beyond_loopback(endpoint: str) -> bool:
    """A plain (``tcp``, ``udp``, ``ws``) endpoint that other hosts can reach: no TLS."""
    if not endpoint.startswith(("tcp/", "udp/", "ws/")):
        return False
    host = _host_of(endpoint)
    if host == "localhost":
        return False
    try:
        return not ipaddress.ip_address(host).is_loopback
    except ValueError:
        return True  # a host name: another host


class ZenohSettings(_Strict):
    """Zenoh session: loopback peer by default; ``connect`` to a router in a plant.

    ``tls``: mutual TLS (``[zenoh.tls]``; endpoints ``tls/<host>:<port>``). Closed by default:
    an endpoint other hosts can reach without TLS (``tcp/10.0.0.5:7447``, ``tcp/0.0.0.0:…``) is
    refused unless ``plain_beyond_loopback = true`` says so on purpose."""

    mode: Literal["peer", "client"] = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    tls: ZenohTls | None = None
    plain_beyond_loopback: bool = False

    @model_validator(mode="after")
    def _closed_by_default(self) -> ZenohSettings:
        for kind, endpoints in (("listen", self.listen), ("connect", self.connect)):
            for endpoint in endpoints:
                if endpoint.startswith("tls/") and self.tls is None:
                    raise ValueError(f"{kind}: {endpoint!r} needs [zenoh.tls] (directory, name)")
                if _plain_beyond_loopback(endpoint) and not self.plain_beyond_loopback:
                    raise ValueError(
                        f"{kind}: {endpoint!r} is reachable from other hosts without TLS; use "
                        "tls/<host>:<port> with [zenoh.tls], or set plain_beyond_loopback = "
                        "true on a network you trust"
                    )
        return self

    @model_validator(mode="after")
    def _endpoints(self) -> ZenohSettings:
        # (checks them; TLS endpoints are checked with their certificates when the session opens)
        build_config(mode=self.mode, listen=_plain(self.listen), connect=_plain(self.connect))
        return self


def _plain(endpoints: tuple[str, ...]) -> list[str]:
    return [e for e in endpoints if not e.startswith("tls/")]


class ArchiveSettings(_Strict):
    """MCAP archive: hourly, 256 MiB files, 64 KiB chunks flushed at least every 0.1 s.
    ``max_unwritten_mb``: while the archive cannot be written (a full disk), received blocks
    wait in memory up to this many MiB (compressed) and are archived in order once it can; the
    blocks beyond are fetched again from the gateways' spools
    (:class:`millwatch.worker.health.WriteEpisodes`)."""

    directory: Path = Path("var/archive")
    rotate_seconds: Annotated[float, Field(gt=0)] = 3600.0
    rotate_bytes: Annotated[int, Field(gt=0)] = 256 * 2**20
    chunk_size: Annotated[int, Field(gt=0)] = 64 * 2**10
    max_latency_s: Annotated[float, Field(gt=0)] = 0.1
    max_unwritten_mb: Annotated[float, Field(gt=0)] = 64.0


class StoreSettings(_Strict):
    path: Path = Path("var/millwatch.db")


class WorkerSettings(_Strict):
    """Queue between zenoh callbacks and the worker, how often to checkpoint, and which mills
    this worker analyses when several share a zenoh router (scale-out):

    * ``queue_blocks``: bounds memory, never what is kept: the callbacks' queue before the
      archiving thread and the analysis's queue after it each hold at most this many blocks; a
      full callbacks' queue slows the zenoh link down, and an analysis that falls behind reads
      the blocks it has no room for back from the archive (:mod:`millwatch.worker.archive_first`).

    * ``partition``: zenoh key expressions; the worker analyses exactly the configured mills
      whose live keys (``millwatch/v1/<site>/<mill>/*``) intersect one of them, e.g.
      ``["millwatch/v1/rustenburg/**"]``. Empty (default): every configured mill.
    * ``name``: the worker's name in its liveliness tokens and in API errors
      (``[a-z0-9][a-z0-9_-]*``); default: the host name.
    * ``standby``: ``true`` makes this worker a hot standby of its partition's mills (README
      "Scale-out"): it subscribes, archives, analyses and stores like the primary, with its
      own ``name``, archive and store, and the API answers from it only while the mill has no
      live primary. A primary refuses a mill another primary holds, never one a standby holds.
      A boolean (``true``/``false``), nothing else.
    * ``recovery_jobs``: processes that replay a long archive tail at start, the mills split
      between them (0, the default: one per available core; 1: the worker alone). A tail under
      32 MB is always replayed by the worker alone.
    * ``gateway_wait_s``: at start, each mill is subscribed once a gateway publisher of every
      one of its channels is up (so their caches come, in order, before live blocks: issue 16),
      or after this many seconds with whatever is up (default 10 s: 2.5 times zenoh's longest
      connect retry period, 4 s). Gateways with plain publishers are never seen as up: their
      mills are subscribed after the wait (0: subscribe at once, no recovery wait).

    Admission (README "Admission": what a block from any peer must be to be analysed):

    * ``max_ahead_s``: how far ahead of its receive time a block may reach — its samples as
      sent, and where its sequence number puts them after its channel's last block (default
      60 s: the gateways' clocks may run this far ahead of the worker's; a sender faster than
      real time may run further ahead one block at a time). Further is implausible: archived
      as received, counted, alarmed, never analysed and never moving its channel's state (a
      forged sequence number 2^63, a +100,000 jump, a t0 in 2100).
    * ``max_block_bytes``: the largest block payload taken (default 1 MiB: 262,144 float32
      samples, over four minutes of a 1 kHz channel per block); larger ones are refused before
      the archive, counted per mill and logged once.
    """

    queue_blocks: Annotated[int, Field(gt=0)] = 200_000
    checkpoint_seconds: Annotated[float, Field(gt=0)] = 60.0
    stale_after_s: Annotated[float, Field(gt=0)] = 10.0
    name: Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_-]{0,63}$")] | None = None
    partition: tuple[str, ...] = ()
    standby: bool = False
    recovery_jobs: Annotated[int, Field(ge=0, le=256)] = 0
    gateway_wait_s: Annotated[float, Field(ge=0, le=600)] = 10.0
    max_ahead_s: float = 60.0
    max_block_bytes: int = 2**20

    @field_validator("standby", mode="before")
    @classmethod
    def _standby(cls, value: object) -> object:
        if not isinstance(value, bool):  # ("yes", 1 or "true" in quotes would mean a guess)
            raise ValueError(f"{value!r} is not a boolean: write standby = true or standby = false")
        return value

    @field_validator("max_ahead_s")
    @classmethod
    def _ahead(cls, value: float) -> float:
        if not 1.0 <= value <= 86_400.0:  # (NaN fails too)
            raise ValueError(f"{value!r} s is out of range: give 1 to 86400 s (one day)")
        return value

    @field_validator("max_block_bytes")
    @classmethod
    def _block_bytes(cls, value: int) -> int:
        if not 4096 <= value <= 2**31:
            raise ValueError(
                f"{value!r} bytes is out of range: give 4096 (a 40-byte header and 1,014 "
                f"float32 samples) to {2**31} bytes"
            )
        return value

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


class ApiUser(_Strict):
    """One REST API user (``[[api.users]]``): ``name`` and a key from ``key_file`` (a secret
    file; trailing newline dropped) or the environment variable ``key_env`` — never in this
    file, never logged. ``role``: ``operator`` may act on alarms (acknowledge, confirm,
    comment, shelve, remove from service), ``viewer`` is refused them (403). The acting user
    recorded with every action is this name."""

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.@-]{0,63}$")]
    key_file: Path | None = None
    key_env: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")] | None = None
    role: Literal["operator", "viewer"] = "operator"

    @model_validator(mode="before")
    @classmethod
    def _no_key_here(cls, data: Any) -> Any:
        if isinstance(data, dict) and "key" in data:
            raise ValueError(
                "key: not in the settings file; put it in a secret file named by "
                "key_file, or in the environment variable named by key_env"
            )
        return data

    @model_validator(mode="after")
    def _one_source(self) -> ApiUser:
        if self.key_file is None and self.key_env is None:
            raise ValueError(f"user {self.name!r}: set key_file or key_env")
        return self

    def key(self) -> str | None:
        """The user's API key (None when its environment variable is unset)."""
        return read_secret(self.key_file, self.key_env, f"api.users.{self.name}")


class ApiSettings(_Strict):
    """The REST API; ``query_timeout_s``: how long the API waits for a worker's answer over
    zenoh (``millwatch api``) before it answers 504. ``api_key``: the shared key — acts on
    alarms as the ``by`` its caller names (default ``api``), and signs the actions the API sends
    the workers over zenoh (``millwatch api``; they check them with their own copy).
    ``users``: per-user keys (:class:`ApiUser`): the action is recorded as the key's user.
    ``max_shelve_s``: the longest timed shelve (default 8 h, one shift; at most 7 days),
    checked where the action is applied (the worker) and by ``millwatch api`` before it asks.
    ``max_body_bytes``: the largest request body (413 beyond, before it is read);
    ``report_renders``: reports built and rendered at once (one more: 503 with Retry-After)."""

    host: str = "127.0.0.1"
    port: Annotated[int, Field(ge=0, le=65535)] = 8080
    api_key: str | None = None
    users: tuple[ApiUser, ...] = ()
    max_shelve_s: Annotated[float, Field(gt=0, le=7 * 86400)] = DEFAULT_MAX_SHELVE_S
    query_timeout_s: Annotated[float, Field(gt=0, le=600)] = 10.0
    max_body_bytes: Annotated[int, Field(ge=1024, le=64 * 2**20)] = 64 * 1024
    report_renders: Annotated[int, Field(ge=1, le=64)] = 2

    @field_validator("users")
    @classmethod
    def _unique(cls, value: tuple[ApiUser, ...]) -> tuple[ApiUser, ...]:
        names = [u.name for u in value]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"user {twice[0]!r} is configured twice")
        return value


class MillSettings(_Strict):
    """Which mill configuration files this worker analyses."""

    files: tuple[Path, ...] = ()
    directory: Path | None = None


def read_secret(path: Path | None, env: str | None, field: str) -> str | None:
    """A secret from a file (trailing newline dropped) or else an environment variable; None
    when neither holds one; :class:`SettingsError` naming ``field`` for an unreadable file.
    The secret itself is never put in a message."""
    if path is not None:
        try:
            return path.read_text(encoding="utf-8").rstrip("\r\n")
        except OSError as exc:
            raise SettingsError(f"{field}: cannot read {path} ({exc.strerror or exc})") from exc
    return (os.environ.get(env) or None) if env else None


def no_password_field(data: Any, hint: str = "") -> Any:
    """``data`` unchanged; :class:`ValueError` when it holds a ``password`` (secrets live in a
    file or the environment, never in the settings file)."""
    if isinstance(data, dict) and "password" in data:
        raise ValueError(
            "password: not in the settings file; put it in a secret file named by "
            "password_file, or in the environment variable named by password_env " + hint
        )
    return data


class MailSettings(_Strict):
    """Mail of each monthly report (SMTP; :mod:`millwatch.reports.mail`): one mail per mill and
    month to every recipient, the PDF and HTML attached (``attach``).

    The password is never in this file: it is read when a mail is sent from ``password_file``
    (a secret file; trailing newline dropped) or else from the environment variable named by
    ``password_env``, and never logged. ``starttls`` (default on) upgrades the connection
    before logging in; ``ca_file`` trusts another CA than the system's (a site's own)."""

    host: Annotated[str, Field(min_length=1)]
    port: Annotated[int, Field(ge=1, le=65535)] = 587
    starttls: bool = True
    username: str | None = None
    password_file: Path | None = None
    password_env: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")] = (
        "MILLWATCH_SMTP_PASSWORD"
    )
    sender: Annotated[str, Field(pattern=r"^[^@\s]+@[^@\s]+$")]
    recipients: Annotated[
        tuple[Annotated[str, Field(pattern=r"^[^@\s]+@[^@\s]+$")], ...], Field(min_length=1)
    ]
    ca_file: Path | None = None
    timeout_s: Annotated[float, Field(gt=0, le=600)] = 30.0
    attach: tuple[str, ...] = ("pdf", "html")

    @model_validator(mode="before")
    @classmethod
    def _no_password_here(cls, data: Any) -> Any:
        return no_password_field(data, "(default MILLWATCH_SMTP_PASSWORD)")

    @model_validator(mode="after")
    def _no_clear_text_login(self) -> MailSettings:
        if self.username is not None and not self.starttls:
            raise ValueError(
                "username: logging in without starttls would send the password in clear text; "
                "set starttls = true (the default) or drop username"
            )
        return self

    @field_validator("attach")
    @classmethod
    def _formats(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        return parse_formats(value) if value else ()

    def password(self) -> str | None:
        """The SMTP password from ``password_file`` or ``password_env`` (None when neither
        holds one); :class:`SettingsError` for a secret file that cannot be read."""
        return read_secret(self.password_file, self.password_env, "reports.mail.password_file")


class ReportSettings(_Strict):
    """Monthly reports written after each local month end (:mod:`millwatch.reports.month_end`).

    * ``directory``: reports go to ``<directory>/<mill>/<YYYY-MM>.<ext>``; ``formats`` which.
    * ``delay_s``: how long after the local month end (each mill's ``time_zone``) its report is
      made, so late data (gateway caches, queue) is in (default 15 min).
    * ``catch_up_months``: at start and every ``check_every_s``, the finished months this far
      back that have data and no report yet are made (a service down at month end catches up).
    * ``attempts``, ``backoff_s``, ``backoff_max_s``: a failed render/write or mail is tried
      ``attempts`` times, waiting ``backoff_s`` doubled each time (at most ``backoff_max_s``);
      then the ``report_delivery`` alarm is raised, and the month is tried again after
      ``retry_failed_after_s``.
    * ``jobs``: processes that build and render reports, at low priority (0: one per core;
      reports of several mills are made in parallel, off the worker's real-time path).
    """

    enabled: bool = True
    directory: Path = Path("var/reports")
    formats: tuple[str, ...] = REPORT_FORMATS
    delay_s: Annotated[float, Field(ge=0, le=7 * 86_400)] = 900.0
    catch_up_months: Annotated[int, Field(ge=1, le=24)] = 3
    check_every_s: Annotated[float, Field(gt=0, le=86_400)] = 60.0
    attempts: Annotated[int, Field(ge=1, le=20)] = 4
    backoff_s: Annotated[float, Field(ge=0, le=3600)] = 30.0
    backoff_max_s: Annotated[float, Field(ge=0, le=86_400)] = 600.0
    retry_failed_after_s: Annotated[float, Field(gt=0, le=30 * 86_400)] = 3600.0
    jobs: Annotated[int, Field(ge=0, le=64)] = 0
    mail: MailSettings | None = None

    @field_validator("formats")
    @classmethod
    def _formats(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        return parse_formats(value)


SecurityPolicy = Literal["None", "Basic256Sha256_Sign", "Basic256Sha256_SignAndEncrypt"]
"""Security policies the OPC UA server can offer (``[opcua] security``)."""


class OpcUaUser(_Strict):
    """One OPC UA user: ``name`` and a password from ``password_file`` or the environment
    variable ``password_env`` (never in this file, never logged). ``role``: ``operator`` may
    acknowledge alarms, ``viewer`` only reads."""

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.@-]{0,63}$")]
    password_file: Path | None = None
    password_env: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")] | None = None
    role: Literal["operator", "viewer"] = "operator"

    @model_validator(mode="before")
    @classmethod
    def _no_password_here(cls, data: Any) -> Any:
        return no_password_field(data)

    @model_validator(mode="after")
    def _one_source(self) -> OpcUaUser:
        if self.password_file is None and self.password_env is None:
            raise ValueError(f"user {self.name!r}: set password_file or password_env")
        return self

    def password(self) -> str | None:
        """The password (None when its environment variable is unset)."""
        return read_secret(self.password_file, self.password_env, f"opcua.users.{self.name}")


class OpcUaSettings(_Strict):
    """The OPC UA server (:mod:`millwatch.opcua`), off by default.

    * ``endpoint``: ``opc.tcp://host:port/path``; loopback by default.
    * ``users``: user/password logins; ``user_certificates``: X.509 user certificates (DER or
      PEM files; the file's stem is the user name; operators).
    * ``anonymous``: let clients without credentials browse, read and subscribe (never write,
      never call methods).
    * ``security``: the policies offered (``None``, ``Basic256Sha256_Sign``,
      ``Basic256Sha256_SignAndEncrypt``); the server's self-signed certificate is made at first
      start in ``certificate_dir`` (default: ``opcua/`` beside the store).
    * ``trusted_clients_dir``: the trust list — client application certificates (or their
      CAs' certificates), DER or PEM files; a signing client whose certificate is not there is
      refused and its certificate saved in ``rejected/`` beside it (default: ``trusted/`` in
      ``certificate_dir``; :mod:`millwatch.opcua.trust`).
    * ``update_s``: how often values are read from the backend (≤ 1 s; default 0.25 s).
    * ``login_free_failures``, ``login_lockout_s``: after this many failed logins from one
      client host, every login from it is refused for ``login_lockout_s`` (default 1 s),
      doubled at each further failure, at most 300 s
      (:class:`millwatch.opcua.access.LoginThrottle`).
    """

    enabled: bool = False
    endpoint: Annotated[str, Field(pattern=r"^opc\.tcp://[^/:]+:[0-9]{1,5}(/.*)?$")] = (
        "opc.tcp://127.0.0.1:4840/millwatch"
    )
    users: tuple[OpcUaUser, ...] = ()
    user_certificates: tuple[Path, ...] = ()
    anonymous: bool = False
    security: tuple[SecurityPolicy, ...] = (
        "None",
        "Basic256Sha256_Sign",
        "Basic256Sha256_SignAndEncrypt",
    )
    certificate_dir: Path | None = None
    trusted_clients_dir: Path | None = None
    update_s: Annotated[float, Field(gt=0, le=1.0)] = 0.25
    login_free_failures: Annotated[int, Field(ge=1, le=100)] = 5
    login_lockout_s: Annotated[float, Field(gt=0, le=300)] = 1.0

    @field_validator("users")
    @classmethod
    def _unique(cls, value: tuple[OpcUaUser, ...]) -> tuple[OpcUaUser, ...]:
        names = [u.name for u in value]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"user {twice[0]!r} is configured twice")
        return value

    @field_validator("security")
    @classmethod
    def _some(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        if not value:
            raise ValueError("no security policy given (None, Basic256Sha256_Sign, "
                             "Basic256Sha256_SignAndEncrypt)")  # fmt: skip
        return tuple(dict.fromkeys(value))


class ServiceSettings(_Strict):
    zenoh: ZenohSettings = ZenohSettings()
    archive: ArchiveSettings = ArchiveSettings()
    store: StoreSettings = StoreSettings()
    worker: WorkerSettings = WorkerSettings()
    api: ApiSettings = ApiSettings()
    mills: MillSettings = MillSettings()
    reports: ReportSettings = ReportSettings()
    opcua: OpcUaSettings = OpcUaSettings()

    def resolved(self, base: Path) -> ServiceSettings:
        """The same settings with relative paths made relative to ``base``."""

        def at(p: Path) -> Path:
            return p if p.is_absolute() else (base / p).resolve()

        mills = MillSettings(
            files=tuple(at(p) for p in self.mills.files),
            directory=None if self.mills.directory is None else at(self.mills.directory),
        )
        mail = self.reports.mail
        if mail is not None:
            mail = mail.model_copy(
                update={
                    "password_file": None if mail.password_file is None else at(mail.password_file),
                    "ca_file": None if mail.ca_file is None else at(mail.ca_file),
                }
            )
        return self.model_copy(
            update={
                "archive": self.archive.model_copy(
                    update={"directory": at(self.archive.directory)}
                ),
                "store": StoreSettings(path=at(self.store.path)),
                "zenoh": self._resolved_zenoh(at),
                "mills": mills,
                "reports": self.reports.model_copy(
                    update={"directory": at(self.reports.directory), "mail": mail}
                ),
                "opcua": self._resolved_opcua(at),
                "api": self._resolved_api(at),
            }
        )

    def _resolved_zenoh(self, at: Any) -> ZenohSettings:
        tls = self.zenoh.tls
        if tls is None:
            return self.zenoh
        return self.zenoh.model_copy(
            update={"tls": tls.model_copy(update={"directory": at(tls.directory)})}
        )

    def _resolved_api(self, at: Any) -> ApiSettings:
        users = tuple(
            u.model_copy(update={"key_file": at(u.key_file)}) if u.key_file is not None else u
            for u in self.api.users
        )
        return self.api.model_copy(update={"users": users})

    def _resolved_opcua(self, at: Any) -> OpcUaSettings:
        o = self.opcua
        users = tuple(
            u.model_copy(update={"password_file": at(u.password_file)})
            if u.password_file is not None else u
            for u in o.users
        )  # fmt: skip
        return o.model_copy(update={
            "users": users,
            "user_certificates": tuple(at(p) for p in o.user_certificates),
            "certificate_dir": None if o.certificate_dir is None else at(o.certificate_dir),
            "trusted_clients_dir": None if o.trusted_clients_dir is None
            else at(o.trusted_clients_dir),
        })  # fmt: skip

    def load_mills(self, source: str | Path = "") -> dict[str, MillConfig]:
        """The configured mills by id; raises naming the file and field of a bad one (with
        ``source``, the settings file, when none is configured)."""
        mills = load_mill_configs(self.mills.directory) if self.mills.directory else {}
        for path in self.mills.files:
            config = load_mill_config(path)
            if config.id in mills:
                raise SettingsError(f"{path}: mill id {config.id!r} is configured twice")
            mills[config.id] = config
        if not mills:
            where = f"{source}: " if source else ""
            raise SettingsError(f"{where}mills: no mill configured (set mills.files or "
                                "mills.directory)")  # fmt: skip
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


def check_writable(settings: ServiceSettings, source: str | Path) -> None:
    """The places a worker writes — ``archive.directory``, the directory of ``store.path``,
    ``reports.directory`` (when reports are on) — exist or can be made, and are writable;
    else :class:`SettingsError` naming ``source`` (the settings file), the field, its value and
    what is wrong. (Run before a worker starts, so the error comes before its banner.)"""
    places = [("archive.directory", settings.archive.directory, settings.archive.directory),
              ("store.path", settings.store.path, settings.store.path.parent)]  # fmt: skip
    if settings.reports.enabled:
        places.append(("reports.directory", settings.reports.directory, settings.reports.directory))
    for field, value, directory in places:
        problem = _not_writable(directory)
        if problem is None and field == "store.path" and value.is_dir():
            problem = "it is a directory; give the store's file name, e.g. millwatch.db"
        if problem is not None:
            raise SettingsError(f"{source}: {field} = '{value}': {problem}")


def _not_writable(directory: Path) -> str | None:
    """Why this process cannot write in ``directory`` (made if missing), or None."""
    for d in (directory, *directory.parents):
        if d.exists() and not d.is_dir():
            return f"{d} is a file, not a directory"
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return f"cannot create the directory {directory} ({exc.strerror or exc})"
    if not os.access(directory, os.W_OK | os.X_OK):
        return f"the directory {directory} is not writable by this user"
    return None
