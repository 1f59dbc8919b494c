"""Channel roles of the load stage: which of the mill file's channels give the speed, each
drive side's motor torque, pinion torque and pinion bending, which damage components they feed
and which channels a steady-state window reports, by their names in the mill file.

:class:`LoadRoles` is derived once from the configuration and never changes while samples are
fed (nothing of it is snapshotted). Its ``rows`` are the rows of the load stage's sample ring:
the speed, then motor torque, pinion torque, pinion bending per drive side (a channel the mill
file lacks keeps its row, NaN, so every side's rows stand at ``1 + 3·k``).
"""

from __future__ import annotations

from dataclasses import dataclass

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.shaft_stress import ShaftStressModel

__all__ = ["LoadRoles", "component_names", "find_channel", "steady_channels"]

#: The measured quantities of a drive side, in the order of its ring rows: (kind, shaft).
SIDE_ROWS = (("torque", "motor"), ("torque", "pinion"), ("bending", "pinion"))


def find_channel(config: MillConfig, kind: str, shaft: str, side: str | None) -> str | None:
    """The mill file's name of the channel measuring ``kind`` on ``shaft`` of drive ``side``
    (None on a single drive), or None when the mill has none."""
    for name, ch in config.channels.items():
        if ch.kind == kind and ch.shaft == shaft and ch.side == side:
            return name
    return None


def steady_channels(config: MillConfig) -> dict[str, float | None]:
    """The channels a steady-state window reports, by their names in the mill file, in the
    order of the analysis' rows (per drive side: motor torque, pinion torque, pinion bending;
    a channel the mill file lacks is left out, never derived from another), each with its scale
    to % of the motor's rated torque (pinion torque referred to the motor by the reducer ratio,
    Diering 2011 §6.2.4 Tables 14–15; None for bending, which stays in MPa)."""
    t_m = 100.0 / config.motor_rated_torque_knm
    scale = {"motor": t_m, "pinion": t_m / config.drive.reducer_ratio}
    out: dict[str, float | None] = {}
    for side in config.sides:
        for kind, shaft in SIDE_ROWS:
            name = find_channel(config, kind, shaft, side)
            if name is not None:
                out[name] = scale[shaft] if kind == "torque" else None
    return out


def component_names(config: MillConfig) -> list[str]:
    """Damage components of a mill: combined/torsion per side (Diering 2011 §8.1–8.2; see
    :mod:`millwatch.analytics.mill.loads`)."""
    return config.components


@dataclass(frozen=True)
class LoadRoles:
    """The roles of a mill's channels in the load stage (module docstring). ``rated_rpm`` is
    the rated speed of the shaft the speed channel measures (rpm); ``motor``, ``pinion`` and
    ``bending`` name each side's channel (None where the mill has none)."""

    speed_ch: str
    rated_rpm: float
    sides: tuple[str | None, ...]
    motor: list[str | None]
    pinion: list[str | None]
    bending: list[str | None]
    rows: list[str]
    components: list[str]
    stress_model: ShaftStressModel

    @classmethod
    def of(cls, config: MillConfig) -> LoadRoles:
        """The roles in ``config``; ValueError when the mill file has no rpm speed channel."""
        speed = [n for n, ch in config.channels.items() if ch.kind == "rpm"]
        if not speed:
            raise ValueError(f"mill {config.id}: no rpm speed channel (tacho conversion not wired)")
        shaft = config.channels[speed[0]].shaft
        rated = config.drive.motor_speed_rpm if shaft == "motor" else config.pinion_speed_rpm
        per_role: tuple[list[str | None], ...] = ([], [], [])
        rows = [speed[0]]
        for side in config.sides:
            for names, (kind, sh) in zip(per_role, SIDE_ROWS, strict=True):
                name = find_channel(config, kind, sh, side)
                names.append(name)
                rows.append(name or f"(missing {kind} {sh} {side})")
        return cls(
            speed_ch=speed[0], rated_rpm=rated, sides=config.sides, motor=per_role[0],
            pinion=per_role[1], bending=per_role[2], rows=rows,
            components=component_names(config), stress_model=config.shafts.stress_model(),
        )  # fmt: skip

    @property
    def torque(self) -> str | None:
        """The torque channel a barring session is measured on: the first side's motor torque,
        else its pinion torque."""
        return self.motor[0] or self.pinion[0]
