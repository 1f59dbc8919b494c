"""Drivetrain kinematics: the lines a steady-state torque spectrum is expected to contain.

Sources: Diering 2011 §6.1.2 and §6.2.7 list the expected excitation frequencies of a
grinding-mill drivetrain — mill speed, pinion-shaft speed, shell-liner passing (mill speed ×
liners, 20–35), motor-shaft speed, pinion/girth gear mesh and main-reducer gear mesh — and show
±-frequency sidebands around the reducer mesh (Figure 36); Fedin & Vinogradov 2018
eq. 12 adds the gear kinematic error at 3× the drive-gear (pinion) rotation (``p_p = 3ω₁``) and at
tooth-mesh frequency; Toram 2005 (Toram 2005, §5 and App. E eq. E.4) adds the grinding-media
oscillation, a rigid-body pendulum of the charge at ``ω_n = √(m g e / I)`` (1.3–1.9 Hz on a 0.3 m
lab mill), a line at a fixed frequency rather than an order of shaft rotation.

The base orders come from
:meth:`millwatch.analytics.drivetrain.mill_config.MillConfig.excitation_orders` (cycles per
pinion revolution); this module adds the harmonics and the ±mill-speed sidebands of the mesh
lines, the optional media line, evaluates them at a measured pinion speed and marks each line
*not observable* above the telemetry bandwidth (Diering 2011 §5.1.2: 0–250 Hz) or Nyquist. Units:
frequency Hz, speed rpm, order in cycles per pinion revolution.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from millwatch.analytics.drivetrain.mill_config import ChannelConfig, MillConfig

__all__ = [
    "ExpectedLine",
    "KinematicsOptions",
    "LineKind",
    "expected_lines",
    "media_oscillation_hz",
    "pinion_rpm",
    "shaft_speeds_rpm",
]

LineKind = Literal["fundamental", "harmonic", "sideband", "fixed"]
MESH_PREFIXES = ("girth_mesh", "reducer_mesh")
STANDARD_GRAVITY = 9.80665  # m/s²


class KinematicsOptions(BaseModel):
    """Which derived lines to expect. Proposed as an optional ``MillConfig.kinematics`` field.

    ``mesh_harmonics``: highest harmonic of each mesh line (1 = fundamental only);
    ``mesh_sidebands``: ±k·mill-speed sidebands around each mesh line and its harmonics;
    ``media_oscillation_hz``: grinding-media oscillation frequency (Toram 2005), None = none;
    ``bandwidth_hz``: telemetry bandwidth, None = ``MillConfig.telemetry_bandwidth_hz``.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    mesh_harmonics: Annotated[int, Field(ge=1, le=10)] = 3
    mesh_sidebands: Annotated[int, Field(ge=0, le=5)] = 1
    media_oscillation_hz: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    bandwidth_hz: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None


@dataclass(frozen=True)
class ExpectedLine:
    """One expected spectral line.

    ``order`` is in cycles per pinion revolution (None for a fixed-frequency line such as the
    media oscillation), ``frequency_hz`` its frequency at the speed the list was built for,
    ``family`` the base excitation (``girth_mesh`` for ``girth_mesh_h2-1``), ``observable``
    False above the telemetry bandwidth or Nyquist (such lines are listed, never measured).
    """

    name: str
    family: str
    kind: LineKind
    order: float | None
    frequency_hz: float
    observable: bool

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return asdict(self)


def media_oscillation_hz(mass_kg: float, eccentricity_m: float, inertia_kgm2: float) -> float:
    """Linearised grinding-media pendulum, Toram 2005 App. E eq. E.4: ``√(m g e / I) / 2π`` in Hz.

    ``mass_kg`` charge mass, ``eccentricity_m`` distance from the mill centre to the charge's
    centre of gravity, ``inertia_kgm2`` the charge's moment of inertia about the mill axis.
    """
    if min(mass_kg, eccentricity_m, inertia_kgm2) <= 0:
        raise ValueError("mass, eccentricity and inertia must be > 0")
    return math.sqrt(mass_kg * STANDARD_GRAVITY * eccentricity_m / inertia_kgm2) / (2.0 * math.pi)


