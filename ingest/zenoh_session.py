"""Zenoh hygiene: explicit configs, always-closed sessions, BLOCK publishers for blocks.

Rules this module encodes (zenoh 1.x Python API):

- **Explicit topology.** :func:`build_config` sets listen and connect endpoints
  explicitly (e.g. ``tcp/127.0.0.1:<port>``) and turns multicast scouting OFF. With
  no listen endpoint given, the session listens nowhere: zenoh's peer default
  (``tcp/[::]:0``, every interface) is replaced by an empty list. Gossip scouting is
  off unless asked for (it only spreads endpoints we already configured).
- **Start without peers.** A ``connect`` endpoint that is not up yet is retried by zenoh
  itself (``connect/retry``: first after 250 ms, doubling to at most 4 s), never fatal
  (``connect/exit_on_failure`` false, ``connect/timeout_ms`` -1). In *peer* mode
  ``zenoh.open`` returns at once (after the scouting delay, 0.5 s) and zenoh connects in the
  background. In *client* mode zenoh 1.10 cannot do that: a client connects to its router
  inside ``zenoh.open`` (``connect_peers_single_link`` has no background connector; with
  timeout 0 it raises ``Unable to connect``), so :func:`open_session` waits there, retrying,
  until a router answers — it no longer dies. :func:`open_session` logs once which endpoints
  are not up yet; :func:`connected_peers` says how many routers and peers are connected now.
- **Sessions are always closed.** :func:`open_session` is a context manager; an
  unclosed session with a callback subscriber keeps zenoh threads alive and hangs
  interpreter exit.
- **Archived or replayed data is never dropped silently.** Block publishers use
  ``CongestionControl.BLOCK`` and reliable transport: zenoh's default ``DROP`` lost
  63 % of messages at high rate in our tests. ``DROP`` remains available for
  best-effort live views (``archived=False``).
- **Payloads are bytes** (the :mod:`millwatch.ingest.wire` block), encoding
  ``application/octet-stream;millwatch.block.v1``.
- Subscriber callbacks run on zenoh threads: they must only enqueue. The wrapper of
  :func:`declare_block_subscriber` hands ``(key, payload_bytes)`` to the callback and
  logs (never raises) its exceptions.
"""

from __future__ import annotations

import contextlib
import ipaddress
import json
import logging
import re
import socket
import time
from collections.abc import Callable, Iterator, Sequence

import zenoh

from millwatch.ingest.wire import FORMAT_VERSION
from millwatch.ingest.zenoh_tls import TlsFiles, tls_settings

log = logging.getLogger(__name__)

LOOPBACK = "127.0.0.1"
BLOCK_ENCODING = "application/octet-stream"
BLOCK_SCHEMA = "millwatch.block.v" + str(FORMAT_VERSION)
_MODES = ("peer", "client", "router")
#: zenoh's connect retry (``connect/retry``): a peer started a moment after us is found within
#: 250 ms; one that stays down costs a connection attempt every 4 s at most.
CONNECT_RETRY = {"period_init_ms": 250, "period_max_ms": 4000, "period_increase_factor": 2}


class ZenohConfigError(ValueError):
    """An endpoint or option of the zenoh config is invalid."""


class ZenohListenError(OSError):
    """A listen endpoint cannot be bound (e.g. its port is in use); the message names the
    endpoint, the reason and what to do."""


#: zenoh's words for a listener it could not bind: the endpoint, then the OS's reason.
_LISTENER = re.compile(r"listener bound to (\S+?):? \[[^:]*:\d+: ([^(\]]+)")


def _open(config: zenoh.Config) -> zenoh.Session:
    """``zenoh.open``, a listen endpoint that cannot be bound turned into a
    :class:`ZenohListenError` naming it (zenoh's own text is three lines of Rust paths)."""
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        found = _LISTENER.search(str(exc))
        if found is None:
            raise
        endpoint, reason = found[1], found[2].strip()
        raise ZenohListenError(
            f"cannot listen on {endpoint}: {reason}. Another millwatch or zenoh process may "
            "be using it: stop that one, or listen on another port (--listen, or [zenoh] "
            "listen in the settings)"
        ) from None


