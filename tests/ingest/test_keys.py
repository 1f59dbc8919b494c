"""Key expressions: build/parse pairs, replay tag, patterns, zenoh-compatible matching."""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.ingest.keys import (
    ChannelKey,
    KeyFormatError,
    Side,
    Signal,
    build_key,
    key_matches,
    live_pattern,
    mill_pattern,
    parse_key,
    replay_pattern,
    site_pattern,
    to_live,
    to_replay,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("signal", list(Signal))
@pytest.mark.parametrize("side", [None, *Side])
@pytest.mark.parametrize("run", [None, "r20261121t2330z"])
def test_build_parse_round_trip(signal: Signal, side: Side | None, run: str | None) -> None:
    expr = build_key("site-a", "mill_1", signal, side, replay_run=run)
    key = parse_key(expr)
    assert key == ChannelKey("site-a", "mill_1", signal, side, run)
    assert key.expr == expr == str(key)
    assert key.is_replay is (run is not None)


def test_layout_is_as_documented() -> None:
    assert build_key("s", "m", "pinion_torque", "nbs") == "millwatch/v1/s/m/pinion_torque_nbs"
    assert build_key("s", "m", Signal.SPEED) == "millwatch/v1/s/m/speed"
    replay = build_key("s", "m", "tacho", "bs", replay_run="run7")
    assert replay == "millwatch/v1/@replay/run7/s/m/tacho_bs"


def test_replay_and_live_conversions() -> None:
    live = build_key("s", "m", "motor_torque")
    replay = to_replay(live, "run1")
    assert parse_key(replay).replay_run == "run1"
    assert to_live(replay) == live
    assert to_replay(replay, "run2") == build_key("s", "m", "motor_torque", replay_run="run2")


BAD_KEYS = [
    ("other/v1/s/m/speed", "root"),
    ("millwatch/v2/s/m/speed", "version"),
    ("millwatch", "version"),
    ("millwatch/v1/S/m/speed", "site"),
    ("millwatch/v1/s/m m/speed", "mill"),
    ("millwatch/v1/s/m/torque", "signal"),
    ("millwatch/v1/s/m/speed_left", "signal"),
    ("millwatch/v1/s/m/speed/extra", "key"),
    ("millwatch/v1/s/m", "key"),
    ("millwatch/v1/@replay/s/m/speed", "key"),
    ("millwatch/v1/@replay/Run/s/m/speed", "run"),
    ("millwatch/v1/s/*/speed", "mill"),
]


@pytest.mark.parametrize(("expr", "segment"), BAD_KEYS)
def test_parse_errors_name_the_bad_segment(expr: str, segment: str) -> None:
    with pytest.raises(KeyFormatError) as info:
        parse_key(expr)
    assert info.value.segment == segment
    assert segment in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "segment"),
    [
        ({"site": ""}, "site"),
        ({"mill": "-x"}, "mill"),
        ({"signal": "pinion_torque_nbs"}, "signal"),
        ({"side": "left"}, "side"),
        ({"replay_run": "a/b"}, "run"),
    ],
)
def test_build_errors_name_the_bad_segment(kwargs: dict[str, str], segment: str) -> None:
    args = {"site": "s", "mill": "m", "signal": "speed", "side": None} | kwargs
    run = args.pop("replay_run", None)
    with pytest.raises(KeyFormatError) as info:
        build_key(**args, replay_run=run)
    assert info.value.segment == segment


def test_patterns() -> None:
    assert mill_pattern("s", "m") == "millwatch/v1/s/m/*"
    assert site_pattern("s") == "millwatch/v1/s/*/*"
    assert live_pattern() == "millwatch/v1/*/*/*"
    assert replay_pattern() == "millwatch/v1/@replay/*/*/*/*"
    assert mill_pattern("s", "m", replay_run="r1") == "millwatch/v1/@replay/r1/s/m/*"
    with pytest.raises(KeyFormatError):
        mill_pattern("s", "M")


def test_live_patterns_never_match_replayed_keys() -> None:
    replay = build_key("s", "m", "speed", replay_run="r1")
    for pattern in (live_pattern(), "millwatch/v1/**", "**", site_pattern("s")):
        assert not key_matches(pattern, replay)
    assert key_matches(replay_pattern(), replay)
    assert key_matches("millwatch/v1/@replay/**", replay)


_CHUNKS = st.sampled_from(["millwatch", "v1", "@replay", "s", "m", "speed", "r1"])
_PATTERN_CHUNKS = st.one_of(_CHUNKS, st.just("*"), st.just("**"))


def _no_double_globs(chunks: list[str]) -> bool:
    return all(not (a == b == "**") for a, b in itertools.pairwise(chunks))


@settings(max_examples=300, deadline=None)
@given(
    st.lists(_PATTERN_CHUNKS, min_size=1, max_size=6).filter(_no_double_globs),
    st.lists(_CHUNKS, min_size=1, max_size=6),
)
def test_matching_agrees_with_zenoh(pattern: list[str], key: list[str]) -> None:
    p, k = "/".join(pattern), "/".join(key)
    assert key_matches(p, k) == zenoh.KeyExpr.autocanonize(p).intersects(zenoh.KeyExpr(k))


