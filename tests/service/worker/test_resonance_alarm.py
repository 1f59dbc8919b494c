"""The torsional model wired (Fedin & Vinogradov 2018): the live pipeline of the shipped SAG mill
on the simulator's ``resonance`` scene (a 12 Hz torsional line, Diering 2011 §6.2.7) raises the
``resonance_margin`` warning against the mill file's 12.67 Hz mode; the steady scene does not; a
mill file without a ``[torsional]`` table says so once, in words, and no message says "None Hz".
"""

from __future__ import annotations

import logging
from functools import cache
from pathlib import Path

from millwatch.alarms.lifecycle import Transition
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.torsional_model import NO_MODEL_NOTE, natural_frequencies_of
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import decode_block
from millwatch.worker.mill_job import MillJob

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
SAG = load_mill_config(MILL)
NO_MODEL = SAG.model_copy(update={"torsional": None})
BATCH = 400  # blocks aligned before each analysis (about 10 s of the four channels)


def run(config: MillConfig, scene: str, duration_s: float) -> tuple[MillJob, list[Transition]]:
    """The worker's pipeline of ``config`` fed with the scene's blocks, in batches."""
    job = MillJob(config)
    channel = {c.key: n for n, c in config.channels.items()}
    transitions: list[Transition] = []
    for k, b in enumerate(scene_blocks(get_scene(scene, config, seed=4, duration_s=duration_s))):
        job.add_block(channel[b.key.rsplit("/", 1)[-1]], decode_block(b.payload))
        if k % BATCH == BATCH - 1:
            transitions += job.finish().alarm_transitions
    job.analyzer.flush()
    return job, transitions + job.finish().alarm_transitions


@cache
def resonance_run() -> tuple[MillJob, list[Transition]]:
    return run(SAG, "resonance", 220.0)


def test_the_shipped_mill_has_a_mode_in_the_10_to_15_hz_band():
    natural = natural_frequencies_of(SAG)
    assert len(natural) == 4 and any(10.0 < f < 15.0 for f in natural), natural


def test_resonance_margin_fires_on_the_resonance_scene():
    _, transitions = resonance_run()
    raised = [t for t in transitions if t.alarm.rule == "resonance_margin"]
    assert raised, [t.alarm.rule for t in transitions]
    first = raised[0]
    assert str(first.kind) == "raised" and str(first.severity) == "warning"
    assert first.value is not None and first.value < SAG.alarms.resonance_margin_warn
    assert "(unexplained peak 12 Hz, natural 12.67 Hz)" in first.message, first.message


def test_every_unexplained_peak_carries_a_finite_natural_frequency():
    job, transitions = resonance_run()
    report = job.analyzer.report()
    assert report["unexplained_peaks"]
    for p in report["unexplained_peaks"]:
        assert p["nearest_natural_hz"] is not None and 12.6 < p["nearest_natural_hz"] < 12.7
    margins = {m["channel"]: m for m in report["resonance_margins"]}
    for torque in ("motor_torque", "pinion_torque"):  # the torsional line is in the torque
        assert margins[torque]["line"] == "unexplained peak"
        f, fn = margins[torque]["frequency_hz"], margins[torque]["natural_hz"]
        assert margins[torque]["margin"] == abs(f - fn) / fn < 0.1
    assert margins["pinion_bending"]["margin"] > 0.1  # … not in the bending
    assert (
        "natural frequencies 5.05, 12.67, 83.18, 350.73 Hz"
        in (report["summary"]["torsional_model"])
    )
    assert all("None" not in t.message for t in transitions)


def test_steady_running_keeps_its_margin():
    job, transitions = run(SAG, "steady", 140.0)
    assert not [t for t in transitions if t.alarm.rule == "resonance_margin"]
    margins = job.analyzer.report()["resonance_margins"]
    assert margins and all(m["margin"] > SAG.alarms.resonance_margin_warn for m in margins)


def test_a_mill_without_a_model_says_so_once(caplog):
    with caplog.at_level(logging.INFO, logger="millwatch.worker.mill_job"):
        job, transitions = run(NO_MODEL, "resonance", 100.0)
    said = [r for r in caplog.records if NO_MODEL_NOTE in r.getMessage()]
    assert len(said) == 1 and NO_MODEL.id in said[0].getMessage()
    report = job.analyzer.report()
    assert report["summary"]["torsional_model"] == NO_MODEL_NOTE
    assert report["resonance_margins"] == []
    assert all(p["nearest_natural_hz"] is None for p in report["unexplained_peaks"])
    peaks = [t for t in transitions if t.alarm.rule == "unexplained_peak"]
    assert peaks and all("no torsional model to compare it with" in t.alarm.advice for t in peaks)
    assert not [t for t in transitions if t.alarm.rule == "resonance_margin"]
