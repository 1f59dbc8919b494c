"""``millwatch simulate``: a simulated mill with ground truth, written to MCAP or published live.

A scene is a mill configuration plus a timeline of operating events (Diering 2011 §6.1 Figure 20:
switch-on, acceleration, short-circuit peak, steady oscillations, switch-off, rocking, barring,
failed starts, trips, telemetry spikes and dropouts). Catalogue scenes are named; a scene TOML
file can define its own timeline. The output is exactly what a plant gateway would send: wire
blocks (see README "Wire format") on the channel keys of the mill configuration.

Offline (``--out``) runs as fast as the machine allows with a progress bar; ``--out x.mcap``
writes one file, ``--out DIR`` hourly rotated files named after the mill. ``--truth`` writes the
ground truth (event times, peaks, rise times, harmonic lines, injected faults) as JSON.

Live (``--publish``) re-times the scene to start now and publishes each block on the mill's live
keys when it is complete, at ``--speed`` × real time, like a plant gateway. By default it listens
on ``tcp/127.0.0.1:7447`` (loopback only, multicast scouting off), where ``millwatch serve`` with
default settings connects; ``--connect`` a router instead in a plant-like setup (a router that is
not up yet is retried in the background; publishing starts regardless).

Like a plant gateway it keeps the last ``--retention`` of every channel (default 10m, sample
time) in zenoh's advanced-publisher cache, from which a restarted worker recovers what it missed
(README "Wire format").

``--anchor-ns T`` resumes a scene as a restarted gateway would: T is the wall time (ns since the
Unix epoch, UTC) at which the scene's first sample is/was due (default: now). Blocks that fell due
before this process started are not published — they are lost, as for a DAQ that was off — and
the next block keeps its scene sequence number and timestamps. Kill a gateway and restart it with
the same --anchor-ns and --seed: sequence numbers continue, and the lost span is exactly the
blocks that fell due while it was down. The number skipped is printed at start.

``--spool DIR`` keeps every block in a spool on disk before publishing it and answers the
worker's recovery queries from it (README "Wire format"), for ``--spool-hours`` and at most
``--spool-max-mb``. The spool also remembers the scene's anchor: restarted with the same
``--spool`` (and the same scene, mill, seed, duration and block size), the gateway resumes the
scene where its wall clock is now, without ``--anchor-ns`` (a finished scene stays finished:
a new run needs a new spool directory). What fell due while it was down is known from the scene
clock — the blocks due between its last spooled block and now — and is not published (a DAQ
that was off has nothing of it); every block it published before it was killed is in the
spool, and its sequence numbers continue from the spool's.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import cast

from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.cli.args import (
    add_tls_arguments,
    duration_seconds,
    positive_float,
    positive_int,
    tls_files,
    utc_time_ns,
)
from millwatch.cli.edge.spool import add_spool_arguments, open_spool, spool_summary
from millwatch.ingest import wire
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.gateway import DEFAULT_RETENTION_S
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene, list_scenes, load_scene_file
from millwatch.ingest.sim.spec import SceneSpec
from millwatch.ingest.spool.query import SpoolServer
from millwatch.ingest.spool.store import Spool, SpoolError
from millwatch.ingest.zenoh_session import build_config, open_session
from millwatch.ingest.zenoh_tls import gateway_name

__all__ = ["add_parser", "build_scene", "simulate_to_archive"]

log = logging.getLogger(__name__)

DEFAULT_MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
_NO_ROTATION_S = 1e12
_NO_ROTATION_BYTES = 2**62


def build_scene(
    name_or_file: str, mill: Path | None, *, seed: int, duration_s: float | None
) -> Scene:
    """A catalogue scene by name, or a scene TOML file; ``duration_s`` overrides its length."""
    config = load_mill_config(mill) if mill is not None else None
    if name_or_file.endswith(".toml") or Path(name_or_file).is_file():
        scene = load_scene_file(name_or_file, config)
    else:
        if name_or_file not in list_scenes():
            known = ", ".join(list_scenes())
            raise ValueError(
                f"--scene {name_or_file!r}: no such scene file or catalogue scene (known: {known})"
            )
        scene = get_scene(name_or_file, config or load_mill_config(DEFAULT_MILL), seed=seed)
    if duration_s is None:
        return scene
    spec = SceneSpec.model_validate({**scene.spec.model_dump(), "duration_s": duration_s})
    return Scene(scene.config, spec)


def simulate_to_archive(
    scene: Scene,
    out: Path,
    *,
    block_samples: int = 100,
    dtype: wire.DType = wire.DType.FLOAT64,
    progress: bool = False,
) -> list[Path]:
    """Write every block of ``scene`` to MCAP; returns the files written."""
    single = out.suffix.lower() == ".mcap"
    directory = out.parent if single else out
    prefix = f"simulate-{os.getpid()}" if single else scene.config.id
    with ArchiveWriter(
        directory,
        prefix,
        rotate_seconds=_NO_ROTATION_S if single else 3600.0,
        rotate_bytes=_NO_ROTATION_BYTES if single else 256 * 2**20,
        max_latency_s=None,
    ) as writer:
        for block in _with_progress(
            scene, scene_blocks(scene, block_samples=block_samples, dtype=dtype), progress
        ):
            writer.write(block.key, block.payload, block.t_end_ns)
    files = list(writer.files_written)
    if single and files:
        files[0].replace(out)
        files = [out]
    return files


def _with_progress(
    scene: Scene, blocks: Iterator[SceneBlock], enabled: bool
) -> Iterator[SceneBlock]:
    n_channels = len(scene.config.channels)
    with tqdm(
        total=scene.n_samples,
        unit="sample",
        unit_scale=True,
        disable=not enabled,
        desc=f"simulate {scene.spec.name}",
        file=sys.stderr,
    ) as bar:
        for seen, block in enumerate(blocks, start=1):
            yield block
            if seen % n_channels == 0:
                bar.update(block.n_samples)


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate a mill (scene) to an MCAP file with ground truth",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            f"catalogue scenes: {', '.join(list_scenes())}\n\n"
            "examples:\n"
            "  millwatch simulate --scene start-lrs --out start.mcap --truth start.json\n"
            "  millwatch simulate --scene month --duration 2d --out archive/ --dtype float32\n"
            "  millwatch simulate --scene steady --mill deploy/mills/ball-dual-lrs.toml "
            "--duration 10m --out steady.mcap\n"
            "  millwatch simulate --scene start-lrs --publish --speed 10 --retention 30m\n\n"
            "a gateway killed and restarted mid-scene (the second run skips what fell due while\n"
            "it was down and continues the sequence numbers):\n"
            "  T=$(date +%s%N)\n"
            "  millwatch simulate --scene month --seed 3 --publish --anchor-ns $T   # Ctrl-C\n"
            "  millwatch simulate --scene month --seed 3 --publish --anchor-ns $T\n\n"
            "the same with a spool on disk (the anchor is kept in the spool):\n"
            "  millwatch simulate --scene month --seed 3 --publish --spool /var/spool/mw   # kill\n"
            "  millwatch simulate --scene month --seed 3 --publish --spool /var/spool/mw"
        ),
    )
    p.add_argument("--scene", required=True, help="catalogue scene name or scene .toml file")
    p.add_argument(
        "--mill",
        type=Path,
        help=f"mill configuration .toml (default: deploy/mills/{DEFAULT_MILL.name}; "
        "a scene file may name its own)",
    )
    p.add_argument(
        "--duration",
        type=duration_seconds,
        help="length, e.g. 90s, 10m, 2h, 30d (default: the scene's own)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed: same seed, same signals")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--out", type=Path, help="FILE.mcap (one file) or a directory (hourly files)"
    )
    where.add_argument(
        "--publish", action="store_true", help="publish live to zenoh instead (paced by --speed)"
    )
    p.add_argument("--truth", type=Path, help="write the ground truth as JSON here")
    p.add_argument(
        "--block-size",
        type=positive_int,
        default=100,
        help="samples per wire block (default 100 = 0.1 s at 1 kHz)",
    )
    p.add_argument(
        "--dtype",
        choices=["float32", "float64"],
        default="float64",
        help="sample type on the wire (float64 keeps the simulator's values exactly)",
    )
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    live = p.add_argument_group("live publishing (--publish)")
    live.add_argument(
        "--speed",
        type=positive_float,
        default=1.0,
        help="× real time (default 1; 60 shows an hour a minute)",
    )
    live.add_argument(
        "--listen",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="zenoh endpoint to listen on (default tcp/127.0.0.1:7447)",
    )
    live.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="zenoh endpoint to connect to (e.g. a router)",
    )
    add_tls_arguments(live, "the certificate's name in --tls-dir (default: "
                      "gateway.<site>.<mill> of the mill simulated)")  # fmt: skip
    live.add_argument(
        "--retention",
        type=duration_seconds,
        default=DEFAULT_RETENTION_S,
        help="sample time kept per channel for recovery by restarted workers, e.g. 90s, 10m, "
        "1h (default 10m; measured 0.43 MB per channel-minute at 1 kHz, 100-sample float32 "
        "blocks: 4.3 MB per channel for 10m)",
    )
    live.add_argument(
        "--anchor-ns",
        type=utc_time_ns,
        metavar="T",
        help="wall time (ns since the epoch, UTC, or ISO-8601 with zone) at which the scene's "
        "first sample is/was due (default: now, or the anchor kept in --spool); blocks already "
        "due are skipped, as lost",
    )
    add_spool_arguments(p)
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    scene = build_scene(args.scene, args.mill, seed=args.seed, duration_s=args.duration)
    dtype = wire.DType[args.dtype.upper()]
    if args.publish:
        return _publish(scene, args, dtype)
    progress = not args.no_progress and sys.stderr.isatty()
    files = simulate_to_archive(
        scene, args.out, block_samples=args.block_size, dtype=dtype, progress=progress
    )
    if args.truth is not None:
        args.truth.write_text(json.dumps(scene.truth.to_dict(), indent=2) + "\n")
    _report(scene.config, scene, files, args.truth)
    return 0


def _publish(scene: Scene, args: argparse.Namespace, dtype: wire.DType) -> int:
    listen = (
        args.listen if args.listen is not None else ([] if args.connect else ["tcp/127.0.0.1:7447"])
    )
    spool = open_spool(args)
    scene = starting_now(scene, _anchor(spool, scene, args))
    if args.truth is not None:
        args.truth.write_text(json.dumps(scene.truth.to_dict(), indent=2) + "\n")
    tls = tls_files(args, gateway_name(scene.config.site, scene.config.id))
    config = build_config(listen=listen, connect=args.connect, tls=tls)
    with ExitStack() as stack:
        if spool is not None:
            stack.enter_context(spool)
        session = stack.enter_context(open_session(config))  # (a busy port: one line, exit 2)
        sys.stderr.write(
            f"publishing {scene.spec.name!r} for mill {scene.config.id} at {args.speed:g}× "
            "real time "
            f"({scene.n_samples / scene.fs / args.speed:.0f} s); listen {listen or '-'}, "
            f"connect {args.connect or '-'}; retention {args.retention:g} s; anchor "
            f"{scene.t_ns(0)} ns; Ctrl-C stops\n"
        )
        if spool is not None:
            stack.callback(SpoolServer(session, spool).close)
        publisher = ScenePublisher(
            session,
            scene,
            speed=args.speed,
            block_samples=args.block_size,
            dtype=dtype,
            retention_s=args.retention,
            anchored=True,
            spool=spool,
        )
        try:
            report = publisher.run()
        except KeyboardInterrupt:
            sys.stderr.write(
                f"stopped after {publisher.published} blocks "
                f"({publisher.skipped} skipped as due before start)\n"
            )
            return 130
    sys.stdout.write(
        f"published {report.blocks} blocks in {report.wall_s:.1f} s; {report.skipped} blocks "
        f"fell due before start and were skipped; first sequence {report.first_seq}\n"
    )
    if spool is not None:
        sys.stdout.write(spool_summary(spool) + "\n")
    return 0


def _scene_identity(scene: Scene, args: argparse.Namespace) -> dict[str, object]:
    """What must be the same for a restarted gateway to continue a spooled scene."""
    return {"scene": scene.spec.name, "mill": scene.config.id, "seed": args.seed,
            "samples": scene.n_samples, "block_size": args.block_size}  # fmt: skip


def _anchor(spool: Spool | None, scene: Scene, args: argparse.Namespace) -> int | None:
    """The scene's anchor: ``--anchor-ns``, else the one the spool kept (a restart), else now
    (None); recorded in the spool. A spool of another scene or anchor is refused: its sequence
    numbers would not continue (the blocks it holds would hide the new run's)."""
    if spool is None:
        return cast(int | None, args.anchor_ns)
    identity = _scene_identity(scene, args)
    kept = spool.meta()
    given = None if args.anchor_ns is None else _whole_ms(args.anchor_ns)
    if kept and (kept.get("scene_identity") != identity or given not in (None, kept["anchor_ns"])):
        raise SpoolError(
            f"--spool {spool.directory} holds the blocks of another run ({kept}); give this "
            "scene its own spool directory (the same directory resumes the run it holds)"
        )
    anchor = given if given is not None else kept.get("anchor_ns")
    if anchor is None:
        anchor = _whole_ms(time.time_ns())
    elif given is None:
        log.info("resuming the spooled scene anchored at %d ns", anchor)
    spool.set_meta(scene_identity=identity, anchor_ns=anchor)
    return int(anchor)


def _whole_ms(t_ns: int) -> int:
    """``t_ns`` down to whole ms (where :func:`starting_now` places a scene's t0)."""
    return int(t_ns) // 1_000_000 * 1_000_000


def _report(config: MillConfig, scene: Scene, files: list[Path], truth: Path | None) -> None:
    where = files[0] if len(files) == 1 else f"{len(files)} files in {files[0].parent}"
    sys.stdout.write(
        f"simulated {scene.spec.name!r} on mill {config.id} ({config.site}): "
        f"{scene.n_samples / scene.fs:g} s, {len(config.channels)} channels → {where}\n"
    )
    if truth is not None:
        sys.stdout.write(f"ground truth → {truth}\n")