def free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (for tests)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOOPBACK, 0))
        return int(sock.getsockname()[1])


def tcp_endpoint(port: int, host: str = LOOPBACK) -> str:
    """``tcp/<host>:<port>`` (default host 127.0.0.1)."""
    if not 0 < port < 65536:
        raise ZenohConfigError(f"port {port} is out of range 1..65535")
    return "tcp/" + host + ":" + str(port)


def _is_loopback(endpoint: str) -> bool:
    _, _, address = endpoint.partition("/")
    host = address.split("#")[0].split("?")[0].rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _check_port(kind: str, endpoint: str) -> None:
    """A network endpoint (``tcp/host:port``, udp, tls, quic, ws) ends with a port 1..65535."""
    proto, _, address = endpoint.partition("/")
    if proto not in ("tcp", "udp", "tls", "quic", "ws"):
        return
    port = address.split("#")[0].split("?")[0].rpartition(":")[2]
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ZenohConfigError(f"{kind} endpoint {endpoint!r}: the port must be a number "
                               f"1..65535, got {port!r}")  # fmt: skip


def _check_endpoints(kind: str, endpoints: Sequence[str], loopback_only: bool) -> list[str]:
    checked = []
    for endpoint in endpoints:
        if "/" not in endpoint:
            raise ZenohConfigError(f"{kind} endpoint {endpoint!r}: expected '<proto>/<address>'")
        if loopback_only and not _is_loopback(endpoint):
            raise ZenohConfigError(f"{kind} endpoint {endpoint!r} is not a loopback address")
        _check_port(kind, endpoint)
        checked.append(endpoint)
    return checked


def build_config(
    *,
    mode: str = "peer",
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    gossip: bool = False,
    loopback_only: bool = False,
    tls: TlsFiles | None = None,
) -> zenoh.Config:
    """An explicit zenoh config: given endpoints only, multicast scouting OFF.

    ``listen``/``connect`` are zenoh endpoints such as ``tcp/127.0.0.1:7447``;
    ``loopback_only`` rejects any non-loopback endpoint (tests, single-host setups).
    ``tls``: mutual TLS with these files (:mod:`millwatch.ingest.zenoh_tls`; endpoints ``tls/…``);
    :class:`ZenohConfigError` naming a file that cannot be read.
    """
    if mode not in _MODES:
        raise ZenohConfigError(f"mode {mode!r}: expected one of {', '.join(_MODES)}")
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", json.dumps(gossip))
    config.insert_json5(
        "listen/endpoints", json.dumps(_check_endpoints("listen", listen, loopback_only))
    )
    config.insert_json5(
        "connect/endpoints", json.dumps(_check_endpoints("connect", connect, loopback_only))
    )
    config.insert_json5("connect/timeout_ms", "-1")  # retry until connected ...
    config.insert_json5("connect/exit_on_failure", "false")  # ... in the background (peer)
    config.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    if tls is not None:
        for what, path in (("CA", tls.ca), ("certificate", tls.certificate),
                           ("private key", tls.private_key)):  # fmt: skip
            if not path.is_file():
                raise ZenohConfigError(f"zenoh TLS {what} {path} does not exist (make it with "
                                       "'millwatch zenoh-certs')")  # fmt: skip
        config.insert_json5("transport/link/tls", json.dumps(tls_settings(tls)))
    return config


@contextlib.contextmanager
def open_session(config: zenoh.Config) -> Iterator[zenoh.Session]:
    """Open a session and close it on exit, whatever happens inside.

    Connect endpoints that are down do not fail the open (see the module docstring): a peer
    opens at once and connects when they come up; a client waits, retrying, for its router.
    Either way one line is logged naming the endpoints not up yet.
    """
    session = open_retrying(config)
    try:
        yield session
    finally:
        session.close()


