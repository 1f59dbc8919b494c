"""Service settings: defaults, relative paths, and errors that name the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from millwatch.api.identity import ApiIdentity, ApiKeys
from millwatch.settings import ServiceSettings, SettingsError, load_service_settings

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"


def test_paths_are_relative_to_the_settings_file(tmp_path):
    path = tmp_path / "plant" / "millwatch.toml"
    path.parent.mkdir()
    path.write_text(
        '[archive]\ndirectory = "archive"\n[store]\npath = "db/mw.db"\n'
        f'[mills]\ndirectory = "{MILLS}"\n'
    )
    s = load_service_settings(path)
    assert s.archive.directory == (path.parent / "archive").resolve()
    assert s.store.path == (path.parent / "db" / "mw.db").resolve()
    assert {"sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"} <= set(s.load_mills())
    assert s.zenoh.listen == ("tcp/127.0.0.1:7447",)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[archive]\nrotate_seconds = -1\n", "archive.rotate_seconds"),
        ("[worker]\nqueue = 5\n", "worker.queue"),
        ("[zenoh\n", "TOML syntax error"),
        ("[worker]\nmax_ahead_s = 0.5\n", r"worker\.max_ahead_s: 0\.5 s is out of range"),
        ("[worker]\nmax_ahead_s = nan\n", r"worker\.max_ahead_s: nan s is out of range"),
        ("[worker]\nmax_ahead_s = 1e6\n", r"worker\.max_ahead_s: 1000000\.0 s"),
        ("[worker]\nmax_block_bytes = 100\n", r"worker\.max_block_bytes: 100 bytes is out"),
        ("[worker]\nmax_block_bytes = 4294967296\n", r"worker\.max_block_bytes: 4294967296"),
    ],
)
def test_errors_name_the_file_and_field(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SettingsError, match=message) as err:
        load_service_settings(path)
    assert str(path) in str(err.value)


def test_admission_limits_come_from_the_worker_section(tmp_path):
    path = tmp_path / "ok.toml"
    path.write_text("[worker]\nmax_ahead_s = 5\nmax_block_bytes = 65536\n")
    worker = load_service_settings(path).worker
    assert (worker.max_ahead_s, worker.max_block_bytes) == (5.0, 65536)
    assert (ServiceSettings().worker.max_ahead_s, ServiceSettings().worker.max_block_bytes) == (
        60.0,
        2**20,
    )


def test_no_mill_configured_is_an_error():
    with pytest.raises(SettingsError, match="no mill configured"):
        ServiceSettings().load_mills()


def test_the_same_mill_twice_is_an_error():
    twice = ServiceSettings.model_validate(
        {"mills": {"files": [str(MILLS / "sag-5200-lrs.toml")] * 2}}
    )
    with pytest.raises(SettingsError, match="configured twice"):
        twice.load_mills()


MAIL = '[reports.mail]\nhost = "smtp.plant"\nsender = "mw@plant"\nrecipients = ["m@plant"]\n'


def test_report_paths_and_the_secret_file_are_relative_to_the_settings_file(tmp_path, monkeypatch):
    path = tmp_path / "millwatch.toml"
    path.write_text('[reports]\ndirectory = "out"\n' + MAIL +
                    'username = "mw"\npassword_file = "secret"\n')  # fmt: skip
    (tmp_path / "secret").write_text("pw-from-file\n")
    monkeypatch.setenv("MILLWATCH_SMTP_PASSWORD", "pw-from-env")
    s = load_service_settings(path)
    assert s.reports.directory == (tmp_path / "out").resolve()
    assert s.reports.mail.password_file == (tmp_path / "secret").resolve()
    assert s.reports.mail.password() == "pw-from-file"  # the file wins, newline dropped
    assert "pw-from" not in repr(s)  # the settings never hold the password
    env_only = s.reports.mail.model_copy(update={"password_file": None})
    assert env_only.password() == "pw-from-env"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ('password = "hunter2"\n', "password: not in the settings file"),
        ('username = "mw"\nstarttls = false\n', "password in clear text"),
        ('attach = ["doc"]\n', "'doc' is not one of html, pdf, csv"),
    ],
)
def test_mail_settings_refuse_a_password_in_the_file_and_clear_text_logins(
    tmp_path, extra, message
):
    path = tmp_path / "millwatch.toml"
    path.write_text(MAIL + extra)
    with pytest.raises(SettingsError, match=r"reports\.mail") as err:
        load_service_settings(path)
    assert message in str(err.value) and "hunter2" not in str(err.value)


def test_opcua_is_off_by_default_on_loopback_with_basic256sha256_offered():
    o = ServiceSettings().opcua
    assert not o.enabled and not o.anonymous
    assert o.endpoint == "opc.tcp://127.0.0.1:4840/millwatch"
    assert "Basic256Sha256_SignAndEncrypt" in o.security and "None" in o.security


def test_opcua_password_files_are_relative_and_never_held(tmp_path, monkeypatch):
    path = tmp_path / "millwatch.toml"
    path.write_text(
        '[opcua]\nenabled = true\ncertificate_dir = "pki"\n'
        '[[opcua.users]]\nname = "operator"\npassword_file = "op.secret"\n'
        '[[opcua.users]]\nname = "hmi"\npassword_env = "HMI_PW"\nrole = "viewer"\n'
    )
    (tmp_path / "op.secret").write_text("op-pw\n")
    monkeypatch.setenv("HMI_PW", "hmi-pw")
    s = load_service_settings(path)
    op, hmi = s.opcua.users
    assert op.password_file == (tmp_path / "op.secret").resolve()
    assert s.opcua.certificate_dir == (tmp_path / "pki").resolve()
    assert (op.password(), hmi.password(), hmi.role) == ("op-pw", "hmi-pw", "viewer")
    assert "-pw" not in repr(s)


@pytest.mark.parametrize(
    ("users", "message"),
    [
        ('name = "op"\npassword = "hunter2"\n', "password: not in the settings file"),
        ('name = "op"\n', "set password_file or password_env"),
        ('name = "op"\npassword_env = "X"\nrole = "admin"\n', "opcua.users.0.role"),
    ],
)
def test_opcua_users_refuse_passwords_in_the_file_and_name_the_field(tmp_path, users, message):
    path = tmp_path / "millwatch.toml"
    path.write_text("[opcua]\nenabled = true\n[[opcua.users]]\n" + users)
    with pytest.raises(SettingsError, match=r"opcua\.users") as err:
        load_service_settings(path)
    assert message in str(err.value) and "hunter2" not in str(err.value)


def test_opcua_endpoint_must_be_opc_tcp(tmp_path):
    path = tmp_path / "millwatch.toml"
    path.write_text('[opcua]\nendpoint = "http://127.0.0.1:4840"\n')
    with pytest.raises(SettingsError, match=r"opcua\.endpoint"):
        load_service_settings(path)


@pytest.mark.parametrize(
    ("zenoh", "message"),
    [
        ('listen = ["tcp/0.0.0.0:7447"]', "reachable from other hosts without TLS"),
        ('mode = "client"\nconnect = ["tcp/10.1.2.3:7447"]', "'tcp/10.1.2.3:7447'"),
        ('mode = "client"\nconnect = ["tcp/router.plant:7447"]', "plain_beyond_loopback"),
        ('mode = "client"\nconnect = ["tls/router.plant:7447"]', "needs [zenoh.tls]"),
    ],
)
def test_zenoh_endpoints_beyond_loopback_need_tls_unless_said_otherwise(tmp_path, zenoh, message):
    path = tmp_path / "s.toml"
    path.write_text(f"[zenoh]\n{zenoh}\n")
    with pytest.raises(SettingsError, match="zenoh") as err:
        load_service_settings(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_zenoh_tls_files_are_relative_to_the_settings_file_and_plain_is_a_choice(tmp_path):
    path = tmp_path / "plant" / "s.toml"
    path.parent.mkdir()
    path.write_text(
        '[zenoh]\nmode = "client"\nconnect = ["tls/router.plant:7447"]\n'
        '[zenoh.tls]\ndirectory = "tls"\nname = "worker"\n'
    )
    tls = load_service_settings(path).zenoh.tls
    assert tls is not None
    files = tls.files()
    assert files.ca == path.parent / "tls" / "ca.pem"
    assert files.certificate == path.parent / "tls" / "worker.pem"
    assert files.private_key == path.parent / "tls" / "worker-key.pem"
    path.write_text('[zenoh]\nlisten = ["tcp/0.0.0.0:7447"]\nplain_beyond_loopback = true\n')
    assert load_service_settings(path).zenoh.listen == ("tcp/0.0.0.0:7447",)


def test_api_user_keys_are_relative_never_held_and_name_their_user(tmp_path, monkeypatch):
    path = tmp_path / "millwatch.toml"
    path.write_text(
        '[api]\napi_key = "shared-key"\nmax_shelve_s = 3600\n'
        '[[api.users]]\nname = "j.perez"\nkey_file = "keys/j.perez"\n'
        '[[api.users]]\nname = "wall"\nkey_env = "WALL_KEY"\nrole = "viewer"\n'
    )
    (tmp_path / "keys").mkdir()
    (tmp_path / "keys" / "j.perez").write_text("perez-key-0123456789\n")
    monkeypatch.setenv("WALL_KEY", "wall-key-0123456789ab")
    s = load_service_settings(path)
    op, wall = s.api.users
    assert op.key_file == (tmp_path / "keys" / "j.perez").resolve()
    assert (op.key(), wall.key(), wall.role, s.api.max_shelve_s) == (
        "perez-key-0123456789", "wall-key-0123456789ab", "viewer", 3600.0)  # fmt: skip
    assert "-key-" not in repr(s)
    keys = ApiKeys.from_settings(s.api)
    assert keys.find("perez-key-0123456789") == ApiIdentity("j.perez", "operator", False)
    assert keys.find("shared-key") == ApiIdentity("api", "operator", True)
    assert keys.find("wall-key-0123456789ab").role == "viewer" and keys.find("x") is None
    monkeypatch.delenv("WALL_KEY")
    with pytest.raises(SettingsError, match=r"api\.users\.wall: key_env WALL_KEY holds no key"):
        ApiKeys.from_settings(s.api)
    (tmp_path / "keys" / "j.perez").write_text("short")
    monkeypatch.setenv("WALL_KEY", "wall-key-0123456789ab")
    with pytest.raises(SettingsError, match=r"api\.users\.j\.perez: the key in key_file .* is 5 "):
        ApiKeys.from_settings(s.api)
    (tmp_path / "keys" / "j.perez").write_text("wall-key-0123456789ab")
    with pytest.raises(SettingsError, match="share a key"):
        ApiKeys.from_settings(s.api)


@pytest.mark.parametrize(
    ("users", "message"),
    [
        ('name = "op"\nkey = "hunter2"\n', "key: not in the settings file"),
        ('name = "op"\n', "set key_file or key_env"),
        ('name = "op"\nkey_env = "X"\nrole = "admin"\n', "api.users.0.role"),
        ('name = "op"\nkey_env = "X"\n[[api.users]]\nname = "op"\nkey_env = "Y"\n',
         "user 'op' is configured twice"),
    ],
)  # fmt: skip
def test_api_users_refuse_keys_in_the_file_and_name_the_field(tmp_path, users, message):
    path = tmp_path / "millwatch.toml"
    path.write_text("[[api.users]]\n" + users)
    with pytest.raises(SettingsError, match=r"api\.users") as err:
        load_service_settings(path)
    assert message in str(err.value) and "hunter2" not in str(err.value)


def test_the_longest_shelve_is_bounded(tmp_path):
    path = tmp_path / "millwatch.toml"
    path.write_text("[api]\nmax_shelve_s = 864000\n")
    with pytest.raises(SettingsError, match=r"api\.max_shelve_s"):
        load_service_settings(path)


@pytest.mark.parametrize("value", ['"yes"', '"true"', "1", "0"])
def test_standby_is_a_boolean_nothing_else(tmp_path, value):
    path = tmp_path / "standby.toml"
    path.write_text(f"[worker]\nstandby = {value}\n")
    with pytest.raises(SettingsError, match=r"worker\.standby: .* is not a boolean"):
        load_service_settings(path)
    path.write_text("[worker]\nstandby = true\n")
    assert load_service_settings(path).worker.standby is True
    assert ServiceSettings().worker.standby is False
