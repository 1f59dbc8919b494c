"""The Foxglove export writer: fixed-width protobuf encodings read back bit for bit by a stock
protobuf decoder, sample times as the analyzer computes them, schema names."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from millwatch.ingest.archive.foxglove_export import (
    DAMAGE_SCHEMA,
    ENVELOPE_SCHEMA,
    SAMPLE_SCHEMA,
    FoxgloveExportWriter,
    encode_doubles,
    encode_samples,
    sample_time_ns,
    sample_times_ns,
)

T0 = 1_704_067_200_000_000_000  # 2024-01-01T00:00:00Z


def _message_class(path: Path, schema: str) -> type:
    """The protobuf class of ``schema`` from the FileDescriptorSet the export file holds."""
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    (data,) = {s.data for s in summary.schemas.values() if s.name == schema}
    pool = descriptor_pool.DescriptorPool()
    for proto in descriptor_pb2.FileDescriptorSet.FromString(data).file:
        pool.Add(proto)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema))


@pytest.fixture(scope="module")
def sample_class(tmp_path_factory: pytest.TempPathFactory) -> type:
    path = tmp_path_factory.mktemp("fx") / "one.mcap"
    with FoxgloveExportWriter(path) as w:
        w.samples("m1", "speed", np.array([T0]), np.array([1.0]))
    return _message_class(path, SAMPLE_SCHEMA)


@given(hnp.arrays(np.float64, st.integers(1, 50), elements=st.floats()))
def test_samples_decode_bit_for_bit(sample_class: type, values: np.ndarray) -> None:
    got = np.array([sample_class.FromString(m).value for m in encode_samples(values)])
    assert got.view(np.uint64).tolist() == values.view(np.uint64).tolist()  # NaN, -0.0 too


def test_multi_field_encoding_puts_each_column_in_its_field() -> None:
    (msg,) = encode_doubles([np.array([1.5]), np.array([-2.0]), np.array([np.nan])])
    assert len(msg) == 27 and msg[0] == 0x09 and msg[9] == 0x11 and msg[18] == 0x19
    assert np.frombuffer(msg[10:18], "<f8")[0] == -2.0


def test_sample_times_follow_the_wire_convention() -> None:
    assert sample_times_ns(T0, 1000.0, 3).tolist() == [T0, T0 + 1_000_000, T0 + 2_000_000]
    assert sample_times_ns(T0, 1000.0, 4, first=2).tolist() == [T0 + 2_000_000, T0 + 3_000_000]
    # 1/3 ms steps: t0 + round(i·1e9/fs), as the analyzer's clock (LoadAnalysis.t_ns)
    assert sample_times_ns(0, 3000.0, 4).tolist() == [0, 333_333, 666_666, 1_000_000]
    assert sample_times_ns(0, 2999.5, 2).tolist() == [0, round(1e9 / 2999.5)]
    for fs in (1000.0, 3000.0, 2999.5):
        assert [sample_time_ns(T0, fs, i) for i in range(7)] == sample_times_ns(T0, fs, 7).tolist()


def test_every_topic_has_its_schema_and_the_time_it_describes(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    with FoxgloveExportWriter(path) as w:
        w.samples("m1", "speed", sample_times_ns(T0, 1000.0, 5), np.arange(5.0))
        w.overview("m1", "speed", T0, np.array([1.0, np.nan, 3.0]))
        w.state("m1", T0, "running")
        w.damage("m1", "pinion_combined", T0 + 7, 1e-9, 2e-9)
        w.event("m1", {"event": "stop", "t_ns": T0 + 5, "end_t_ns": T0 + 9, "sample": 5,
                       "rocking_peak_pct": 40.0}, "stop")  # fmt: skip
        w.alarm("m1", {"kind": "raised", "severity": "alarm", "message": "too high",
                       "t_ns": T0 + 6, "alarm_id": "a1", "rule": "start_peak"})  # fmt: skip
    got: dict[str, list] = {}
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert message.publish_time == message.log_time
            got.setdefault(channel.topic, []).append((schema.name, message.log_time, decoded))
    assert {t: v[0][0] for t, v in got.items()} == {
        "/m1/samples/speed": SAMPLE_SCHEMA, "/m1/overview/speed": ENVELOPE_SCHEMA,
        "/m1/state": "foxglove.KeyValuePair", "/m1/damage/pinion_combined": DAMAGE_SCHEMA,
        "/m1/events": "foxglove.Event", "/m1/log": "foxglove.Log", "/m1/alarms": "foxglove.Log",
    }  # fmt: skip
    assert [(t, d.value) for _, t, d in got["/m1/samples/speed"]] == [
        (T0 + k * 1_000_000, float(k)) for k in range(5)
    ]
    (_, _, env), = got["/m1/overview/speed"]  # fmt: skip
    assert (env.min, env.max, env.mean) == (1.0, 3.0, 2.0)
    (_, t, event), = got["/m1/events"]  # fmt: skip
    meta = {kv.key: kv.value for kv in event.metadata}
    assert t == T0 + 5 and event.end_time.nanos == (T0 + 9) % 10**9
    assert meta["rocking_peak_pct"] == "40" and "sample" not in meta
    (_, t, alarm), = got["/m1/alarms"]  # fmt: skip
    assert t == T0 + 6 and alarm.name == "start_peak" and "too high" in alarm.message
    assert alarm.level == 4  # foxglove.Log.Level.ERROR for severity "alarm"


def test_every_chunk_is_indexed_as_foxglove_reads_it(tmp_path: Path) -> None:
    """Foxglove opens MCAP through an indexed reader that refuses a chunk with messages but no
    message index: every chunk index of an export points at message indexes, in time order."""
    path = tmp_path / "x.mcap"
    with FoxgloveExportWriter(path) as w:
        w.samples("m1", "speed", sample_times_ns(T0, 1000.0, 200_000), np.zeros(200_000))
        w.state("m1", T0, "running")
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 1
    for index in summary.chunk_indexes:
        assert index.message_index_length > 0 and index.message_index_offsets
        assert index.message_start_time <= index.message_end_time
