"""The one module that owns millwatch's zenoh key expressions (build/parse pairs).

Layout, version 1 (``/``-separated chunks)::

    live:    millwatch/v1/<site>/<mill>/<signal>
    replay:  millwatch/v1/@replay/<run>/<site>/<mill>/<signal>
    alarms:  millwatch/v1/<site>/<mill>/@alarms
    query:   millwatch/v1/<site>/<mill>/@query/<what>     (a worker's queryable)
    worker:  millwatch/v1/<site>/<mill>/@worker/<worker>  (liveliness token)
    spool:   <channel key>/@spool                  (a gateway spool's queryable)

- ``v1`` is the key-layout version; a new layout gets ``v2`` and both can coexist
  on one router.
- ``<site>``, ``<mill>`` and the replay ``<run>`` id are lower-case segments matching
  ``[a-z0-9][a-z0-9_-]{0,63}``.
- ``<signal>`` is a base signal, optionally with a drive-side suffix on dual-drive
  mills: ``motor_torque``, ``pinion_torque``, ``pinion_bending``, ``speed``,
  ``tacho``; suffix ``_nbs`` (non-barring side) or ``_bs`` (barring side), e.g.
  ``pinion_torque_nbs``. Single-drive mills use the bare base name.
- Replayed data is tagged by the **verbatim** chunk ``@replay`` followed by a run id.
  In zenoh 1.x a chunk starting with ``@`` is matched only by the identical chunk,
  never by ``*`` or ``**``: a live consumer subscribed to ``millwatch/v1/**`` can
  therefore never receive replayed blocks by accident, and each replay run has its
  own key space (two engineers replaying the same mill do not interleave).

- Alarm transitions of a mill (JSON, :mod:`millwatch.alarms.wire`) go on the **verbatim** chunk
  ``@alarms`` in place of the signal: ``*``/``**`` never match it, so telemetry consumers
  (``millwatch/v1/**``, :func:`live_pattern`) never receive alarms and alarm subscribers never
  receive telemetry. SCADA gateways subscribe to :func:`alarm_pattern` (all sites and mills:
  ``millwatch/v1/*/*/@alarms``) or to one site or mill. :func:`parse_key` refuses alarm keys
  (they are not channels); :func:`parse_alarm_key` parses them.

- Scale-out (:func:`query_key`, :func:`worker_token_key`): a worker answers ``get`` about
  each of its mills on ``…/@query/<what>`` and holds a liveliness token
  ``…/@worker/<worker>`` per mill while it runs (a hot standby ``…/@standby/<worker>``);
  ``*``/``**`` never match these chunks.

- Gateway spools (:func:`spool_key`, :mod:`millwatch.ingest.spool`): a spool answers ``get`` for the
  blocks it holds of one channel on that channel's key followed by the verbatim chunk
  ``@spool`` (live and replay keys alike); ``*``/``**`` never match it, so no telemetry
  subscriber sees recovery traffic and a query reaches only the spools of that channel.

No other module formats keys: use :func:`build_key`, :func:`parse_key` and the
pattern helpers. The map between a mill file's channels and their keys is built here too:
:func:`mill_channel_keys` (channel name → key) and :class:`ChannelRoutes` (key → mill id and
channel name), for the worker, offline analysis, the simulator, subscriptions and tools alike.
:func:`key_matches` implements zenoh's ``*``/``**``/verbatim rules for concrete keys (used by
the archive reader, which must not need a session).
"""

from __future__ import annotations

import enum
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # (only the annotation: keys stays importable without pydantic)
    from millwatch.analytics.drivetrain.mill_config import MillConfig

ROOT = "millwatch"
LAYOUT_VERSION = "v1"
REPLAY_TAG = "@replay"
ALARMS_TAG = "@alarms"
WILD = "*"
WILD_ANY = "**"
_SEGMENT_RE = re.compile(r"[a-z0-9][a-z0-9_-]{0,63}")
_LIVE_LEN = 5  # millwatch / v1 / site / mill / signal
_REPLAY_LEN = 7  # millwatch / v1 / @replay / run / site / mill / signal


