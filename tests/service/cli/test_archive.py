"""``millwatch archive info|recover``: describe files, recover one truncated mid-chunk."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import pytest
from mcap.opcode import Opcode
from mcap.reader import make_reader

from millwatch.cli.main import main
from millwatch.ingest.archive.files import MCAP_MAGIC, list_archive_files
from millwatch.ingest.archive.writer import ArchiveWriter
from tests.ingest.test_replay import KEYS, MS, T0, write_archive

RECORD_HEAD = struct.Struct("<BQ")


def chunk_spans(data: bytes) -> list[tuple[int, int]]:
    """(start, end) byte offsets of the top-level chunk records of an MCAP file."""
    spans, pos = [], len(MCAP_MAGIC)
    for _ in range(100_000):  # bounded walk over the records
        if pos + RECORD_HEAD.size > len(data):
            break
        opcode, length = RECORD_HEAD.unpack_from(data, pos)
        end = pos + RECORD_HEAD.size + length
        if opcode == Opcode.CHUNK:
            spans.append((pos, end))
        if opcode == Opcode.FOOTER:
            break
        pos = end
    return spans


@pytest.fixture
def archive_file(tmp_path: Path) -> tuple[Path, list[tuple[str, int, bytes]]]:
    written = write_archive(tmp_path / "a", 300, chunk_size=2048)
    (path,) = list_archive_files(tmp_path / "a", "m1")
    return path, written


@pytest.fixture
def truncated(
    tmp_path: Path, archive_file: tuple[Path, list[tuple[str, int, bytes]]]
) -> tuple[Path, int]:
    """The archive cut in the middle of its third chunk; returns (file, cut offset)."""
    path, _ = archive_file
    data = path.read_bytes()
    spans = chunk_spans(data)
    assert len(spans) > 4
    start, end = spans[2]
    cut = (start + end) // 2
    torn = tmp_path / "torn.mcap"
    torn.write_bytes(data[:cut])
    return torn, cut


def standard_messages(path: Path) -> list[tuple[str, int, bytes]]:
    with open(path, "rb") as stream:
        return [
            (channel.topic, message.log_time, message.data)
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)
        ]


def test_info_of_a_finished_file(
    archive_file: tuple[Path, list[tuple[str, int, bytes]]], capsys: pytest.CaptureFixture[str]
) -> None:
    path, written = archive_file
    assert main(["archive", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"{path}: finished" in out
    assert "300 messages on 3 channels" in out
    assert "2025-11-21T23:30:00.000Z .. 2025-11-21T23:30:00.598Z" in out
    assert all(f"{key}  100" in out for key in KEYS)
    assert main(["archive", "info", str(path), "--json"]) == 0
    (info,) = json.loads(capsys.readouterr().out)
    assert info["finished"] and info["torn_bytes"] == 0
    assert info["first_log_time_ns"] == T0 and info["last_log_time_ns"] == written[-1][1]


def test_info_of_a_file_truncated_mid_chunk(
    truncated: tuple[Path, int], capsys: pytest.CaptureFixture[str]
) -> None:
    torn, cut = truncated
    assert main(["archive", "info", str(torn), "--json"]) == 1  # 1: found a problem
    (info,) = json.loads(capsys.readouterr().out)
    assert not info["finished"] and 0 < info["torn_bytes"] < cut
    assert 0 < info["messages"] < 300 and "torn" in info["error"]
    assert main(["archive", "info", str(torn)]) == 1
    assert "archive recover" in capsys.readouterr().out


def test_info_counts_what_is_readable_not_what_the_summary_claims(
    archive_file: tuple[Path, list[tuple[str, int, bytes]]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A finished file whose third chunk was never written whole (what a writer that counted
    the writes a full disk refused left: issue 26 measured a summary of 6,000 messages over
    3,957 readable ones): info reports the readable count and the summary's, exit 1."""
    path, written = archive_file
    data = bytearray(path.read_bytes())
    start, end = chunk_spans(bytes(data))[2]
    data[(start + end) // 2 : end] = bytes(end - (start + end) // 2)  # zeros where data was
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    assert main(["archive", "info", str(bad), "--json"]) == 1
    (info,) = json.loads(capsys.readouterr().out)
    assert info["finished"] and info["summary_messages"] == len(written) == 300
    assert 0 < info["messages"] < 300 and sum(info["messages_by_channel"].values()) < 300
    assert f"its summary states 300 messages, {info['messages']} are readable" in info["error"]
    assert main(["archive", "info", str(bad)]) == 1
    assert "BUT its summary states 300" in capsys.readouterr().out
    assert main(["archive", "info", str(path), "--json"]) == 0  # (the intact file: no error)
    (info,) = json.loads(capsys.readouterr().out)
    assert info["messages"] == info["summary_messages"] == 300 and info["error"] is None


def test_recover_keeps_every_complete_message_byte_identical(
    archive_file: tuple[Path, list[tuple[str, int, bytes]]],
    truncated: tuple[Path, int],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    _, written = archive_file
    torn, _ = truncated
    out = tmp_path / "fixed.mcap"
    assert main(["archive", "recover", str(torn), "--out", str(out)]) == 0
    summary = capsys.readouterr().out
    assert "recovered" in summary and f"-> {out}" in summary
    kept = standard_messages(out)  # the standard (seeking) reader accepts it now
    assert 0 < len(kept) < 300 and kept == written[: len(kept)]
    assert main(["archive", "info", str(out)]) == 0
    assert main(["archive", "recover", str(torn)]) == 0  # in place
    assert standard_messages(torn) == kept
    capsys.readouterr()
    assert main(["archive", "recover", str(torn)]) == 0
    assert "already finished" in capsys.readouterr().out


def test_archive_errors_name_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"PK\x03\x04 a zip, not an archive")
    existing = tmp_path / "exists.mcap"
    with ArchiveWriter(tmp_path, "x") as writer:
        writer.write(KEYS[0], b"payload", T0)
    existing.write_bytes(b"keep me")
    good = str(list_archive_files(tmp_path, "x")[0])
    cases = [
        (["info", str(tmp_path / "missing.mcap")], "missing.mcap: no such file"),
        (["info", good, str(bad)], "bad.mcap: not an MCAP file"),
        (["recover", str(bad)], "bad.mcap: not an MCAP file"),
        (["recover", good, "--out", str(existing)], "exists.mcap: file exists"),
    ]
    for args, message in cases:
        assert main(["archive", *args]) == 2
        assert message in capsys.readouterr().err
    assert existing.read_bytes() == b"keep me"


def test_info_gives_each_channels_sample_time_span_rate_dtype_and_unit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The log time is when a block was received; info also says what the blocks hold: the
    first and last sample time, the count, the rate, the sample type and the unit."""
    from millwatch.cli.simulate import DEFAULT_MILL
    from millwatch.ingest.mill_files import load_mill_config

    out, truth = tmp_path / "s.mcap", tmp_path / "t.json"
    assert main(["simulate", "--scene", "steady", "--duration", "5s", "--dtype", "float32",
                 "--out", str(out), "--truth", str(truth), "--no-progress"]) == 0  # fmt: skip
    t0 = json.loads(truth.read_text())["t0_ns"]
    capsys.readouterr()
    assert main(["archive", "info", str(out), "--json"]) == 0
    (info,) = json.loads(capsys.readouterr().out)
    config = load_mill_config(DEFAULT_MILL)
    spans = info["samples_by_channel"]
    assert len(spans) == len(config.channels)
    for name, ch in config.channels.items():
        (span,) = [v for k, v in spans.items() if k.endswith(f"/{name}")]
        assert span["first_sample_ns"] == t0
        assert span["last_sample_ns"] == t0 + 4_999_000_000  # sample 4999 at 1 kHz
        assert span["samples"] == 5000 and span["rates_hz"] == [1000.0]
        assert span["dtypes"] == ["float32"] and span["units"] == [ch.units]
    assert info["first_log_time_ns"] > t0  # received when a block was complete
    assert main(["archive", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "(sample time), 5000 samples at 1000 Hz, float32, kN·m" in text


def test_info_counts_blocks_whose_header_does_not_decode(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from tests.ingest.test_replay import payload

    key = KEYS[0]
    with ArchiveWriter(tmp_path, "bad") as writer:
        for i in range(3):
            writer.write(key, payload(i), T0 + i)
        writer.write(key, b"MWBK but nothing else", T0 + 3)
    (path,) = list_archive_files(tmp_path, "bad")
    assert main(["archive", "info", str(path), "--json"]) == 0
    (info,) = json.loads(capsys.readouterr().out)
    span = info["samples_by_channel"][key]
    assert span["undecodable_blocks"] == 1 and span["samples"] == 30
    assert span["first_sample_ns"] == T0 and span["last_sample_ns"] == T0 + 4 * MS + 9 * MS
    assert main(["archive", "info", str(path)]) == 0
    assert "; 1 blocks undecodable" in capsys.readouterr().out