def test_subchunk_wildcards_are_rejected() -> None:
    with pytest.raises(KeyFormatError):
        key_matches("millwatch/v1/s/m/speed$*", "millwatch/v1/s/m/speed_bs")


_FORMATTED_KEY = re.compile(
    r"""(f["'][^"'\n]*millwatch/|["'][^"'\n]*millwatch/[^"'\n]*["']\s*(%|\.format))"""
)


def _modules_but_keys(found: Callable[[str], object]) -> list[str]:
    """The product's modules other than ``ingest/keys.py`` whose text ``found`` something in."""
    owner = REPO / "ingest" / "keys.py"
    return [
        str(path.relative_to(REPO))
        for package in ("analytics", "ingest", "alarms", "service")
        for path in (REPO / package).rglob("*.py")
        if path != owner and found(path.read_text(encoding="utf-8"))
    ]


def test_no_formatted_keys_outside_the_keys_module() -> None:
    assert _modules_but_keys(_FORMATTED_KEY.search) == []


def test_channel_key_takes_the_mill_config_segment():
    from millwatch.ingest.keys import channel_key

    assert (
        channel_key("plant", "m1", "pinion_torque_nbs") == "millwatch/v1/plant/m1/pinion_torque_nbs"
    )
    assert channel_key("plant", "m1", "speed") == "millwatch/v1/plant/m1/speed"
    with pytest.raises(KeyFormatError) as err:
        channel_key("plant", "m1", "pinion_torque_left")
    assert err.value.segment == "signal"


@pytest.mark.parametrize("pattern", ["millwatch/v1/s1/m1/*_torque", "millwatch/**x/speed"])
def test_partial_chunk_wildcards_are_refused_not_silently_unmatched(pattern):
    with pytest.raises(KeyFormatError, match="must stand alone"):
        key_matches(pattern, "millwatch/v1/s1/m1/pinion_torque")


# ---------------------------------------------------------------- alarm keys
def test_alarm_key_layout_and_parse():
    from millwatch.ingest.keys import alarm_key, alarm_pattern, parse_alarm_key

    key = alarm_key("rustenburg", "sag-5200-lrs")
    assert key == "millwatch/v1/rustenburg/sag-5200-lrs/@alarms"
    assert parse_alarm_key(key) == ("rustenburg", "sag-5200-lrs")
    assert alarm_pattern() == "millwatch/v1/*/*/@alarms"
    assert alarm_pattern("rustenburg") == "millwatch/v1/rustenburg/*/@alarms"
    for pattern in (alarm_pattern(), alarm_pattern("rustenburg"), key):
        assert key_matches(pattern, key)
    with pytest.raises(KeyFormatError) as err:
        alarm_key("rustenburg", "Mill 1")
    assert err.value.segment == "mill"
    with pytest.raises(KeyFormatError):
        parse_key(key)  # not a channel
    for bad in (
        "millwatch/v1/s/m/speed",
        "millwatch/v2/s/m/@alarms",
        "millwatch/v1/@replay/@alarms",
    ):
        with pytest.raises(KeyFormatError):
            parse_alarm_key(bad)


def test_telemetry_and_alarm_subscriptions_never_see_each_other():
    from millwatch.ingest.keys import alarm_key, alarm_pattern

    key = alarm_key("s", "m")
    telemetry = build_key("s", "m", "speed")
    for pattern in (live_pattern(), "millwatch/v1/**", mill_pattern("s", "m"), site_pattern("s")):
        assert not key_matches(pattern, key)
        assert not zenoh.KeyExpr(pattern).intersects(zenoh.KeyExpr(key))
    assert not key_matches(alarm_pattern(), telemetry)
    assert zenoh.KeyExpr(alarm_pattern()).intersects(zenoh.KeyExpr(key))


def test_the_key_map_of_a_mill_file_both_ways():
    """:func:`mill_channel_keys` and :class:`ChannelRoutes` are inverse; a replay run's key is
    its channel only where asked for (offline tools), never for the live worker."""
    from millwatch.ingest.keys import ChannelRoutes, mill_channel_keys
    from millwatch.ingest.mill_files import load_mill_config

    config = load_mill_config(REPO / "deploy" / "mills" / "ball-dual-lrs.toml")
    by_name = mill_channel_keys(config)
    assert list(by_name) == list(config.channels)
    live, offline = ChannelRoutes([config]), ChannelRoutes([config], replayed=True)
    for name, key in by_name.items():
        assert live.route(key) == offline.route(key) == (config.id, name)
        assert parse_key(key).signal_segment == config.channels[name].key
        assert live.route(to_replay(key, "r1")) is None
        assert offline.route(to_replay(key, "r1")) == (config.id, name)
    for other in (build_key("elsewhere", config.id, "speed"), "not/a/key", "millwatch/v1"):
        assert live.route(other) is None and offline.route(other) is None


def test_channel_keys_of_a_mill_file_are_built_in_the_keys_module_only() -> None:
    """One key map: nothing else turns a mill file's channels into keys itself."""
    assert _modules_but_keys(lambda text: "channel_key(" in text) == []
