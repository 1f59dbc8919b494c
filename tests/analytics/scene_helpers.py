"""Shared helpers for the operating-state, transient and analyzer tests: short simulator scenes."""

from __future__ import annotations

import itertools
from functools import cache
from pathlib import Path

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.loads import LoadAnalysis
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import SceneSpec

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"


@cache
def mill(name: str) -> MillConfig:
    return load_mill_config(MILLS / f"{name}.toml")


def scene(name: str, mill_name: str = "sag-5200-lrs", seed: int = 0, **kw: object) -> Scene:
    return get_scene(name, mill(mill_name), seed=seed, **kw)


def custom(mill_name: str, events: list[dict], duration_s: float, seed: int = 0) -> Scene:
    spec = SceneSpec.model_validate(
        {"name": "custom", "seed": seed, "duration_s": duration_s, "events": events}
    )
    return Scene(mill(mill_name), spec)


def state_inputs(sc: Scene, data: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Speed and torque fractions of rated, as the analyzer computes them."""
    cfg = sc.config
    speed = next(n for n, c in cfg.channels.items() if c.kind == "rpm")
    shaft = cfg.channels[speed].shaft
    rated = cfg.drive.motor_speed_rpm if shaft == "motor" else cfg.pinion_speed_rpm
    motors = [n for n, c in cfg.channels.items() if c.kind == "torque" and c.shaft == "motor"]
    q = np.max(np.abs(np.vstack([data[n] for n in motors])), axis=0)
    return np.abs(data[speed]) / rated, q / cfg.motor_rated_torque_knm


def run(sc: Scene, cuts: list[int] | None = None, frame: int = 1000) -> LoadAnalysis:
    """Feed a whole scene to a fresh analyzer, in frames of ``frame`` samples or at ``cuts``."""
    data = sc.render(0, sc.n_samples)
    a = LoadAnalysis(sc.config)
    bounds = sorted(set(cuts or range(0, sc.n_samples, frame)) | {0, sc.n_samples})
    for lo, hi in itertools.pairwise(bounds):
        a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
    return a
