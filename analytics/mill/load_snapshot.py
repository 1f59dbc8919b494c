"""The checkpoint format of the load stage: kind, version and key order of
:meth:`LoadAnalysis.snapshot <millwatch.analytics.mill.loads.LoadAnalysis.snapshot>`, and the
reading of an older checkpoint.

Stored checkpoints hold these keys in this order (:data:`KEYS`); each part of the load stage
gives its own keys and :func:`assemble` puts them in that order, so the JSON text is the same
however the parts are divided. Version 2 keyed the steady-state channels by drive-side index
(``motor_torque0``, ``bending1``, …); version 3 by the mill file's channel names.
:func:`checked` renames a version-2 snapshot on restore (:func:`from_version_2`).
"""

from __future__ import annotations

from typing import Any

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.load_roles import find_channel, steady_channels

__all__ = ["KEYS", "KIND", "VERSION", "assemble", "checked", "from_version_2"]

KIND = "mill_analyzer"  # the name LoadAnalysis had when checkpoints were first written
VERSION = (
    3  # 2: arrays packed by millwatch.analytics.snapshot_arrays; 3: steady channels named by the
)
#: mill file (a version-2 snapshot is renamed on restore: :func:`from_version_2`)
#: The keys of a snapshot, in the order stored checkpoints hold them (``phase_days`` and
#: ``app_d_portions`` added at the end: older checkpoints restore without them, and without
#: ``starts_total``).
KEYS = (
    "kind", "version", "mill", "n", "t0_ns", "steady_until", "open_start", "open_stop",
    "stop_after_start", "starts", "stops", "barrings", "windows", "starts_per_day",
    "starts_per_month", "phase_samples", "lead", "discontinuities", "last", "sm",
    "timeline", "ring", "counters", "damage", "meter", "barring", "starts_total", "stress",
    "phase_days", "app_d_portions",
)  # fmt: skip


def assemble(config: MillConfig, *parts: dict[str, Any]) -> dict[str, Any]:
    """A snapshot of ``config``'s mill from the parts' keys, in the order of :data:`KEYS`
    (ValueError naming a key no part gave or one :data:`KEYS` lacks)."""
    given = {"kind": KIND, "version": VERSION, "mill": config.id}
    for part in parts:
        given |= part
    if given.keys() != set(KEYS):
        odd = sorted(set(KEYS) ^ given.keys())
        raise ValueError(f"mill {config.id}: the load stage's snapshot keys differ in {odd}")
    return {key: given[key] for key in KEYS}


def checked(config: MillConfig, snapshot: dict[str, Any]) -> dict[str, Any]:
    """``snapshot`` as version 3 (a version-2 one renamed), checked to be the load stage's of
    ``config``'s mill (:class:`~millwatch.analytics.contracts.SnapshotMismatch` or ValueError in
    words)."""
    if snapshot.get("kind") == KIND and snapshot.get("version") == 2:
        snapshot = from_version_2(config, snapshot)
    check_snapshot(snapshot, KIND, VERSION)
    if snapshot["mill"] != config.id:
        raise ValueError(f"snapshot of mill {snapshot['mill']!r}, configuration is {config.id!r}")
    return snapshot


def from_version_2(config: MillConfig, snap: dict[str, Any]) -> dict[str, Any]:
    """A version-2 snapshot in the form of version 3: version 2 keyed the steady-state
    channels by drive-side index (``motor_torque0``, ``pinion_torque0``, ``bending0``, …, a
    channel the mill lacks included); version 3 by the mill file's channel names, only the
    channels the mill has, and its windows carry ``bending_amplitude_mpa``."""
    names: dict[str, str] = {}
    for k, side in enumerate(config.sides):
        for old, kind, shaft in ((f"motor_torque{k}", "torque", "motor"),
                                 (f"pinion_torque{k}", "torque", "pinion"),
                                 (f"bending{k}", "bending", "pinion")):  # fmt: skip
            name = find_channel(config, kind, shaft, side)
            if name is not None:
                names[old] = name

    def rename(d: dict[str, Any]) -> dict[str, Any]:
        return {names[k]: v for k, v in d.items() if k in names}

    meter = snap["meter"] | {
        key: rename(snap["meter"][key])
        for key in ("part_max", "part_min", "sums", "counts", "rev_max", "rev_min")
    }
    bending = [n for n, scale in steady_channels(config).items() if scale is None]
    windows = []
    for w in snap["windows"]:
        w = w | {f: rename(w[f]) for f in ("mean", "range_per_rev", "mean_pct", "range_pct")}
        per_rev = w["range_per_rev"]
        w["bending_amplitude_mpa"] = {n: per_rev[n] / 2.0 for n in bending if n in per_rev}
        windows.append(w)
    return snap | {"version": VERSION, "meter": meter, "windows": windows}
