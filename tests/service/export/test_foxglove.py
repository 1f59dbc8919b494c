"""``millwatch.export.foxglove``: the export over a directory of rotated archive files (only the
files a span needs are read) and in the units of the mill's calibration."""

from __future__ import annotations

import numpy as np
import pytest

from millwatch.cli.analyze import recording_files
from millwatch.export.foxglove import export_archive
from millwatch.ingest import wire
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from tests.service.export.recorded import (
    MILL,
    T0,
    S,
    admit_for,
    archived_samples,
    read_export,
    recording,
)

__all__ = ["recording"]  # the module fixture, shared


def test_a_directory_of_rotated_files_reads_only_the_files_the_span_needs(recording, tmp_path):
    """The recording re-archived with the real writer as three files (0-70 s, 70-140 s, 140 s-);
    a span at the end reads only the last file and still gives its samples exactly."""
    archive = tmp_path / "archive"
    messages = list(TailTolerantReader(recording[0]).messages())
    for k, (lo, hi) in enumerate([(0, 70), (70, 140), (140, 999)]):
        with ArchiveWriter(tmp_path / f"part{k}", "sag") as writer:
            for m in messages:
                if T0 + lo * S <= wire.decode_block(m.payload).t0_ns < T0 + hi * S:
                    writer.write(m.key, m.payload, m.log_time_ns)
        for f in (tmp_path / f"part{k}").glob("*.mcap"):
            archive.mkdir(exist_ok=True)
            f.rename(archive / f.name)
    assert len(list(archive.glob("*.mcap"))) == 3
    config = load_mill_config(MILL)
    out = tmp_path / "end.mcap"
    result = export_archive(recording_files(archive), config, out, admit_for, start_ns=T0 + 210 * S,
                            end_ns=T0 + 215 * S, context_s=5.0)  # fmt: skip
    assert (result.files_read, result.files_skipped) == (1, 2)
    times, values, _ = archived_samples(recording[0])["speed"]
    k0 = times.index(T0 + 210 * S)
    msgs = read_export(out, ["/sag-5200-lrs/samples/speed"])["/sag-5200-lrs/samples/speed"]
    assert [m[1] for m in msgs] == times[k0 : k0 + 5000]
    exported = np.array([m[3].value for m in msgs])
    assert exported.view(np.uint64).tolist() == values[k0 : k0 + 5000].view(np.uint64).tolist()
    # the whole directory: the same samples as the single file, across the file boundaries
    whole = export_archive(
        recording_files(archive), config, tmp_path / "all.mcap", admit_for, samples=False
    )
    assert (whole.files_read, whole.counts.overview) == (3, 8800)


def test_samples_are_in_the_units_of_the_mill_calibration(recording, tmp_path):
    """With a calibration other than the identity the exported value is gain·(raw − offset),
    the very float64 the analyzer computes from the archived sample."""
    config = load_mill_config(MILL)
    speed = config.channels["speed"].model_copy(update={"gain": 2.5, "offset": 0.1})
    config = config.model_copy(update={"channels": {**config.channels, "speed": speed}})
    out = tmp_path / "cal.mcap"
    export_archive([recording[0]], config, out, admit_for, start_ns=T0 + 30 * S, end_ns=T0 + 31 * S,
                   context_s=1.0)  # fmt: skip
    times, values, _ = archived_samples(recording[0])["speed"]
    k0 = times.index(T0 + 30 * S)
    msgs = read_export(out, ["/sag-5200-lrs/samples/speed"])["/sag-5200-lrs/samples/speed"]
    want = 2.5 * (values[k0 : k0 + 1000] - 0.1)
    got = np.array([m[3].value for m in msgs])
    assert got.view(np.uint64).tolist() == want.view(np.uint64).tolist()


def _messages(path) -> dict[str, list[tuple[int, bytes]]]:
    """Every message of an MCAP file per topic, in file order: (log time, bytes)."""
    from mcap.reader import make_reader

    out: dict[str, list[tuple[int, bytes]]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append((message.log_time, message.data))
    return out


@pytest.mark.parametrize("samples", [True, False])
def test_the_commands_batch_reading_writes_what_block_by_block_writes(recording, tmp_path, samples):
    """``millwatch archive export`` reads the archive in batches (regular runs as arrays,
    ``offline_analysis.export_files``): every topic holds exactly the messages, in the same
    order, that the block-by-block reading writes, for a span with edges inside blocks and a
    context (and with a gap and a repeat in the archive, which take the block-by-block path)."""
    from millwatch.worker.offline_analysis import export_files

    messages = list(TailTolerantReader(recording[0]).messages())
    with ArchiveWriter(tmp_path / "archive", "sag") as writer:
        for k, m in enumerate(messages):
            if k not in (5000, 5001):  # a gap on two channels
                writer.write(m.key, m.payload, m.log_time_ns)
            if k == 7000:  # and a repeat
                writer.write(m.key, m.payload, m.log_time_ns)
    files = recording_files(tmp_path / "archive")
    config = load_mill_config(MILL)
    span = {"start_ns": T0 + 20 * S + 50_000_000, "end_ns": T0 + 140 * S + 30_000_000,
            "context_s": 30.0, "samples": samples}  # fmt: skip
    one = export_archive(files, config, tmp_path / "one.mcap", admit_for, **span)
    batched = export_archive(
        files, config, tmp_path / "batched.mcap", admit_for, **span,
        feed=lambda export, read, advance: export_files(read, config, export, advance),
    )  # fmt: skip
    assert batched.counts == one.counts
    assert (batched.first_sample_ns, batched.last_sample_ns) == (
        one.first_sample_ns, one.last_sample_ns)  # fmt: skip
    want, got = _messages(tmp_path / "one.mcap"), _messages(tmp_path / "batched.mcap")
    assert got.keys() == want.keys() and len(got) >= 15
    for topic in want:
        assert got[topic] == want[topic], topic
