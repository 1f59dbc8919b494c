"""``millwatch replay``: time arguments, a real replay over loopback zenoh, and clear errors.

The command runs in-process (``millwatch.cli.main.main``) and dials the test's listening session on
a free 127.0.0.1 port; it never touches the default endpoint. Every wait is bounded.
"""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from pathlib import Path

import pytest

from millwatch.cli.main import main
from millwatch.cli.replay import default_run_name, utc_time_ns
from millwatch.ingest import keys
from tests.ingest.test_replay import KEYS, MS, T0, by_key, leftovers, loopback, write_archive

ISO_T0 = "2025-11-21T23:30:00Z"


def test_times_are_iso_utc_or_ns() -> None:
    assert utc_time_ns(ISO_T0) == T0
    assert utc_time_ns(str(T0)) == T0
    assert utc_time_ns("2025-11-21T23:30:00.123456Z") == T0 + 123_456_000
    assert utc_time_ns("2025-11-22T00:30:00+01:00") == T0
    assert utc_time_ns("1970-01-01T00:00:00Z") == 0
    for bad in ("2025-11-21T23:30:00", "yesterday", "-5", str(2**63)):
        with pytest.raises(argparse.ArgumentTypeError):
            utc_time_ns(bad)


def test_default_run_name_is_a_valid_run_segment() -> None:
    name = default_run_name(datetime(2026, 11, 21, 23, 30, tzinfo=UTC))
    assert name == "r20261121t233000"
    assert keys.parse_key(keys.to_replay(KEYS[0], name)).replay_run == name


def _replay(args: list[str], endpoint: str) -> list[str]:
    return ["replay", *args, "--connect", endpoint, "--no-progress", "--wait-subscribers", "5"]


def test_replay_filters_by_time_and_keys_over_loopback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    written = write_archive(tmp_path, 300)
    start, end = T0 + 100 * MS, T0 + 400 * MS
    pattern = "millwatch/v1/s1/*/speed"
    expected = [
        (keys.to_replay(k, "c1"), p)
        for k, t, p in written
        if start <= t < end and keys.key_matches(pattern, k)
    ]
    with loopback() as net:
        subscriber = net.subscribe(keys.replay_pattern("c1"))
        args = [str(tmp_path), "--max", "--run", "c1", "--from", str(start), "--to",
                "2025-11-21T23:30:00.400Z", "--keys", pattern]  # fmt: skip
        assert main(_replay(args, net.endpoint)) == 0
        received = net.drain(len(expected))
        extra = leftovers(net.inbox)
        subscriber.undeclare()
    assert by_key(received) == by_key(expected) and extra == []
    out = capsys.readouterr()
    assert f"replayed {len(expected)} blocks" in out.out
    assert keys.replay_pattern("c1") in out.err


def test_replay_json_report_and_live_remap_to_a_test_site(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    written = write_archive(tmp_path, 120)  # log times span 0.238 s
    lab = "millwatch/v1/lab/*/*"
    with loopback() as net:
        subscriber = net.subscribe(lab)
        args = [str(tmp_path), "--speed", "4", "--remap", "millwatch/v1/lab", "--json"]
        assert main(_replay(args, net.endpoint)) == 0
        received = net.drain(len(written))
        subscriber.undeclare()
    assert {k for k, _ in received} == {keys.build_key("lab", "m1", s.signal) for s in
                                        map(keys.parse_key, KEYS)}  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["blocks"] == 120 and report["subscription"] == lab
    assert report["x_real_time"] == pytest.approx(4.0, rel=0.25)


def test_nothing_matched_is_exit_status_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_archive(tmp_path, 30)
    with loopback() as net:
        args = [str(tmp_path), "--max", "--from", "2030-01-01T00:00:00Z"]
        assert main([*_replay(args, net.endpoint), "--wait-subscribers", "0"]) == 1
    assert "no archived block matched" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{d}/missing.mcap"], "missing.mcap: no such file"),
        (["{d}/notes.mcap"], "notes.mcap: not an MCAP file"),
        (["{d}/notes.txt"], "notes.txt: expected a .mcap file"),
        (["{d}/a", "--from", "2025-11-21T23:31:00Z", "--to", ISO_T0], "--from"),
        (["{d}/a", "--connect", "127.0.0.1:7447"], "expected '<proto>/<address>'"),
    ],
)
def test_bad_inputs_exit_2_naming_the_file_or_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    write_archive(tmp_path / "a", 3)
    (tmp_path / "notes.mcap").write_text("not an archive")
    (tmp_path / "notes.txt").write_text("not an archive")
    argv = ["replay", *[a.format(d=tmp_path) for a in args], "--no-progress"]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--speed", "0"], "--speed"),
        (["--speed", "2", "--max"], "not allowed with argument"),
        (["--from", "yesterday"], "--from"),
        (["--to", "2025-11-21T23:30:00"], "no time zone"),
        (["--keys", "millwatch/v1/s$*/**"], "--keys"),
        (["--keys", "millwatch//v1"], "--keys"),
        (["--keys", "millwatch/v1/*_torque"], "may only be preceded by"),
        (["--run", "Run 1"], "--run"),
        (["--remap", "elsewhere/x"], "--remap"),
        (["--run", "r1", "--remap", "millwatch/v1/lab"], "not allowed with argument"),
    ],
)
def test_bad_options_are_argparse_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["replay", str(tmp_path), *args])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_replay_restarted_on_its_spool_resumes_after_its_last_spooled_block(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Nothing falls due while a replay is down: restarted with the same ``--spool``, it goes
    on after the last block its spool holds per key, each block published once."""
    written = write_archive(tmp_path / "a", 120)
    spool = str(tmp_path / "spool")
    with loopback() as net:
        subscriber = net.subscribe(keys.replay_pattern("c1"))
        common = [str(tmp_path / "a"), "--max", "--run", "c1", "--spool", spool, "--json"]
        assert main(_replay([*common, "--to", str(T0 + 100 * MS)], net.endpoint)) == 0
        first = json.loads(capsys.readouterr().out)["blocks"]
        assert main(_replay(common, net.endpoint)) == 0
        out = capsys.readouterr()
        received = net.drain(len(written))
        extra = leftovers(net.inbox)
        subscriber.undeclare()
    assert first == 50 and json.loads(out.out)["blocks"] == len(written) - first
    assert "50 blocks were in --spool already" in out.err
    assert by_key(received) == by_key([(keys.to_replay(k, "c1"), p) for k, _, p in written])
    assert extra == []
