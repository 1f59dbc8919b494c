"""Test helpers: a short simulated scene (the real producer) and the same samples written in
each legacy format with that format's own library — what an engineer's tools would write."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.cli.analyze import analyze_recording
from millwatch.cli.simulate import DEFAULT_MILL, simulate_to_archive
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene

#: A start of the default mill (LRS starter) at 1 s, running up to about 16 s: a start event
#: with its peaks, and damage on every component, in 30 s of samples.
SCENE_S = 30.0


@dataclass(frozen=True)
class SceneData:
    """The scene's samples (engineering units) per channel, their times, its MCAP file."""

    config: MillConfig
    data: dict[str, np.ndarray]
    times_ns: np.ndarray
    mcap: Path

    @property
    def t0_ns(self) -> int:
        return int(self.times_ns[0])


def make_scene(directory: Path, mill: Path = DEFAULT_MILL) -> SceneData:
    config = load_mill_config(mill)
    events = [{"kind": "start", "at_s": 1.0}, {"kind": "stop", "at_s": 25.0}]
    scene = get_scene("start-lrs", config, seed=3, duration_s=SCENE_S, events=events)
    out = directory / "scene.mcap"
    simulate_to_archive(scene, out)
    (chunk,) = scene.chunks(SCENE_S)
    times = np.array([scene.t_ns(i) for i in range(scene.n_samples)], dtype=np.int64)
    return SceneData(config, dict(chunk.data), times, out)


def outcome(path: Path, config: MillConfig) -> tuple[list[tuple[str, int]], dict, dict]:
    """What the analyzer makes of a recording: events as (kind, t_ns) in time order, damage per
    component (committed, and by phase), and the whole report."""
    analyzer, _ = analyze_recording([path], config, spectra=False)
    report = analyzer.report()
    events = sorted((kind, e["t_ns"]) for kind in ("starts", "stops", "barring")
                    for e in report[kind])  # fmt: skip
    damage = {c: (d["committed"], d["phases"]) for c, d in report["damage"].items()}
    return events, damage, report


def messages(path: Path) -> list[tuple[str, bytes, int]]:
    return [(m.key, bytes(m.payload), m.log_time_ns) for m in TailTolerantReader(path).messages()]


def rel_s(times_ns: np.ndarray) -> np.ndarray:
    return (times_ns - times_ns[0]) / 1e9


def write_csv(path: Path, data: dict[str, np.ndarray], times_ns: np.ndarray) -> Path:
    """Seconds since the epoch as float64 (as a logger's CSV export has them), values repr'd."""
    with open(path, "w", newline="") as stream:
        out = csv.writer(stream)
        out.writerow(["time", *data])
        columns = [times_ns / 1e9, *data.values()]
        out.writerows(zip(*(c.tolist() for c in columns), strict=True))
    return path


def write_mat(path: Path, data: dict[str, np.ndarray], t0_ns: int | None, fs: float) -> Path:
    import scipy.io

    variables: dict[str, object] = {name: x.reshape(1, -1) for name, x in data.items()}
    variables["fs"] = fs
    if t0_ns is not None:
        variables["t0"] = t0_ns / 1e9
    scipy.io.savemat(path, variables)
    return path


def write_tdms(path: Path, data: dict[str, np.ndarray], t0_ns: int, fs: float) -> Path:
    from nptdms import ChannelObject, GroupObject, TdmsWriter

    start = np.datetime64(t0_ns, "ns").astype("datetime64[us]")
    channels = [
        ChannelObject("Measurement", name, x, properties={
            "wf_increment": 1.0 / fs, "wf_start_time": start, "wf_start_offset": 0.0,
            "wf_samples": x.shape[0],
        })
        for name, x in data.items()
    ]  # fmt: skip
    with TdmsWriter(path) as writer:
        writer.write_segment([GroupObject("Measurement"), *channels])
    return path


def write_mf4(path: Path, data: dict[str, np.ndarray], times_ns: np.ndarray, t0_ns: int) -> Path:
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    mdf.header.start_time = datetime.fromtimestamp(t0_ns / 1e9, tz=UTC)
    stamps = (times_ns - t0_ns) / 1e9
    mdf.append([Signal(x, stamps, name=name, unit="") for name, x in data.items()])
    mdf.save(path, overwrite=True)
    mdf.close()
    return path


def write_h5(path: Path, data: dict[str, np.ndarray], t0_ns: int | None, fs: float) -> Path:
    import h5py

    with h5py.File(path, "w") as f:
        for name, x in data.items():
            f[name] = x
        f.attrs["fs"] = fs
        if t0_ns is not None:
            f.attrs["t0"] = t0_ns / 1e9
    return path