class KeyFormatError(ValueError):
    """A key or key segment is malformed; ``segment`` names the offending part."""

    def __init__(self, segment: str, value: str, reason: str) -> None:
        super().__init__(f"{segment} segment {value!r} is invalid: {reason}")
        self.segment = segment
        self.value = value


class Signal(enum.StrEnum):
    """Base signal names (the ``<signal>`` chunk without side suffix)."""

    MOTOR_TORQUE = "motor_torque"
    PINION_TORQUE = "pinion_torque"
    PINION_BENDING = "pinion_bending"
    SPEED = "speed"
    TACHO = "tacho"


class Side(enum.StrEnum):
    """Drive side on dual-drive mills: non-barring side and barring side."""

    NBS = "nbs"
    BS = "bs"


def _check_segment(name: str, value: str) -> str:
    if not isinstance(value, str) or not _SEGMENT_RE.fullmatch(value):
        raise KeyFormatError(name, str(value), "must match [a-z0-9][a-z0-9_-]{0,63}")
    return value


_SIGNALS = frozenset(s.value for s in Signal)
_SIDES = frozenset(s.value for s in Side)


def _parse_signal(value: str) -> tuple[Signal, Side | None]:
    if value in _SIGNALS:
        return Signal(value), None
    base, _, suffix = value.rpartition("_")
    if base in _SIGNALS and suffix in _SIDES:
        return Signal(base), Side(suffix)
    known = ", ".join(s.value for s in Signal)
    raise KeyFormatError("signal", value, f"expected one of {known}, optionally + _nbs/_bs")


def _as_signal(value: Signal | str) -> Signal:
    if str(value) not in _SIGNALS:
        known = ", ".join(sorted(_SIGNALS))
        raise KeyFormatError("signal", str(value), f"expected one of {known}")
    return Signal(value)


def _as_side(value: Side | str | None) -> Side | None:
    if value is not None and str(value) not in _SIDES:
        raise KeyFormatError("side", str(value), "expected 'nbs' or 'bs'")
    return None if value is None else Side(value)


@dataclass(frozen=True, slots=True)
class ChannelKey:
    """A parsed channel key. ``replay_run`` is ``None`` for live data."""

    site: str
    mill: str
    signal: Signal
    side: Side | None = None
    replay_run: str | None = None

    def __post_init__(self) -> None:
        _check_segment("site", self.site)
        _check_segment("mill", self.mill)
        object.__setattr__(self, "signal", _as_signal(self.signal))
        object.__setattr__(self, "side", _as_side(self.side))
        if self.replay_run is not None:
            _check_segment("run", self.replay_run)

    @property
    def signal_segment(self) -> str:
        """The ``<signal>`` chunk, e.g. ``pinion_torque_nbs``."""
        return self.signal.value if self.side is None else self.signal.value + "_" + self.side

    @property
    def is_replay(self) -> bool:
        """True for keys carrying the ``@replay/<run>`` tag."""
        return self.replay_run is not None

    @property
    def expr(self) -> str:
        """The key expression string."""
        return "/".join([*_prefix(self.replay_run), self.site, self.mill, self.signal_segment])

    def as_replay(self, run: str) -> ChannelKey:
        """The same channel under replay run ``run``."""
        return replace(self, replay_run=run)

    def as_live(self) -> ChannelKey:
        """The same channel without replay tag."""
        return replace(self, replay_run=None)

    def __str__(self) -> str:
        return self.expr


def _prefix(replay_run: str | None) -> list[str]:
    if replay_run is None:
        return [ROOT, LAYOUT_VERSION]
    return [ROOT, LAYOUT_VERSION, REPLAY_TAG, replay_run]


def build_key(
    site: str,
    mill: str,
    signal: Signal | str,
    side: Side | str | None = None,
    *,
    replay_run: str | None = None,
) -> str:
    """Build a concrete channel key; raises :class:`KeyFormatError` naming the bad segment.

    ``signal`` is a base signal name; the drive side goes in ``side``.
    """
    _check_segment("site", site)
    _check_segment("mill", mill)
    return ChannelKey(site, mill, _as_signal(signal), _as_side(side), replay_run).expr


def channel_key(site: str, mill: str, segment: str, *, replay_run: str | None = None) -> str:
    """The key of a configured channel whose ``<signal>`` chunk is ``segment`` (e.g. the mill
    config's ``pinion_torque_nbs``); raises :class:`KeyFormatError` naming the bad part."""
    signal, side = _parse_signal(segment)
    return build_key(site, mill, signal, side, replay_run=replay_run)


