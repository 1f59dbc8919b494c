"""``millwatch demo``: the whole product on one machine, with simulated mills.

Starts, on loopback only: the worker (zenoh subscriber, MCAP archive, analysis, SQLite store,
checkpoints), one simulated sensor gateway per mill publishing a month-long scene of starts,
barring, steady running and telemetry spikes (Diering 2011 §6) at ``--speed`` × real time, and the
REST API. It prints where to look and runs until Ctrl-C (or ``--minutes``). The data is
SIMULATED and says so everywhere it is shown.

**Plant time.** Sample time advances ``--speed`` times faster than the wall clock, so were the
scene to start *now*, its samples would soon lie hours in the future: channel lags negative,
alarms raised "later today", an acknowledgement (wall-clock time) listed before the raise it
answers. The demo therefore replays the recent past: each scene starts early enough
(:func:`replay_start_ns`) that it meets the wall clock when the run ends (``--minutes``, or the
scene's end), and no block is published before its samples' time has passed
(``never_ahead``). Lags read as what they are — how old the data replayed now are, falling to 0
— and every alarm time lies in the past, before its acknowledgement. The start line prints the
plant-time span.
"""

from __future__ import annotations

import argparse
import logging
import secrets
import sys
import tempfile
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

import uvicorn

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.app import create_app
from millwatch.api.local_backend import LocalBackend
from millwatch.cli.args import positive_float, positive_int
from millwatch.cli.serve import AnnouncingServer, check_api_port, run_until_signal
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.opcua.launch import start_opcua, trust_directories
from millwatch.settings import ServiceSettings
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime

__all__ = ["add_parser"]

log = logging.getLogger(__name__)

MILLS_DIR = Path(__file__).resolve().parents[2] / "deploy" / "mills"


OPCUA_USER = "operator"
OPCUA_SECRET = "opcua-operator.secret"


def demo_opcua(directory: Path, port: int) -> dict[str, object]:
    """The demo's ``[opcua]``: on, loopback, user ``operator`` with a new random password in
    ``directory/opcua-operator.secret`` (owner-only), anonymous clients read-only."""
    secret = directory / OPCUA_SECRET
    if not secret.exists():
        secret.touch(mode=0o600)
        secret.write_text(secrets.token_urlsafe(12) + "\n", encoding="utf-8")
    return {"enabled": True, "endpoint": f"opc.tcp://127.0.0.1:{port}/millwatch",
            "users": [{"name": OPCUA_USER, "password_file": str(secret)}],
            "anonymous": True}  # fmt: skip


def demo_settings(
    directory: Path, zenoh_port: int, api_port: int, mills: int, opcua_port: int = 4840
) -> ServiceSettings:
    files = sorted(MILLS_DIR.glob("*.toml"))[:mills]
    return ServiceSettings.model_validate({
        "zenoh": {"listen": [tcp_endpoint(zenoh_port)]},
        "archive": {"directory": str(directory / "archive")},
        "store": {"path": str(directory / "millwatch.db")},
        "reports": {"directory": str(directory / "reports")},
        "worker": {"checkpoint_seconds": 30.0, "stale_after_s": 10.0},
        "api": {"host": "127.0.0.1", "port": api_port},
        "mills": {"files": [str(f) for f in files]},
        "opcua": demo_opcua(directory, opcua_port),
    })  # fmt: skip


def simulated_mills(mills: dict[str, MillConfig]) -> dict[str, MillConfig]:
    """The demo's mills marked ``simulated`` whatever their files say: the demo's data come
    from the simulator, and every answer, report and alarm must say so."""
    return {m: c.model_copy(update={"simulated": True}) for m, c in mills.items()}


def replay_start_ns(now_ns: int, speed: float, scene_s: float, minutes: float | None) -> int:
    """The scenes' first sample time (ns since the epoch) for a demo started at ``now_ns``:
    ``(speed − 1) × run`` seconds back, ``run`` being the run's wall-clock length
    (``minutes``, at most the scene's ``scene_s`` seconds played at ``speed``), so that sample
    time reaches the wall clock when the run ends and is behind it until then (never ahead).
    At ``speed`` ≤ 1 the scene starts now."""
    run_s = scene_s / speed if minutes is None else min(minutes * 60.0, scene_s / speed)
    behind_s = max(0.0, speed - 1.0) * run_s
    return now_ns - round(behind_s * 1e9)


