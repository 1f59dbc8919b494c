"""Workers split the mills by zenoh key expression (``[worker] partition``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from millwatch.ingest.keys import worker_token_key
from millwatch.ingest.mill_files import load_mill_configs
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.settings import ServiceSettings, SettingsError, load_service_settings
from millwatch.worker.partition import check_exclusive, partition_mills, worker_identity

MILLS = load_mill_configs(Path(__file__).resolve().parents[3] / "deploy" / "mills")


@pytest.mark.parametrize(
    ("partition", "expected"),
    [
        ((), {"ball-dual-lrs", "rod-1100-grid", "sag-5200-lrs"}),
        (("millwatch/v1/rustenburg/**",), {"ball-dual-lrs", "sag-5200-lrs"}),
        (("millwatch/v1/carletonville/*/*",), {"rod-1100-grid"}),
        (("millwatch/v1/*/sag-5200-lrs/**",), {"sag-5200-lrs"}),
        (("millwatch/v1/*/sag-5200-lrs/**", "millwatch/v1/carletonville/**"),
         {"sag-5200-lrs", "rod-1100-grid"}),
        (("millwatch/v1/**",), {"ball-dual-lrs", "rod-1100-grid", "sag-5200-lrs"}),
    ],
)  # fmt: skip
def test_a_partition_keeps_the_mills_whose_keys_intersect_it(partition, expected):
    chosen = partition_mills(MILLS, partition)
    assert set(chosen) == expected
    assert list(chosen) == [m for m in MILLS if m in expected]  # configuration order


def test_a_partition_entry_matching_no_mill_is_an_error_naming_it():
    with pytest.raises(SettingsError, match=r"'millwatch/v1/nowhere/\*\*' matches none") as exc:
        partition_mills(MILLS, ("millwatch/v1/rustenburg/**", "millwatch/v1/nowhere/**"))
    assert "rustenburg/sag-5200-lrs" in str(exc.value)


@pytest.mark.parametrize(
    ("partition", "words"),
    [(["millwatch//x"], "not a zenoh key expression"), (["other/**"], "must start with")],
)
def test_settings_refuse_a_malformed_partition(partition, words):
    with pytest.raises(ValueError, match=words):
        ServiceSettings.model_validate({"worker": {"partition": partition}})


def test_worker_name_defaults_to_the_host_name_as_a_key_segment():
    assert worker_identity(ServiceSettings.model_validate({"worker": {"name": "north"}})) == "north"
    name = worker_identity(ServiceSettings())
    assert name and name == name.lower() and "." not in name


def test_a_second_worker_for_the_same_mill_is_refused():
    port = free_loopback_port()
    sag = {"sag-5200-lrs": MILLS["sag-5200-lrs"]}
    router = build_config(mode="router", listen=[tcp_endpoint(port)])
    client = build_config(mode="client", connect=[tcp_endpoint(port)])
    with open_session(router) as first, open_session(client) as second:
        token = first.liveliness().declare_token(
            worker_token_key("rustenburg", "sag-5200-lrs", "north")
        )
        check_exclusive(second, {"rod-1100-grid": MILLS["rod-1100-grid"]}, "south")  # no clash
        check_exclusive(second, sag, "north")  # its own old token (a restart): no clash
        with pytest.raises(SettingsError, match=r"sag-5200-lrs \(worker 'north'\)"):
            check_exclusive(second, sag, "south")
        token.undeclare()


def test_a_hot_standby_shares_the_mills_of_a_primary_but_two_primaries_do_not():
    port = free_loopback_port()
    sag = {"sag-5200-lrs": MILLS["sag-5200-lrs"]}
    router = build_config(mode="router", listen=[tcp_endpoint(port)])
    client = build_config(mode="client", connect=[tcp_endpoint(port)])
    with open_session(router) as first, open_session(client) as second:
        standby = first.liveliness().declare_token(
            worker_token_key("rustenburg", "sag-5200-lrs", "north-standby", standby=True)
        )
        check_exclusive(second, sag, "north")  # a primary starts while its standby holds
        primary = first.liveliness().declare_token(
            worker_token_key("rustenburg", "sag-5200-lrs", "north")
        )
        with pytest.raises(SettingsError, match=r"standby = true"):
            check_exclusive(second, sag, "south")  # a second primary is refused, with the way out
        primary.undeclare()
        standby.undeclare()


def test_the_example_plant_workers_split_the_mills_exactly_once():
    deploy = Path(__file__).resolve().parents[3] / "deploy"
    split, standbys = {}, {}
    for path in sorted(deploy.glob("worker-*.toml")):
        settings = load_service_settings(path)
        mills = set(partition_mills(settings.load_mills(), settings.worker.partition))
        (standbys if settings.worker.standby else split)[settings.worker.name] = mills
    # each primary has a hot standby of exactly its mills (the two-host layout)
    assert {f"{name}-standby": mills for name, mills in split.items()} == standbys
    assert len(split) == 2 and all(split.values())
    assert sorted(m for mills in split.values() for m in mills) == sorted(MILLS)
    api = load_service_settings(deploy / "api.toml")
    assert set(api.load_mills()) == set(MILLS) and api.api.query_timeout_s == 10