def pinion_rpm(speed_rpm: float, channel: ChannelConfig, config: MillConfig) -> float:
    """Pinion speed (rpm) from a speed reading on the channel's shaft (motor ÷ reducer ratio)."""
    return speed_rpm / config.drive.reducer_ratio if channel.shaft == "motor" else speed_rpm


def shaft_speeds_rpm(config: MillConfig, pinion_speed_rpm: float | None = None) -> dict[str, float]:
    """Mill, pinion and motor speed (rpm) at ``pinion_speed_rpm`` (None: rated)."""
    pinion = config.pinion_speed_rpm if pinion_speed_rpm is None else float(pinion_speed_rpm)
    orders = config.excitation_orders()
    return {
        "mill": pinion * orders["mill_speed"],
        "pinion": pinion,
        "motor": pinion * orders["motor_speed"],
    }


def _limit_hz(config: MillConfig, options: KinematicsOptions) -> float:
    bandwidth = options.bandwidth_hz or config.telemetry_bandwidth_hz
    return min(bandwidth, config.sample_rate_hz / 2.0)


def _mesh_orders(
    name: str, order: float, mill_order: float, options: KinematicsOptions
) -> list[tuple[str, LineKind, float]]:
    """Harmonics ``name_hK`` and sidebands ``name[_hK]±j`` (j mill orders) of one mesh line."""
    out: list[tuple[str, LineKind, float]] = []
    for h in range(1, options.mesh_harmonics + 1):
        base = name if h == 1 else f"{name}_h{h}"
        if h > 1:
            out.append((base, "harmonic", h * order))
        for j in range(1, options.mesh_sidebands + 1):
            out.append((f"{base}-{j}", "sideband", h * order - j * mill_order))
            out.append((f"{base}+{j}", "sideband", h * order + j * mill_order))
    return out


def expected_orders(
    config: MillConfig, options: KinematicsOptions | None = None
) -> list[tuple[str, str, LineKind, float]]:
    """(name, family, kind, order) of every shaft-locked line: the config's excitation orders,
    then the harmonics and sidebands of the mesh lines."""
    options = options or KinematicsOptions()
    base = config.excitation_orders()
    mill_order = base["mill_speed"]
    rows: list[tuple[str, str, LineKind, float]] = [
        (name, name, "fundamental", order) for name, order in base.items()
    ]
    for name, order in base.items():
        if name.startswith(MESH_PREFIXES):
            rows += [(n, name, k, o) for n, k, o in _mesh_orders(name, order, mill_order, options)]
    return rows


def expected_lines(
    config: MillConfig,
    pinion_speed_rpm: float | None = None,
    options: KinematicsOptions | None = None,
) -> list[ExpectedLine]:
    """Every expected line at ``pinion_speed_rpm`` (None: rated), sorted by frequency.

    Lines above ``min(bandwidth, fs/2)`` are returned with ``observable=False``; callers skip them.
    """
    options = options or KinematicsOptions()
    rev_hz = (config.pinion_speed_rpm if pinion_speed_rpm is None else pinion_speed_rpm) / 60.0
    limit = _limit_hz(config, options)
    lines = [
        ExpectedLine(name, family, kind, order, order * rev_hz, 0.0 < order * rev_hz <= limit)
        for name, family, kind, order in expected_orders(config, options)
    ]
    if options.media_oscillation_hz is not None:
        f = options.media_oscillation_hz
        lines.append(ExpectedLine("media_oscillation", "media_oscillation", "fixed", None, f,
                                  f <= limit))  # fmt: skip
    return sorted(lines, key=lambda line: line.frequency_hz)
