"""An MCAP file that Foxglove plots: samples at their sample time, beside what millwatch concluded.

The archive itself is not plottable (:mod:`millwatch.ingest.archive.files`: its channels carry the
raw wire
blocks, encoding ``millwatch.block.v1``, stamped with the *receive* time). This module writes a
derived file with the official Foxglove SDK (``foxglove-sdk``, :func:`foxglove.open_mcap`), every
message stamped with the time it describes: MCAP ``log_time`` = ``publish_time`` = sample time
(block ``t0 + i·1e9/fs``, the wire header's clock), or the time of the event, state change or
alarm transition.

Topics of one mill ``<mill>`` (schema in brackets; protobuf encoding throughout):

* ``/<mill>/samples/<channel>`` [``millwatch.Sample``]: one message per sample, ``value``
  (float64, calibrated units of the mill config: kN·m, MPa, rpm). Foxglove's Plot panel draws a
  time series of one value per message against log time, so this is the one layout that plots
  the 1 kHz signal itself (message path ``/<mill>/samples/motor_torque.value``). No Foxglove
  schema holds a bare number, hence a custom one.
* ``/<mill>/overview/<channel>`` [``millwatch.SampleEnvelope``]: one message per archived block
  (0.1 s for 100-sample blocks at 1 kHz): ``min``, ``max``, ``mean`` of its samples (NaN
  samples left out), stamped at the block's first sample — for spans too long to plot sample by
  sample.
* ``/<mill>/state`` [``foxglove.KeyValuePair``]: ``key="operating_state"``, ``value`` the state
  (``stopped``, ``starting``, ``running``, ``stopping``, ``barring``, ``unknown``), at the span
  start and at every change.
* ``/<mill>/events`` [``foxglove.Event``]: starts, stops and barring sessions with their start and
  end time and, as metadata, their measures (switch-on and short-circuit peaks in % of rated
  torque, rise times, rocking, …); ``/<mill>/log`` [``foxglove.Log``]: the same as one line each.
* ``/<mill>/damage/<component>`` [``millwatch.Damage``]: Miner damage booked since the span start,
  ``committed`` (closed rainflow cycles) and ``with_residue`` (plus the open residue closed as
  half cycles now; its turning points may predate the span), at a regular step.
* ``/<mill>/starts`` [``millwatch.StartPeaks``]: each start's ``switch_on_peak_pct``,
  ``short_circuit_peak_pct`` (% of rated motor torque), ``rise_time_10_90_ms``, ``accel_s`` (NaN
  where not measured), for a Plot of the peaks across starts.
* ``/<mill>/harmonics/<channel>/<line>`` [``millwatch.HarmonicLine``]: each detected drivetrain
  line of each spectral window: ``frequency_hz``, ``amplitude`` (channel units), ``amplitude_pct``
  (% rated, NaN for bending), ``snr_db``, stamped at the window's end.
* ``/<mill>/steady/<channel>`` [``millwatch.SteadyState``]: each steady-state window of each
  torque and bending channel (the mill file's names): ``mean`` and ``range_per_rev`` (channel
  units), ``mean_pct`` and ``range_pct`` (% of rated motor torque, NaN for bending),
  ``bending_amplitude_mpa`` (NaN for torque), stamped at the window's first sample.
* ``/<mill>/alarms`` [``foxglove.Log``]: each alarm transition (raised, escalated, cleared…),
  level Warning/Error/Fatal by severity, Info when cleared.

The custom schemas are proto3 messages of doubles only, so their encoding is fixed-width and is
built for many samples at once with numpy (field tag byte + little-endian float64); any protobuf
decoder (Foxglove's, ``mcap-protobuf-support``) reads them back bit for bit.
"""

from __future__ import annotations

import logging
import math
import struct
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import foxglove
import numpy as np
from foxglove import Channel, Schema
from foxglove.channels import EventChannel, KeyValuePairChannel, LogChannel
from foxglove.mcap import MCAPWriteOptions
from foxglove.messages import Event, KeyValuePair, Log, LogLevel, Timestamp
from google.protobuf import descriptor_pb2

from millwatch.analytics.spectra.facts import HarmonicWindow

__all__ = [
    "DAMAGE_SCHEMA",
    "ENVELOPE_SCHEMA",
    "HARMONIC_SCHEMA",
    "SAMPLE_SCHEMA",
    "START_SCHEMA",
    "STEADY_SCHEMA",
    "ExportCounts",
    "FoxgloveExportWriter",
    "encode_doubles",
    "encode_samples",
    "sample_time_ns",
    "sample_times_ns",
    "topic",
]

log = logging.getLogger(__name__)