class Gateways:
    """One simulated gateway thread per mill, each with its own zenoh session, each replaying
    its scene from ``t0_ns`` and never ahead of the wall clock (module docstring)."""

    def __init__(
        self, runtime: ServiceRuntime, endpoint: str, speed: float, scene: str, t0_ns: int
    ) -> None:
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._run, args=(config, endpoint, speed, scene, seed, t0_ns),
                             name=f"gateway-{mill_id}", daemon=True)
            for seed, (mill_id, config) in enumerate(runtime.mills.items())
        ]  # fmt: skip

    def start(self) -> None:
        for t in self._threads:
            t.start()

    def _run(
        self, config: MillConfig, endpoint: str, speed: float, name: str, seed: int, t0_ns: int
    ) -> None:
        scene = starting_now(get_scene(name, config, seed=seed), t0_ns)
        with open_session(build_config(connect=[endpoint])) as session:
            ScenePublisher(session, scene, speed=speed, wait_subscribers_s=5.0,
                           never_ahead=True).run(self._stop)  # fmt: skip

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=10)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run everything on loopback with simulated mills: worker, gateways, REST API",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch demo --speed 40                # 40 minutes of plant time a minute\n"
            "  millwatch demo --mills 1 --speed 100     # one mill, faster\n\n"
            "One worker core keeps up with about 120 mill-equivalents (mills x speed)."
        ),
    )
    p.add_argument(
        "--mills",
        type=positive_int,
        default=3,
        help="simulated mills from deploy/mills (1–3, default 3)",
    )
    p.add_argument(
        "--speed",
        type=positive_float,
        default=20.0,
        help="× real time of the simulated plant (default 20)",
    )
    p.add_argument(
        "--scene", default="month", help="catalogue scene each mill plays (default: month)"
    )
    p.add_argument("--port", type=int, default=8080, help="API port on 127.0.0.1 (default 8080)")
    p.add_argument("--opcua-port", type=int, default=4840,
                   help="OPC UA port on 127.0.0.1 (default 4840)")  # fmt: skip
    p.add_argument(
        "--dir",
        type=Path,
        help="where the archive and store go (default: a new temporary directory)",
    )
    p.add_argument(
        "--minutes",
        type=positive_float,
        help="stop by itself after this many minutes (default: run until Ctrl-C)",
    )
    p.set_defaults(handler=_main)


#: Mill-equivalents (mills × speed) one worker core keeps up with, measured with
#: tests/bench/bench_pipeline.py (about 150 running mills per core); kept with some margin.
KEEPS_UP_WITH = 120


def _main(args: argparse.Namespace) -> int:
    mills = min(args.mills, 3)
    if mills * args.speed > KEEPS_UP_WITH:
        log.warning(
            "%d mills at %g× real time is %g mill-equivalents; one worker keeps up with about "
            "%d — expect a growing queue, dropped blocks and stale-channel alarms",
            mills, args.speed, mills * args.speed, KEEPS_UP_WITH,
        )  # fmt: skip
    check_api_port("127.0.0.1", args.port, "--port")
    directory = args.dir or Path(tempfile.mkdtemp(prefix="millwatch-demo-"))
    zenoh_port = free_loopback_port()
    directory.mkdir(parents=True, exist_ok=True)
    settings = demo_settings(directory, zenoh_port, args.port, mills, args.opcua_port)
    settings = with_demo_api_key(settings)
    runtime = ServiceRuntime(settings, simulated_mills(settings.load_mills()), MillJob)
    runtime.start()
    backend = LocalBackend(runtime)
    scene_s = _scene_seconds(args.scene, next(iter(runtime.mills.values())))
    args.t0_ns = replay_start_ns(time.time_ns(), args.speed, scene_s, args.minutes)
    gateways = Gateways(runtime, tcp_endpoint(zenoh_port), args.speed, args.scene, args.t0_ns)
    config = uvicorn.Config(create_app(backend), host="127.0.0.1", port=args.port,
                            log_level="warning")  # fmt: skip
    ready = f"millwatch demo: ready; {len(runtime.mills)} simulated mill(s), http://127.0.0.1:{args.port}"
    server = AnnouncingServer(config, ready)
    timer = _stop_after(server, args.minutes)
    opcua = None
    try:
        opcua = start_opcua(backend, settings)
        gateways.start()
        _announce(settings, runtime, directory, args)
        run_until_signal(server)
    finally:
        if timer is not None:
            timer.cancel()
        gateways.stop()
        if opcua is not None:
            opcua.stop()
        runtime.stop()
    sys.stdout.write(f"millwatch demo stopped; archive and store kept in {directory}\n")
    return 0