def mill_channel_keys(config: MillConfig) -> dict[str, str]:
    """A mill's live channel keys by configured channel name, in configuration order (the
    ``key`` of each channel of the mill file is its ``<signal>`` chunk)."""
    return {
        name: channel_key(config.site, config.id, channel.key)
        for name, channel in config.channels.items()
    }


class ChannelRoutes:
    """The one key → ``(mill id, configured channel name)`` map of the given mills.

    ``replayed=False`` (the live worker and its archive replay): live keys only, so blocks of a
    replay run can never be taken for the mill's live data (the ``@replay`` promise above).
    ``replayed=True`` (offline tools reading a recording, which may come from a replay run): a
    replay run's key of a channel routes like its live key."""

    def __init__(self, configs: Iterable[MillConfig], *, replayed: bool = False) -> None:
        self._live = {
            key: (config.id, name)
            for config in configs
            for name, key in mill_channel_keys(config).items()
        }
        self._seen: dict[str, tuple[str, str] | None] = {}
        #: (mill id, channel name) of a key; None for a key of no given mill's channel. (Live
        #: only: the dictionary's own lookup, no Python call — the worker routes every block.)
        self.route: Callable[[str], tuple[str, str] | None] = (
            self._route_replayed if replayed else self._live.get
        )

    def _route_replayed(self, key: str) -> tuple[str, str] | None:
        found = self._live.get(key)
        if found is None and key not in self._seen:  # (parsed once a key)
            try:
                self._seen[key] = self._live.get(to_live(key))
            except KeyFormatError:
                self._seen[key] = None
        return found if found is not None else self._seen[key]


def _split_prefix(expr: str) -> tuple[str | None, list[str]]:
    parts = expr.split("/")
    if parts[:1] != [ROOT]:
        raise KeyFormatError("root", parts[0], f"expected {ROOT!r}")
    if parts[1:2] != [LAYOUT_VERSION]:
        got = parts[1] if len(parts) > 1 else ""
        raise KeyFormatError("version", got, f"expected {LAYOUT_VERSION!r}")
    if len(parts) > 2 and parts[2] == REPLAY_TAG:
        if len(parts) != _REPLAY_LEN:
            raise KeyFormatError("key", expr, "replay keys have 7 chunks: " + replay_pattern())
        return _check_segment("run", parts[3]), parts[4:]
    if len(parts) != _LIVE_LEN:
        raise KeyFormatError("key", expr, "live keys have 5 chunks: " + live_pattern())
    return None, parts[2:]


def parse_key(expr: str) -> ChannelKey:
    """Parse a concrete key (live or replay); raises :class:`KeyFormatError`."""
    run, (site, mill, signal) = _split_prefix(expr)
    base, side = _parse_signal(signal)
    return ChannelKey(_check_segment("site", site), _check_segment("mill", mill), base, side, run)


def _segment_or_wild(name: str, value: str) -> str:
    return value if value in (WILD, WILD_ANY) else _check_segment(name, value)


def mill_pattern(site: str, mill: str, *, replay_run: str | None = None) -> str:
    """All signals of one mill: ``millwatch/v1/<site>/<mill>/*`` (``*`` allowed)."""
    run = None if replay_run is None else _segment_or_wild("run", replay_run)
    segs = [_segment_or_wild("site", site), _segment_or_wild("mill", mill), WILD]
    return "/".join([*_prefix(run), *segs])


def site_pattern(site: str, *, replay_run: str | None = None) -> str:
    """All mills of one site: ``millwatch/v1/<site>/*/*``."""
    return mill_pattern(site, WILD, replay_run=replay_run)


def live_pattern() -> str:
    """Every live channel: ``millwatch/v1/*/*/*`` (never matches replayed keys)."""
    return mill_pattern(WILD, WILD)


def replay_pattern(run: str = WILD) -> str:
    """Every channel of replay run ``run`` (default: all runs)."""
    return mill_pattern(WILD, WILD, replay_run=run)


