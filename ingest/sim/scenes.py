"""The scene catalogue and scene files.

A catalogue scene is built for any mill configuration by name (:func:`get_scene`); a scene file
(TOML, :func:`load_scene_file`) names a mill file and either a catalogue ``base`` or its own
events::

    name = "night-trip"
    mill = "../mills/sag-5200-lrs.toml"   # relative to the scene file
    seed = 3
    duration_s = 900
    t0 = 2024-05-01T00:00:00Z             # optional; TOML datetime or int ns
    base = "start-lrs"                    # optional catalogue scene to start from
    [params]                              # optional SceneParams overrides
    motor_oscillation_pct = 30
    [[events]]
    kind = "trip"
    at_s = 400

A mill file's ``[simulation]`` table (e.g. ``bending_range_mpa = 80`` for a misaligned pinion)
sets that mill's scene parameters under every scene's own (:func:`with_mill_params`).

Catalogue (Diering 2011 numbers behind each are in :mod:`millwatch.ingest.sim.renderer`):

``steady``            10 min of steady running,
``start-lrs``, ``start-grid``, ``start-elrs``
                      one start (that starter), 2 min running, stop, rest,
``month``             30 days with ~90 switch-ons (Diering 2011 §6.2.8: peak 90 stops a month),
                      failed starts, trips, barring after long stops, spikes and dropouts,
``barring``           a barring session on a stopped mill (Figure 27, Tables 12–13),
``telemetry-faults``  steady running with interference spikes and dropouts (§5.2.2),
``resonance``         steady running with an extra 12 Hz torsional line (§6.2.7: 10–15 Hz).
"""

from __future__ import annotations

import logging
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from millwatch.analytics.drivetrain.mill_config import (
    MillConfig,
    Starter,
    describe_validation_error,
)
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.spec import (
    BarringEvent,
    DropoutEvent,
    FailedStartEvent,
    ResonanceEvent,
    SceneError,
    SceneParams,
    SceneSpec,
    SpikesEvent,
    StartEvent,
    StopEvent,
    TripEvent,
)

__all__ = [
    "CATALOGUE",
    "get_scene",
    "list_scenes",
    "load_scene_file",
    "month_events",
    "scene_spec",
    "with_mill_params",
]

log = logging.getLogger(__name__)

DAY_S = 86_400.0
SpecBuilder = Callable[[MillConfig, int], SceneSpec]


def _steady(config: MillConfig, seed: int) -> SceneSpec:
    return SceneSpec(name="steady", seed=seed, duration_s=600.0, initial_state="running")


def _one_start(starter: Starter) -> SpecBuilder:
    def build(config: MillConfig, seed: int) -> SceneSpec:
        events = (StartEvent(at_s=5.0, starter=starter), StopEvent(at_s=150.0))
        name = f"start-{starter.value.lower().replace('-', '')}"
        return SceneSpec(name=name, seed=seed, duration_s=220.0, events=events)

    return build


def _barring(config: MillConfig, seed: int) -> SceneSpec:
    return SceneSpec(
        name="barring", seed=seed, duration_s=420.0, events=(BarringEvent(at_s=5.0, sweeps=2),)
    )


def _telemetry_faults(config: MillConfig, seed: int) -> SceneSpec:
    events: list[Any] = [SpikesEvent(at_s=10.0, bursts=30, spread_s=270.0)]
    events += [DropoutEvent(at_s=t, duration_s=d) for t, d in ((60.0, 0.5), (150.0, 2.0))]
    return SceneSpec(
        name="telemetry-faults",
        seed=seed,
        duration_s=300.0,
        initial_state="running",
        events=tuple(events),
    )


def _resonance(config: MillConfig, seed: int) -> SceneSpec:
    line = ResonanceEvent(at_s=0.0, duration_s=300.0, frequency_hz=12.0, amplitude_pct=8.0)
    return SceneSpec(
        name="resonance", seed=seed, duration_s=300.0, initial_state="running", events=(line,)
    )


def _month(config: MillConfig, seed: int) -> SceneSpec:
    rng = np.random.default_rng([seed, 0x307])
    return SceneSpec(
        name="month", seed=seed, duration_s=30 * DAY_S, events=tuple(month_events(rng))
    )


CATALOGUE: dict[str, SpecBuilder] = {
    "steady": _steady,
    "start-lrs": _one_start(Starter.LRS),
    "start-grid": _one_start(Starter.GRID),
    "start-elrs": _one_start(Starter.E_LRS),
    "month": _month,
    "barring": _barring,
    "telemetry-faults": _telemetry_faults,
    "resonance": _resonance,
}