def _scene_seconds(name: str, config: MillConfig) -> float:
    """The catalogue scene's length, s of sample time (the same for every mill)."""
    return float(get_scene(name, config, seed=0).spec.duration_s)


def plant_time_line(t0_ns: int, speed: float) -> str:
    """The start line's plant-time span: from where the replay starts to when it meets the
    wall clock (UTC, whole seconds)."""
    start = datetime.fromtimestamp(t0_ns / 1e9, UTC).replace(microsecond=0)
    return (f"  plant time replays from {start.isoformat()} at {speed:g}× until it meets the "
            "wall clock (never ahead of it: lags ≥ 0, alarm times in the past)\n")  # fmt: skip


def _stop_after(server: uvicorn.Server, minutes: float | None) -> threading.Timer | None:
    if minutes is None:
        return None
    timer = threading.Timer(minutes * 60.0, lambda: setattr(server, "should_exit", True))
    timer.daemon = True
    timer.start()
    return timer


def _announce(settings: ServiceSettings, runtime: ServiceRuntime, directory: Path,
              args: argparse.Namespace) -> None:  # fmt: skip
    base = f"http://127.0.0.1:{args.port}"
    mills = ", ".join(runtime.mills)
    sys.stdout.write(
        "millwatch demo — SIMULATED mills, nothing here comes from a plant\n"
        f"  mills      {mills} (scene '{args.scene}' at {args.speed:g}× real time)\n"
        f"{plant_time_line(args.t0_ns, args.speed)}"
        f"  API        {base}/mills   {base}/mills/<id>   {base}/ready   {base}/docs\n"
        f"  archive    {settings.archive.directory}\n"
        f"  store      {settings.store.path}\n"
        f"  reports    {settings.reports.directory} (each mill's month, after its local end)\n"
        f"{_opcua_lines(settings)}"
        f"  then try   millwatch analyze {settings.archive.directory} "
        f"--mill deploy/mills/sag-5200-lrs.toml\n"
        "Ctrl-C stops (final checkpoint, archive files finished).\n"
    )
    sys.stdout.write(ack_help(base, settings.api.api_key))
    sys.stdout.flush()


def with_demo_api_key(settings: ServiceSettings) -> ServiceSettings:
    """``settings`` with an API key made for this run (the demo prints it), so acknowledging
    an alarm — what an operator does — can be tried."""
    api = settings.api.model_copy(update={"api_key": secrets.token_urlsafe(16)})
    return settings.model_copy(update={"api": api})


def ack_help(base: str, api_key: str | None) -> str:
    """The lines that show an operator how to list open alarms and acknowledge one."""
    return (
        f"  API key    {api_key}   (header X-API-Key; made for this run)\n"
        f"  alarms     curl --noproxy '*' '{base}/alarms?state=open'\n"
        f"  ack        curl --noproxy '*' -X POST -H 'X-API-Key: {api_key}' "
        f"-H 'Content-Type: application/json' -d '{{\"by\": \"operator\"}}' "
        f"'{base}/alarms/<alarm_id>/ack'\n"
    )


def _opcua_lines(settings: ServiceSettings) -> str:
    """Where the OPC UA server listens and how to log in (the demo's own password)."""
    o = settings.opcua
    user = o.users[0]
    trusted, rejected = trust_directories(settings)
    return (
        f"  OPC UA     {o.endpoint} (security None or Basic256Sha256; anonymous: read-only)\n"
        f"             user {user.name!r}, password {user.password()!r} (in {user.password_file}); "
        "act on alarms with the conditions' Part 9 methods\n"
        f"             a signing client's certificate is refused until moved from {rejected} "
        f"to {trusted}\n"
    )