SAMPLE_SCHEMA = "millwatch.Sample"
ENVELOPE_SCHEMA = "millwatch.SampleEnvelope"
DAMAGE_SCHEMA = "millwatch.Damage"
START_SCHEMA = "millwatch.StartPeaks"
HARMONIC_SCHEMA = "millwatch.HarmonicLine"
STEADY_SCHEMA = "millwatch.SteadyState"
#: Fields (all ``double``, numbered from 1) of each custom schema.
_FIELDS = {
    SAMPLE_SCHEMA: ("value",),
    ENVELOPE_SCHEMA: ("min", "max", "mean"),
    DAMAGE_SCHEMA: ("committed", "with_residue"),
    START_SCHEMA: ("switch_on_peak_pct", "short_circuit_peak_pct", "rise_time_10_90_ms", "accel_s"),
    HARMONIC_SCHEMA: ("frequency_hz", "amplitude", "amplitude_pct", "snr_db"),
    STEADY_SCHEMA: ("mean", "range_per_rev", "mean_pct", "range_pct", "bending_amplitude_mpa"),
}
#: Event fields that count stream samples of one analysis run: meaningless in a file.
_STREAM_FIELDS = frozenset({"sample", "end_sample"})
#: Fixed-width encoding of each custom schema's message: (tag byte, float64) per field.
_PACK = {name: struct.Struct("<" + "Bd" * len(fields)) for name, fields in _FIELDS.items()}
_TAGS = {name: [((k + 1) << 3) | 1 for k in range(len(fields))] for name, fields in _FIELDS.items()}
_LEVEL = {"warning": LogLevel.Warning, "alarm": LogLevel.Error, "critical": LogLevel.Fatal}


def topic(mill: str, *parts: str) -> str:
    """The export topic ``/<mill>/<part>/…`` (module docstring lists them)."""
    return "/" + "/".join((mill, *parts))


def _descriptor_set(name: str) -> bytes:
    """A FileDescriptorSet holding proto3 message ``name`` (``package.Message``) with the
    ``double`` fields of :data:`_FIELDS`: the schema data Foxglove needs to decode it."""
    package, message = name.rsplit(".", 1)
    proto = descriptor_pb2.FileDescriptorProto(
        name=f"{name.replace('.', '/')}.proto", package=package, syntax="proto3"
    )
    msg = proto.message_type.add(name=message)
    for number, field_name in enumerate(_FIELDS[name], start=1):
        msg.field.add(
            name=field_name,
            number=number,
            type=descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE,
            label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL,
        )
    return descriptor_pb2.FileDescriptorSet(file=[proto]).SerializeToString()


def _record_dtype(fields: int) -> np.dtype[Any]:
    """Numpy layout of a message of ``fields`` doubles: (tag, float64) pairs, unpadded."""
    parts: list[tuple[str, str]] = []
    for k in range(fields):
        parts += [(f"t{k}", "u1"), (f"v{k}", "<f8")]
    return np.dtype(parts)


def encode_doubles(columns: list[np.ndarray]) -> list[bytes]:
    """Protobuf encodings of messages whose double fields 1, 2, … hold ``columns[0][i]``,
    ``columns[1][i]``, …: tag byte ``(number << 3) | 1`` then the little-endian float64, every
    field written (also 0.0, which a proto3 decoder reads back as 0.0). One ``bytes`` per
    message."""
    n = columns[0].shape[0]
    rec = np.empty(n, dtype=_record_dtype(len(columns)))
    for k, col in enumerate(columns):
        rec[f"t{k}"] = ((k + 1) << 3) | 1
        rec[f"v{k}"] = col
    raw = rec.tobytes()
    width = rec.dtype.itemsize
    return [raw[i : i + width] for i in range(0, n * width, width)]


def encode_samples(values: np.ndarray) -> list[bytes]:
    """``millwatch.Sample`` messages of ``values`` (float64, bit for bit)."""
    return encode_doubles([np.asarray(values, dtype=np.float64)])


def sample_times_ns(t0_ns: int, fs: float, n: int, first: int = 0) -> np.ndarray:
    """Times (int64 ns since the epoch) of samples ``first … n-1`` of a block starting at
    ``t0_ns``: ``t0 + i·1e9/fs`` (DESIGN "Conventions"), exact integer ns for an integer rate as
    the analyzer computes them (:meth:`millwatch.analytics.mill.loads.LoadAnalysis.t_ns`)."""
    i = np.arange(first, n, dtype=np.int64)
    if float(fs).is_integer():
        return t0_ns + (i * 1_000_000_000) // int(fs)
    return t0_ns + np.round(i * (1e9 / fs)).astype(np.int64)