def open_retrying(config: zenoh.Config) -> zenoh.Session:
    """Open a session whose connect endpoints may be down (see :func:`open_session`, which
    also closes it); the caller closes it."""
    endpoints = json.loads(config.get_json("connect/endpoints")) or []
    if not endpoints:
        return _open(config)
    if json.loads(config.get_json("mode")) != "client":
        session = _open(config)
        if connected_peers(session) == 0:
            log.warning(
                "zenoh: none of %s is up yet; connecting in the background (retry every <= %d ms)",
                endpoints,
                CONNECT_RETRY["period_max_ms"],
            )
        return session
    config.insert_json5("connect/timeout_ms", "0")  # one attempt first, to log a wait once
    try:
        return _open(config)
    except zenoh.ZError:
        log.warning(
            "zenoh client: no router at %s yet; waiting for one (retry every <= %d ms)",
            endpoints,
            CONNECT_RETRY["period_max_ms"],
        )
    finally:
        config.insert_json5("connect/timeout_ms", "-1")
    return _open(config)


def try_open(config: zenoh.Config) -> zenoh.Session | None:
    """One attempt: a session, or None when none of the connect endpoints answers (a client
    with no router up); the caller closes the session."""
    config.insert_json5("connect/timeout_ms", "0")
    try:
        return _open(config)
    except zenoh.ZError:
        return None
    finally:
        config.insert_json5("connect/timeout_ms", "-1")


def connected_peers(session: zenoh.Session) -> int:
    """Routers plus peers this session is connected to right now (0: alone; for ``/ready``)."""
    info = session.info
    return len(list(info.routers_zid())) + len(list(info.peers_zid()))


def block_encoding() -> zenoh.Encoding:
    """Zenoh encoding of wire blocks."""
    return zenoh.Encoding(BLOCK_ENCODING).with_schema(BLOCK_SCHEMA)


def declare_block_publisher(
    session: zenoh.Session, key: str, *, archived: bool = True
) -> zenoh.Publisher:
    """Publisher for wire blocks on ``key`` (build it with :mod:`millwatch.ingest.keys`).

    ``archived=True`` (live gateways, replay): congestion control BLOCK, reliable —
    a slow subscriber slows the publisher instead of losing blocks.
    ``archived=False``: DROP, for best-effort views that must never stall.
    """
    congestion = zenoh.CongestionControl.BLOCK if archived else zenoh.CongestionControl.DROP
    return session.declare_publisher(
        key,
        encoding=block_encoding(),
        congestion_control=congestion,
        reliability=zenoh.Reliability.RELIABLE,
    )


def declare_block_subscriber(
    session: zenoh.Session, pattern: str, on_block: Callable[[str, bytes], None]
) -> zenoh.Subscriber:
    """Subscribe to ``pattern``; ``on_block(key, payload)`` runs on a zenoh thread.

    ``on_block`` must only enqueue. Its exceptions are logged, never propagated.
    Keep the returned subscriber referenced (or use it as a context manager): a
    dropped subscriber is undeclared and silently stops delivering.
    """

    def _callback(sample: zenoh.Sample) -> None:
        try:
            on_block(str(sample.key_expr), sample.payload.to_bytes())
        except Exception:
            log.exception("block callback failed for %s", sample.key_expr)

    return session.declare_subscriber(pattern, _callback)


def wait_for_subscribers(publisher: zenoh.Publisher, timeout_s: float = 5.0) -> bool:
    """Poll (every 10 ms, at most ``timeout_s`` s) until a subscriber matches.

    Note: zenoh 1.10's ``Publisher.matching_status`` returns a ``MatchingStatus``
    object (always truthy) despite its ``bool`` type stub; :func:`has_subscribers`
    reads its ``matching`` field. Where every message counts (tests, replay start), a
    probe/ack handshake is the end-to-end proof of readiness.
    """
    deadline = time.monotonic() + timeout_s
    for _ in range(max(1, int(timeout_s / 0.01)) + 1):
        if has_subscribers(publisher):
            return True
        if time.monotonic() >= deadline:
            break
        time.sleep(0.01)
    return has_subscribers(publisher)


def has_subscribers(publisher: zenoh.Publisher) -> bool:
    """Whether any subscriber currently matches ``publisher``'s key expression."""
    status = publisher.matching_status
    return bool(getattr(status, "matching", status))