def _cycle_events(t: float, length: float, rng: np.random.Generator) -> list[Any]:
    """Events of one stop-to-stop cycle beginning at rest at ``t`` (s) and lasting ``length``."""
    idle = max(600.0, float(rng.uniform(0.05, 0.5)) * length)
    events: list[Any] = []
    start = t + idle
    if idle > 4 * 3600.0:  # long standstill: bar the mill first (Diering 2011 §6.1.1)
        events.append(BarringEvent(at_s=start - 1200.0, sweeps=int(rng.integers(1, 3))))
    if rng.random() < 0.08:
        events.append(FailedStartEvent(at_s=start - 600.0))
    events.append(StartEvent(at_s=start))
    end = t + length - 120.0  # the stop and the rocking end before the next cycle
    kind = TripEvent if rng.random() < 0.3 else StopEvent
    events.append(kind(at_s=max(end, start + 300.0)))
    return events


def month_events(
    rng: np.random.Generator,
    *,
    days: float = 30.0,
    cycles: int = 84,
    spike_bursts: int = 300,
    dropouts: int = 6,
) -> list[Any]:
    """A month of operation: ``cycles`` stop-to-stop cycles of random length (≥ 30 min; with
    failed starts ~90 switch-ons, Diering 2011 §6.2.8), spikes and dropouts at random times."""
    lengths = np.maximum(rng.exponential(1.0, cycles), 0.05)
    lengths = 1800.0 + lengths / lengths.sum() * (days * DAY_S - 3600.0 - 1800.0 * cycles)
    events: list[Any] = []
    t = 60.0
    for length in lengths:
        events += _cycle_events(t, float(length), rng)
        t += float(length)
    span = days * DAY_S - 60.0
    events += [
        SpikesEvent(at_s=float(s), bursts=1) for s in np.sort(rng.uniform(0, span, spike_bursts))
    ]
    events += [
        DropoutEvent(at_s=float(s), duration_s=float(rng.uniform(0.2, 5.0)))
        for s in np.sort(rng.uniform(0, span, dropouts))
    ]
    return events


def list_scenes() -> list[str]:
    """Names of the catalogue scenes."""
    return sorted(CATALOGUE)


def scene_spec(name: str, config: MillConfig, seed: int = 0) -> SceneSpec:
    """The catalogue spec ``name`` for ``config``; ``KeyError`` names the known scenes."""
    try:
        builder = CATALOGUE[name]
    except KeyError:
        raise KeyError(f"unknown scene {name!r}; known: {', '.join(list_scenes())}") from None
    return with_mill_params(builder(config, seed), config)


def with_mill_params(spec: SceneSpec, config: MillConfig) -> SceneSpec:
    """``spec`` with the mill file's ``[simulation]`` scene parameters under the parameters the
    spec sets itself (a catalogue scene's or a scene file's own ``[params]`` win)."""
    if config.simulation is None:
        return spec
    own = spec.params.model_dump(exclude_unset=True)
    params = {**config.simulation.scene_params(), **own}
    return spec.model_copy(update={"params": SceneParams.model_validate(params)})


def get_scene(name: str, config: MillConfig, seed: int = 0, **overrides: Any) -> Scene:
    """Catalogue scene ``name`` for ``config``; ``overrides`` replace SceneSpec fields
    (e.g. ``duration_s``, ``params``)."""
    spec = scene_spec(name, config, seed)
    if overrides:
        dump = {**spec.model_dump(), "params": spec.params.model_dump(exclude_unset=True)}
        spec = SceneSpec.model_validate({**dump, **overrides})
        spec = with_mill_params(spec, config)
    return Scene(config, spec)


def _spec_from_table(data: dict[str, Any], config: MillConfig) -> SceneSpec:
    base = data.pop("base", None)
    if base is None:
        return with_mill_params(SceneSpec.model_validate(data), config)
    spec = scene_spec(base, config, int(data.get("seed", 0))).model_dump()
    spec["params"] = {**spec["params"], **data.pop("params", {})}
    spec["events"] = [*spec["events"], *data.pop("events", [])]
    return SceneSpec.model_validate({**spec, **data})


def load_scene_file(path: str | Path, config: MillConfig | None = None) -> Scene:
    """Read a scene TOML file (format in the module docstring) and build the scene.

    ``config`` overrides the file's ``mill``. Errors raise :class:`SceneError` naming the file
    and the field.
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"{path}: {exc}") from exc
    mill = data.pop("mill", None)
    if config is None:
        if mill is None:
            raise SceneError(f"{path}: mill: required (path of the mill TOML file)")
        config = load_mill_config(path.parent / mill)
    if "t0" in data:
        data["t0_ns"] = data.pop("t0")
    try:
        spec = _spec_from_table(data, config)
    except ValidationError as exc:
        raise SceneError(f"{path}: " + "; ".join(describe_validation_error(exc))) from exc
    except KeyError as exc:
        raise SceneError(f"{path}: base: {exc.args[0]}") from exc
    log.info("scene %s for mill %s from %s", spec.name, config.id, path)
    return Scene(config, spec)