def to_replay(expr: str, run: str) -> str:
    """Map a live (or replay) key to the same channel under replay run ``run``."""
    return parse_key(expr).as_replay(run).expr


def to_live(expr: str) -> str:
    """Strip the replay tag of a key (identity for live keys)."""
    return parse_key(expr).as_live().expr


def _chunk_ok(pattern_chunk: str, key_chunk: str) -> bool:
    if pattern_chunk == WILD:
        return not key_chunk.startswith("@")
    return pattern_chunk == key_chunk


@lru_cache(maxsize=4096)
def _match(pattern: tuple[str, ...], key: tuple[str, ...]) -> bool:
    if not pattern:
        return not key
    head = pattern[0]
    if head == WILD_ANY:
        if _match(pattern[1:], key):
            return True
        return bool(key) and not key[0].startswith("@") and _match(pattern, key[1:])
    return bool(key) and _chunk_ok(head, key[0]) and _match(pattern[1:], key[1:])


def key_matches(pattern: str, key: str) -> bool:
    """Whether concrete ``key`` matches zenoh key expression ``pattern``.

    Supports literal chunks, ``*`` (one chunk) and ``**`` (zero or more chunks);
    wildcards never match verbatim ``@`` chunks, as in zenoh 1.x. Sub-chunk
    wildcards (``$*``) are rejected with :class:`KeyFormatError`.
    """
    if "$*" in pattern:
        raise KeyFormatError("pattern", pattern, "sub-chunk wildcards ($*) are not supported")
    chunks = tuple(pattern.split("/"))
    for chunk in chunks:
        if "*" in chunk and chunk not in (WILD, WILD_ANY):
            raise KeyFormatError(
                "pattern", pattern, f"chunk {chunk!r}: '*' and '**' must stand alone in a chunk"
            )
    return _match(chunks, tuple(key.split("/")))


def alarm_key(site: str, mill: str) -> str:
    """The key a mill's alarm transitions are published on: ``millwatch/v1/<site>/<mill>/@alarms``;
    raises :class:`KeyFormatError` naming the bad segment."""
    return "/".join([*_prefix(None), _check_segment("site", site), _check_segment("mill", mill),
                     ALARMS_TAG])  # fmt: skip


def alarm_pattern(site: str = WILD, mill: str = WILD) -> str:
    """Alarm keys of one mill, one site (``mill="*"``) or everything (default):
    ``millwatch/v1/*/*/@alarms``."""
    segs = [_segment_or_wild("site", site), _segment_or_wild("mill", mill), ALARMS_TAG]
    return "/".join([*_prefix(None), *segs])


def parse_alarm_key(expr: str) -> tuple[str, str]:
    """``(site, mill)`` of an alarm key; raises :class:`KeyFormatError`."""
    parts = expr.split("/")
    if len(parts) != _LIVE_LEN or parts[-1] != ALARMS_TAG:
        raise KeyFormatError("key", expr, "alarm keys look like " + alarm_pattern())
    _split_prefix(expr)
    return _check_segment("site", parts[2]), _check_segment("mill", parts[3])


# ----------------------------------------------------------------------------- scale-out keys
QUERY_TAG = "@query"
WORKER_TAG = "@worker"
#: The token chunk of a hot standby (``[worker] standby = true``): a second worker of the same
#: mills, which the API asks only while no primary (``@worker``) token of the mill is live.
STANDBY_TAG = "@standby"
_QUERY_LEN = 6  # millwatch / v1 / site / mill / @query / what
_TOKEN_LEN = 6  # millwatch / v1 / site / mill / @worker / worker


def query_key(site: str, mill: str, what: str) -> str:
    """The key a worker answers queries about one mill on:
    ``millwatch/v1/<site>/<mill>/@query/<what>`` (``what``: ``status``, ``life``, ``alarms`` …).
    The verbatim ``@query`` chunk keeps queries apart from telemetry and alarm keys."""
    segs = [_check_segment("site", site), _check_segment("mill", mill), QUERY_TAG,
            _check_segment("query", what)]  # fmt: skip
    return "/".join([*_prefix(None), *segs])


