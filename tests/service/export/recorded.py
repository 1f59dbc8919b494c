"""A real archive of a simulated LRS start (``millwatch simulate``: the real ArchiveWriter) and
readers of what an export holds, shared by the export tests of ``service/export`` and ``cli``."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.cli.analyze import _Blocks
from millwatch.cli.main import main
from millwatch.export.foxglove import Admit
from millwatch.ingest import keys, wire
from millwatch.ingest.archive.reader import TailTolerantReader

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
MILL = MILLS / "sag-5200-lrs.toml"
T0 = 1_704_067_200_000_000_000  # 2024-01-01T00:00:00Z, the scene's first sample
S = 1_000_000_000


def admit_for(config: MillConfig) -> Admit:
    """Decoding and admission as ``millwatch analyze`` (what the command passes)."""
    return _Blocks(config).admit


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    d = tmp_path_factory.mktemp("export")
    out, truth = d / "start.mcap", d / "truth.json"
    assert main(["simulate", "--scene", "start-lrs", "--out", str(out), "--truth", str(truth),
                 "--no-progress", "--seed", "3"]) == 0  # fmt: skip
    return out, json.loads(truth.read_text())


def read_export(path: Path, topics: list[str] | None = None) -> dict[str, list[tuple]]:
    """topic → [(schema name, log time, publish time, decoded message)], in file order."""
    got: dict[str, list[tuple]] = defaultdict(list)
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, msg, decoded in reader.iter_decoded_messages(topics=topics):
            got[channel.topic].append((schema.name, msg.log_time, msg.publish_time, decoded))
    return got


def archived_samples(path: Path) -> dict[str, tuple[list[int], np.ndarray, list[int]]]:
    """signal → (sample times, samples as float64, archive log times of the blocks)."""
    parts: dict[str, list[tuple[wire.Block, int]]] = defaultdict(list)
    for msg in TailTolerantReader(path).messages():
        parts[keys.parse_key(msg.key).signal_segment].append(
            (wire.decode_block(msg.payload), msg.log_time_ns)
        )
    out = {}
    for name, blocks in parts.items():
        times = [b.t0_ns + i * 1_000_000 for b, _ in blocks for i in range(len(b.samples))]
        values = np.concatenate([b.samples.astype(np.float64) for b, _ in blocks])
        out[name] = (times, values, [log for _, log in blocks])
    return out