def envelopes(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(min, max, mean) of each row of samples (one block each), NaN-aware: a row with missing
    samples (a dropout) gives the envelope of the rest, all NaN when none is finite. Row sums
    are numpy's 1-D sums (bitwise those of each row alone)."""
    low, high = rows.min(axis=1), rows.max(axis=1)
    mean = rows.sum(axis=1) / rows.shape[1]
    for k in np.flatnonzero(np.isnan(low)).tolist():
        finite = rows[k][np.isfinite(rows[k])]
        low[k] = high[k] = mean[k] = math.nan
        if finite.size:
            low[k], high[k], mean[k] = finite.min(), finite.max(), finite.mean()
    return low, high, mean


def sample_time_ns(t0_ns: int, fs: float, i: int) -> int:
    """Time of sample ``i`` of a block starting at ``t0_ns``, as :func:`sample_times_ns`."""
    if float(fs).is_integer():
        return t0_ns + (i * 1_000_000_000) // int(fs)
    return t0_ns + round(i * (1e9 / fs))


def _stamp(t_ns: int) -> Timestamp:
    return Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000)


def _number(value: Any) -> float:
    """A measure as float64; NaN for None (not measured)."""
    return math.nan if value is None else float(value)


def _text(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


@dataclass
class ExportCounts:
    """Messages written, per kind (what the command prints)."""

    samples: int = 0
    overview: int = 0
    states: int = 0
    events: int = 0
    damage: int = 0
    harmonics: int = 0
    steady: int = 0
    alarms: int = 0
    topics: set[str] = field(default_factory=set)


class FoxgloveExportWriter:
    """Writes the topics of the module docstring to one new MCAP file (a context manager).

    Each writer has its own :class:`foxglove.Context`, so its channels go to its file only. Times
    are int64 ns since the Unix epoch (UTC); every message's log time is the time it describes.
    """

    def __init__(self, path: str | Path, *, overwrite: bool = False) -> None:
        self.path = Path(path)
        self.counts = ExportCounts()
        self._context = foxglove.Context()
        # message indexes stay (16 B a message, uncompressed): Foxglove's indexed MCAP reader
        # (@mcap/core ChunkCursor) refuses a chunk that has messages but no message index
        options = MCAPWriteOptions(emit_message_indexes=True)
        try:
            self._mcap = foxglove.open_mcap(
                self.path, allow_overwrite=overwrite, context=self._context, writer_options=options
            )
        except OSError as exc:  # the SDK's message names no file
            raise OSError(f"{self.path}: cannot write: {exc.strerror or exc}") from exc
        self._schemas = {name: Schema(name=name, encoding="protobuf",
                                      data=_descriptor_set(name)) for name in _FIELDS}  # fmt: skip
        self._custom: dict[str, Channel] = {}
        self._logs: dict[str, LogChannel] = {}
        self._events: dict[str, EventChannel] = {}
        self._states: dict[str, KeyValuePairChannel] = {}

    def __enter__(self) -> FoxgloveExportWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Finish the file (summary, indexes, footer)."""
        self._mcap.close()

    # ------------------------------------------------------------ channels
    def _channel(self, name: str, schema: str) -> Channel:
        ch = self._custom.get(name)
        if ch is None:
            ch = Channel(name, schema=self._schemas[schema], message_encoding="protobuf",
                         context=self._context)  # fmt: skip
            self._custom[name] = ch
            self.counts.topics.add(name)
        return ch

    def _log_channel(self, name: str) -> LogChannel:
        ch = self._logs.get(name)
        if ch is None:
            ch = self._logs[name] = LogChannel(name, context=self._context)
            self.counts.topics.add(name)
        return ch

    # ------------------------------------------------------------ samples
    def samples(self, mill: str, channel: str, t_ns: np.ndarray, values: np.ndarray) -> None:
        """One ``millwatch.Sample`` per sample, stamped ``t_ns[i]``."""
        if values.shape[0] == 0:
            return
        if t_ns.shape != values.shape:
            raise ValueError(f"{channel}: {t_ns.shape[0]} times for {values.shape[0]} samples")
        log_raw = self._channel(topic(mill, "samples", channel), SAMPLE_SCHEMA).base.log
        deque(map(log_raw, encode_samples(values), t_ns.tolist()), maxlen=0)  # no Python loop
        self.counts.samples += values.shape[0]

    def overview(self, mill: str, channel: str, t_ns: int, values: np.ndarray) -> None:
        """One ``millwatch.SampleEnvelope`` (min, max, mean; NaN-aware) at ``t_ns``."""
        if values.shape[0] == 0:
            return
        low, high, mean = envelopes(values[None, :])
        self.envelope(mill, channel, t_ns, float(low[0]), float(high[0]), float(mean[0]))

    def envelope(
        self, mill: str, channel: str, t_ns: int, low: float, high: float, mean: float
    ) -> None:
        """One ``millwatch.SampleEnvelope`` of numbers :func:`envelopes` computed."""
        self.numbers(topic(mill, "overview", channel), ENVELOPE_SCHEMA, t_ns, [low, high, mean])
        self.counts.overview += 1

    def numbers(self, name: str, schema: str, t_ns: int, values: list[float]) -> None:
        """One message of custom ``schema`` on topic ``name``: its fields in order (NaN where a
        value is missing), at ``t_ns``."""
        pairs = [v for tag, x in zip(_TAGS[schema], values, strict=True) for v in (tag, x)]
        self._channel(name, schema).base.log(_PACK[schema].pack(*pairs), t_ns)

    # ------------------------------------------------------------ conclusions
    def state(self, mill: str, t_ns: int, label: str) -> None:
        """The operating state from ``t_ns`` on (``foxglove.KeyValuePair``)."""
        name = topic(mill, "state")
        ch = self._states.get(name)
        if ch is None:
            ch = self._states[name] = KeyValuePairChannel(name, context=self._context)
            self.counts.topics.add(name)
        ch.log(KeyValuePair(key="operating_state", value=label), log_time=t_ns)
        self.counts.states += 1

    def event(self, mill: str, event: dict[str, Any], line: str) -> None:
        """A start/stop/barring event dict of the analyzer: ``foxglove.Event`` (its scalar
        fields as metadata) and ``line`` on the log topic, both at ``event["t_ns"]``."""
        t0, t1 = int(event["t_ns"]), int(event.get("end_t_ns") or event["t_ns"])
        name = topic(mill, "events")
        ch = self._events.get(name)
        if ch is None:
            ch = self._events[name] = EventChannel(name, context=self._context)
            self.counts.topics.add(name)
        meta = [KeyValuePair(key=k, value=_text(v)) for k, v in event.items()
                if isinstance(v, str | int | float | bool) and k not in _STREAM_FIELDS]  # fmt: skip
        ch.log(Event(start_time=_stamp(t0), end_time=_stamp(t1), metadata=meta), log_time=t0)
        level = LogLevel.Warning if event.get("alarm") or event.get("failed") else LogLevel.Info
        self.log_line(mill, "log", t0, level, str(event.get("event", "event")), line)
        if event.get("event") == "start":  # the measures as numbers, for a Plot across starts
            peaks = [_number(event.get(f)) for f in _FIELDS[START_SCHEMA]]
            self.numbers(topic(mill, "starts"), START_SCHEMA, t0, peaks)
        self.counts.events += 1

    def harmonics(self, mill: str, window: HarmonicWindow) -> None:
        """The detected lines of one spectral window (``millwatch.HarmonicLine`` per channel and
        line), stamped at the window's end, when the analysis concluded them."""
        for m in window.lines:
            if m.detected and m.observable:
                values = [m.frequency_hz, m.amplitude, _number(m.amplitude_pct), m.snr_db]
                name = topic(mill, "harmonics", m.channel, m.name)
                self.numbers(name, HARMONIC_SCHEMA, window.t_end_ns, values)
                self.counts.harmonics += 1

    def steady(self, mill: str, window: dict[str, Any]) -> None:
        """One steady-state window of the analyzer (``millwatch.SteadyState`` per channel, by
        the mill file's channel names), stamped at its first sample."""
        fields = _FIELDS[STEADY_SCHEMA]
        for channel in window["range_per_rev"]:
            values = [_number(window.get(f, {}).get(channel)) for f in fields]
            self.numbers(topic(mill, "steady", channel), STEADY_SCHEMA, int(window["t_ns"]), values)
        self.counts.steady += 1

    def log_line(
        self, mill: str, sub: str, t_ns: int, level: LogLevel, name: str, text: str
    ) -> None:
        """A ``foxglove.Log`` line on ``/<mill>/<sub>``."""
        msg = Log(timestamp=_stamp(t_ns), level=level, message=text, name=name)
        self._log_channel(topic(mill, sub)).log(msg, log_time=t_ns)

    def alarm(self, mill: str, transition: dict[str, Any]) -> None:
        """One alarm transition (``millwatch.alarms.lifecycle.TransitionRecord.to_row`` plus
        ``rule``)."""
        kind = str(transition["kind"])
        level = LogLevel.Info if kind == "cleared" else _LEVEL.get(
            str(transition["severity"]), LogLevel.Warning)  # fmt: skip
        text = f"{kind} {transition['severity']}: {transition['message']}"
        self.log_line(mill, "alarms", int(transition["t_ns"]), level,
                      str(transition.get("rule", transition["alarm_id"])), text)  # fmt: skip
        self.counts.alarms += 1

    def damage(self, mill: str, component: str, t_ns: int, committed: float, total: float) -> None:
        """Miner damage booked so far (``millwatch.Damage``) at ``t_ns``."""
        self.numbers(topic(mill, "damage", component), DAMAGE_SCHEMA, t_ns, [committed, total])
        self.counts.damage += 1