def query_pattern(what: str = WILD, site: str = WILD, mill: str = WILD) -> str:
    """Query keys of every mill (default), one site or one mill, for one ``what`` or all:
    ``millwatch/v1/*/*/@query/status``; a ``get`` on it gathers one reply per mill."""
    segs = [_segment_or_wild("site", site), _segment_or_wild("mill", mill), QUERY_TAG,
            _segment_or_wild("query", what)]  # fmt: skip
    return "/".join([*_prefix(None), *segs])


def parse_query_key(expr: str) -> tuple[str, str, str]:
    """``(site, mill, what)`` of a concrete query key; raises :class:`KeyFormatError`."""
    parts = expr.split("/")
    if len(parts) != _QUERY_LEN or parts[4] != QUERY_TAG or parts[:2] != [ROOT, LAYOUT_VERSION]:
        raise KeyFormatError("key", expr, "query keys look like " + query_pattern())
    return (_check_segment("site", parts[2]), _check_segment("mill", parts[3]),
            _check_segment("query", parts[5]))  # fmt: skip


def worker_token_key(site: str, mill: str, worker: str, *, standby: bool = False) -> str:
    """The liveliness token a worker holds while it analyses a mill:
    ``millwatch/v1/<site>/<mill>/@worker/<worker>`` (a hot standby's: ``…/@standby/<worker>``).
    It disappears when the worker's session ends (clean stop, crash: TCP closes; a hung host:
    the zenoh lease)."""
    segs = [_check_segment("site", site), _check_segment("mill", mill),
            STANDBY_TAG if standby else WORKER_TAG, _check_segment("worker", worker)]  # fmt: skip
    return "/".join([*_prefix(None), *segs])


def worker_token_pattern(
    site: str = WILD, mill: str = WILD, worker: str = WILD, *, standby: bool = False
) -> str:
    """Worker tokens of every mill (default), one site or one mill:
    ``millwatch/v1/*/*/@worker/*`` (``standby``: the standbys' ``…/@standby/*``)."""
    segs = [_segment_or_wild("site", site), _segment_or_wild("mill", mill),
            STANDBY_TAG if standby else WORKER_TAG, _segment_or_wild("worker", worker)]  # fmt: skip
    return "/".join([*_prefix(None), *segs])


def parse_worker_token_key(expr: str) -> tuple[str, str, str]:
    """``(site, mill, worker)`` of a worker token key (a primary's or a standby's: which one is
    :func:`is_standby_token`); raises :class:`KeyFormatError`."""
    parts = expr.split("/")
    if (len(parts) != _TOKEN_LEN or parts[4] not in (WORKER_TAG, STANDBY_TAG)
            or parts[:2] != [ROOT, LAYOUT_VERSION]):  # fmt: skip
        raise KeyFormatError("key", expr, "worker tokens look like " + worker_token_pattern())
    return (_check_segment("site", parts[2]), _check_segment("mill", parts[3]),
            _check_segment("worker", parts[5]))  # fmt: skip


def is_standby_token(expr: str) -> bool:
    """Whether a worker token key (:func:`parse_worker_token_key`) is a hot standby's."""
    parts = expr.split("/")
    return len(parts) == _TOKEN_LEN and parts[4] == STANDBY_TAG


def worker_name(text: str) -> str:
    """``text`` (e.g. a host name) made into a valid worker segment: lower case, other
    characters replaced by ``-``, at most 64 characters; ``worker`` when nothing is left."""
    name = re.sub(r"[^a-z0-9_-]", "-", text.lower()).strip("-_")[:64]
    return name if name else "worker"


# ----------------------------------------------------------------------------- gateway spools
SPOOL_TAG = "@spool"


def spool_key(channel: str) -> str:
    """The key a gateway spool answers recovery queries for channel key ``channel`` on:
    ``<channel>/@spool`` (e.g. ``millwatch/v1/plant/m1/speed/@spool``); raises
    :class:`KeyFormatError` when ``channel`` is not a channel key."""
    return "/".join([parse_key(channel).expr, SPOOL_TAG])


def parse_spool_key(expr: str) -> str:
    """The channel key of a spool key (inverse of :func:`spool_key`); raises
    :class:`KeyFormatError`."""
    channel, _, tag = expr.rpartition("/")
    if tag != SPOOL_TAG:
        raise KeyFormatError("key", expr, "spool keys end with " + SPOOL_TAG)
    return parse_key(channel).expr
