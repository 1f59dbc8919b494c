"""One truth for suppression by design: ``millwatch analyze`` and the live worker give the same
alarm transitions — suppression included — on the same recording. The scene: the shipped SAG
mill, whose misaligned pinion (the mill file's ``[simulation]`` bending range of 80 MPa) bends at
about 40 MPa against a 25 MPa warning while it runs; it starts at 5 s, stops at 150 s and starts
again at 200 s. The bending alarm raised while running is suppressed at the stop and unsuppressed
at the next start, on both paths: the simulator's MCAP through ``millwatch analyze --json`` and
the same scene's blocks through the worker's :class:`~millwatch.worker.mill_job.MillJob`."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path
from typing import Any

from millwatch.alarms.report import history
from millwatch.cli.main import main
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import load_scene_file
from millwatch.ingest.wire import decode_block
from millwatch.worker.mill_job import MillJob
from tests.service.worker.test_resonance_alarm import BATCH, MILL, SAG

SCENE = """
name = "stop-and-start"
seed = 4
base = "start-lrs"
duration_s = 330
[[events]]
kind = "start"
at_s = 200
"""
#: The rules both paths judge on the same facts (the live worker also judges data quality and
#: per-window spectra; ``analyze`` the record's long-run spectra: see
#: :mod:`millwatch.alarms.from_analysis`).
SHARED = {"start_peak", "bending_amplitude", "oscillation_range", "starts_per_month"}
NS = 1_000_000_000
STEP = ("seq", "kind", "t_ns", "severity", "state", "value", "threshold", "message")


def _steps(alarms: list[dict[str, Any]]) -> dict[str, list[tuple[Any, ...]]]:
    """Each shared rule's alarm id → its transitions (the fields both paths record)."""
    return {a["alarm_id"]: [tuple(t[k] for k in STEP) for t in a["transitions"]]
            for a in alarms if a["rule"] in SHARED}  # fmt: skip


def both_paths(directory: Path) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(``analyze``'s alarms, the live worker's alarms as ``analyze`` groups them)."""
    scene_file, mcap = directory / "scene.toml", directory / "scene.mcap"
    scene_file.write_text(SCENE)
    assert main(["simulate", "--scene", str(scene_file), "--mill", str(MILL), "--out", str(mcap),
                 "--no-progress"]) == 0  # fmt: skip
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["analyze", str(mcap), "--mill", str(MILL), "--json", "--no-progress"]) == 0
    offline = json.loads(out.getvalue())["alarms"]
    job = MillJob(SAG)
    channel = {c.key: n for n, c in SAG.channels.items()}
    transitions = []
    for k, b in enumerate(scene_blocks(load_scene_file(scene_file, SAG))):
        job.add_block(channel[b.key.rsplit("/", 1)[-1]], decode_block(b.payload))
        if k % BATCH == BATCH - 1:
            transitions += job.finish().alarm_transitions
    job.analyzer.flush()
    transitions += job.finish().alarm_transitions
    return offline, history(transitions)


def test_analyze_and_the_live_worker_give_the_same_transitions_suppression_included(
    tmp_path_factory,
):
    offline, live = both_paths(tmp_path_factory.mktemp("paths"))
    bending = [a for a in live if a["rule"] == "bending_amplitude"]
    assert bending, [a["rule"] for a in live]
    kinds = [str(t["kind"]) for t in bending[0]["transitions"]]
    assert kinds[:3] == ["raised", "suppressed", "unsuppressed"], kinds
    assert _steps(offline) == _steps(live)


def test_the_worker_clears_a_held_start_peak_alarm_while_the_mill_stands_still(tmp_path):
    """An acknowledged start-peak alarm returns to normal ``start_peak_hold_s`` after its last
    exceeding start even when the mill observes nothing (stopped: no steady windows): the
    worker lets the engine see sample time pass at every damage interval. Every start exceeds
    here (warning lowered to 100 %); the hold of 155 s after the start near 5 s ends inside the
    standstill from the stop (150 s) to the next start (200 s), and the blocks end at 195 s;
    damage intervals of 20 s put a tick in the standstill after it."""
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(SCENE)
    alarms = SAG.alarms.model_copy(
        update={"start_peak_warn_pct": 100.0, "start_peak_hold_s": 155.0}
    )
    job = MillJob(
        SAG.model_copy(update={"alarms": alarms}), damage_every_s=20.0
    )  # ticks ~8 s + 20 k
    channel = {c.key: n for n, c in SAG.channels.items()}
    transitions: list[Any] = []
    t_first: int | None = None
    for k, b in enumerate(scene_blocks(load_scene_file(scene_file, SAG))):
        block = decode_block(b.payload)
        t_first = block.t0_ns if t_first is None else t_first
        if block.t0_ns - t_first >= 195 * NS:
            break
        job.add_block(channel[b.key.rsplit("/", 1)[-1]], block)
        if k % BATCH == BATCH - 1:
            for t in job.finish().alarm_transitions:
                transitions.append(t)
                if t.alarm.rule == "start_peak" and t.kind == "raised":
                    job.alarms.acknowledge(t.alarm_id, "ops", t.t_ns + NS)
    transitions += job.finish().alarm_transitions
    kinds = [str(t.kind) for t in transitions if t.alarm.rule == "start_peak"]
    assert kinds == ["raised", "cleared"], kinds
    raised, cleared = (t for t in transitions if t.alarm.rule == "start_peak")
    assert cleared.t_ns == raised.t_ns + 155 * NS
    assert 150 * NS < cleared.t_ns - t_first < 195 * NS
