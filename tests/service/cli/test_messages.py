"""User errors of the long-running commands are one line naming the file, the field and the
value — no traceback, and for ``serve`` before its banner — and ``serve`` says ``ready`` once it
serves (issue 26 deliverable 7). Real ``millwatch`` processes."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint

ROOT = Path(__file__).resolve().parents[3]
MILL_FILE = ROOT / "deploy" / "mills" / "sag-5200-lrs.toml"


def _run(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "millwatch.cli.main", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)  # fmt: skip


def _settings(directory: Path, mill: Path, store: str = "mw.db", port: int = 0) -> Path:
    path = directory / "plant.toml"
    path.write_text(
        f'[zenoh]\nlisten = []\n[archive]\ndirectory = "archive"\n[store]\npath = "{store}"\n'
        f"[worker]\ngateway_wait_s = 0\n[reports]\nenabled = false\n"
        f"[api]\nport = {port or free_loopback_port()}\n"
        f"[mills]\nfiles = [{json.dumps(str(mill))}]\n",
        encoding="utf-8",
    )
    return path


def _edited_mill(directory: Path, old: str, new: str) -> Path:
    text = MILL_FILE.read_text()
    assert old in text
    path = directory / "edited.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def _one_line_error(run: subprocess.CompletedProcess[str]) -> str:
    """The error line of a command that failed as a user error (exit 2, nothing else said)."""
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr, run.stderr
    lines = [ln for ln in run.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("millwatch: error: "), run.stderr
    return lines[0]


@pytest.mark.parametrize(
    ("old", "new", "said"),
    [
        ('key = "speed"', 'key = "Speed rpm"', "channels.speed.key: must be lower-case letters, "
         "digits, '_' and '-', in segments separated by '/', each starting with a letter or "
         "digit, got 'Speed rpm'"),
        ('key = "speed"', 'key = "motor_torque"', "channels.motor_torque.key and "
         "channels.speed.key are both 'motor_torque': each channel needs a key of its own"),
        ("reducer_ratio = 5.65", "reducer_ratio = -5.65", "drive.reducer_ratio: must be > 0.0, "
         "got -5.65"),
    ],
)  # fmt: skip
def test_serve_names_the_mill_file_field_and_value_before_its_banner(
    tmp_path: Path, old: str, new: str, said: str
) -> None:
    mill = _edited_mill(tmp_path, old, new)
    line = _one_line_error(_run("serve", "--config", str(_settings(tmp_path, mill))))
    assert line.startswith(f"millwatch: error: {mill}: ") and said in line


def test_serve_names_a_store_path_it_cannot_create(tmp_path: Path) -> None:
    (tmp_path / "afile").write_text("not a directory")
    settings = _settings(tmp_path, MILL_FILE, store="afile/mw.db")
    line = _one_line_error(_run("serve", "--config", str(settings)))
    assert line == (
        f"millwatch: error: {settings}: store.path = '{tmp_path / 'afile' / 'mw.db'}': "
        f"{tmp_path / 'afile'} is a file, not a directory"
    )


def test_serve_names_a_bad_zenoh_endpoint_and_a_settings_file_without_mills(
    tmp_path: Path,
) -> None:
    settings = _settings(tmp_path, MILL_FILE)
    settings.write_text(
        settings.read_text().replace("listen = []", 'listen = ["tcp/127.0.0.1:99999"]')
    )
    line = _one_line_error(_run("serve", "--config", str(settings)))
    assert line == (f"millwatch: error: {settings}: zenoh: listen endpoint 'tcp/127.0.0.1:99999': "
                    "the port must be a number 1..65535, got '99999'")  # fmt: skip
    empty = tmp_path / "empty.toml"
    empty.write_text("[worker]\ncheckpoint_seconds = 30\n")
    line = _one_line_error(_run("serve", "--config", str(empty)))
    assert line == (f"millwatch: error: {empty}: mills: no mill configured (set mills.files or "
                    "mills.directory)")  # fmt: skip


def test_serve_names_a_store_file_that_is_not_a_store(tmp_path: Path) -> None:
    (tmp_path / "mw.db").write_text("minutes of the shift meeting")
    settings = _settings(tmp_path, MILL_FILE)
    line = _one_line_error(_run("serve", "--config", str(settings)))
    assert line == (f"millwatch: error: {settings}: store.path: {tmp_path / 'mw.db'}: cannot open "
                    "the store (file is not a database)")  # fmt: skip


def test_serve_names_an_unreadable_secret_file_before_its_banner(tmp_path: Path) -> None:
    settings = _settings(tmp_path, MILL_FILE)
    with settings.open("a") as f:
        f.write('[opcua]\nenabled = true\n[[opcua.users]]\nname = "operator"\n'
                f'password_file = "{tmp_path / "no-such-secret"}"\n')  # fmt: skip
    line = _one_line_error(_run("serve", "--config", str(settings)))
    assert line == (f"millwatch: error: {settings}: opcua.users.operator: cannot read "
                    f"{tmp_path / 'no-such-secret'} (No such file or directory)")  # fmt: skip


def test_serve_names_an_api_user_whose_key_is_unset_before_its_banner(tmp_path: Path) -> None:
    settings = _settings(tmp_path, MILL_FILE)
    with settings.open("a") as f:
        f.write('[[api.users]]\nname = "j.perez"\nkey_env = "MILLWATCH_TEST_UNSET_KEY"\n')
    line = _one_line_error(_run("serve", "--config", str(settings)))
    assert line == (f"millwatch: error: {settings}: api.users.j.perez: key_env "
                    "MILLWATCH_TEST_UNSET_KEY holds no key")  # fmt: skip


def test_serve_names_an_api_port_in_use(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        settings = _settings(tmp_path, MILL_FILE, port=port)
        line = _one_line_error(_run("serve", "--config", str(settings)))
    assert line.startswith(f"millwatch: error: {settings}: api.port = {port} (on 127.0.0.1): "
                           "cannot listen there (Address already in use)")  # fmt: skip


def test_simulate_publish_on_a_busy_port_is_one_line(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        endpoint = tcp_endpoint(busy.getsockname()[1])
        run = _run("simulate", "--scene", "start-lrs", "--duration", "2s", "--publish",
                   "--listen", endpoint, "--no-progress")  # fmt: skip
    line = _one_line_error(run)
    assert line.startswith(f"millwatch: error: cannot listen on {endpoint}: Address already in use")


def test_serve_prints_its_banner_then_ready_once_serving(tmp_path: Path) -> None:
    settings = _settings(tmp_path, MILL_FILE)
    argv = [sys.executable, "-m", "millwatch.cli.main", "serve", "--config", str(settings)]
    proc = subprocess.Popen(argv, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + 90.0
        for _ in range(200):  # (bounded: a line at a time until ready, or the process ends)
            line = proc.stderr.readline()
            lines.append(line)
            if not line or line.startswith("millwatch serve: ready") or time.monotonic() > deadline:
                break
    finally:
        proc.send_signal(signal.SIGTERM)
        _, rest = proc.communicate(timeout=60)
    assert proc.returncode == 0, "".join(lines) + rest
    assert lines[0].startswith("millwatch serve: worker ")
    assert lines[-1].startswith("millwatch serve: ready; 1 of 1 mill(s) analysed; API on "
                                "http://127.0.0.1:")  # fmt: skip
    assert "Traceback" not in "".join(lines) + rest


def _ignore_ctrl_c() -> None:  # (runs in the child before exec: what nohup-like parents do)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def test_ctrl_c_stops_a_gateway_whose_parent_ignored_it(tmp_path: Path) -> None:
    """A parent that ignores SIGINT hands that on to its children, and Python then installs no
    KeyboardInterrupt handler: ``simulate --publish`` ("Ctrl-C stops") kept publishing for ever
    (the spool-recovery tests' gateways, launched from the test run, did not stop)."""
    port = free_loopback_port()
    argv = [sys.executable, "-m", "millwatch.cli.main", "simulate", "--scene", "start-lrs",
            "--mill", str(MILL_FILE), "--duration", "300s", "--no-progress", "--publish",
            "--listen", tcp_endpoint(port), "--spool", str(tmp_path / "spool")]  # fmt: skip
    proc = subprocess.Popen(argv, cwd=ROOT, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_ignore_ctrl_c)  # fmt: skip
    try:
        assert proc.stderr is not None
        first = proc.stderr.readline()  # "publishing …; Ctrl-C stops" once it publishes
        assert first.startswith("publishing "), first
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
    assert proc.returncode == 130, rest
    assert "Traceback" not in rest, rest
