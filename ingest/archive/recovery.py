"""Archive recovery: rewrite a file whose writer died into a finished, indexed MCAP file.

:func:`recover_file` copies every complete message of the file (read by
:class:`~millwatch.ingest.archive.reader.TailTolerantReader`: byte-identical, same log/publish
times and
sequence numbers, schemas and channels registered as they come) into a new file with summary
and footer, drops the torn tail, and reports what was kept and dropped (:class:`RecoveryReport`).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Channel, Schema
from mcap.writer import CompressionType, Writer

from millwatch.ingest.archive.files import LIBRARY, PROFILE
from millwatch.ingest.archive.reader import RawMessage, TailTolerantReader

__all__ = ["RecoveryReport", "recover_file"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class RecoveryReport:
    """Outcome of :func:`recover_file`. Times in ns since the Unix epoch (UTC)."""

    src: Path
    dst: Path | None
    was_finished: bool
    messages: int
    channels: int
    valid_bytes: int
    dropped_bytes: int
    first_log_time_ns: int | None
    last_log_time_ns: int | None
    last_log_time_by_key: dict[str, int]
    error: str | None

    def summary(self) -> str:
        """One human-readable line for the CLI."""
        state = "already finished" if self.was_finished else "recovered"
        return (
            f"{self.src}: {state}; {self.messages} messages on {self.channels} channels, "
            f"{self.dropped_bytes} trailing bytes dropped"
            + (f" ({self.error})" if self.error else "")
            + (f" -> {self.dst}" if self.dst else "")
        )


@dataclass(slots=True)
class _Stats:
    last_by_key: dict[str, int] = field(default_factory=dict)
    first: int | None = None
    last: int | None = None

    def observe(self, msg: RawMessage) -> None:
        t = msg.log_time_ns
        self.first = t if self.first is None else min(self.first, t)
        self.last = t if self.last is None else max(self.last, t)
        self.last_by_key[msg.key] = max(self.last_by_key.get(msg.key, t), t)


@dataclass(slots=True)
class _Copier:
    writer: Writer
    schema_ids: dict[int, int] = field(default_factory=dict)
    channel_ids: dict[int, int] = field(default_factory=dict)

    def copy(self, reader: TailTolerantReader, msg: RawMessage) -> None:
        new_channel = self._channel(reader, msg.channel)
        self.writer.add_message(
            new_channel, log_time=msg.log_time_ns, data=msg.payload,
            publish_time=msg.publish_time_ns, sequence=msg.sequence,
        )  # fmt: skip

    def _channel(self, reader: TailTolerantReader, channel: Channel) -> int:
        if channel.id not in self.channel_ids:
            schema_id = self._schema(reader.schemas.get(channel.schema_id))
            self.channel_ids[channel.id] = self.writer.register_channel(
                channel.topic, channel.message_encoding, schema_id, dict(channel.metadata)
            )
        return self.channel_ids[channel.id]

    def _schema(self, schema: Schema | None) -> int:
        if schema is None:
            return 0
        if schema.id not in self.schema_ids:
            self.schema_ids[schema.id] = self.writer.register_schema(
                schema.name, schema.encoding, schema.data
            )
        return self.schema_ids[schema.id]


def _scan(src: Path) -> tuple[TailTolerantReader, _Stats]:
    reader, stats = TailTolerantReader(src), _Stats()
    for msg in reader.messages():
        stats.observe(msg)
    return reader, stats


def _rewrite(src: Path, tmp: Path) -> tuple[TailTolerantReader, _Stats]:
    reader, stats = TailTolerantReader(src), _Stats()
    with open(tmp, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile=PROFILE, library=LIBRARY + " (recovered)")
        copier = _Copier(writer)
        for msg in reader.messages():
            copier.copy(reader, msg)
            stats.observe(msg)
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
    return reader, stats


def recover_file(src: str | Path, dst: str | Path | None = None) -> RecoveryReport:
    """Rewrite an MCAP file whose writer died into a finished, indexed file.

    Keeps every complete message (byte-identical, same log/publish times and sequence
    numbers) and drops the torn tail. ``dst=None`` replaces ``src`` atomically (via a
    ``.recovering`` temp file) and leaves an already finished ``src`` untouched; with
    ``dst`` the rewrite always happens. Returns what was kept and dropped. Never run it
    on the file a live :class:`ArchiveWriter` is still appending to.
    """
    src = Path(src)
    if dst is None:
        probe, stats = _scan(src)
        if probe.finished:
            return _report(src, None, probe, stats)
    target = src if dst is None else Path(dst)
    tmp = target.with_name(target.name + ".recovering")
    try:
        reader, stats = _rewrite(src, tmp)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, target)
    log.info("archive: recovered %s -> %s (%d messages)", src, target, reader.message_count)
    return _report(src, target, reader, stats)


def _report(
    src: Path, dst: Path | None, reader: TailTolerantReader, stats: _Stats
) -> RecoveryReport:
    return RecoveryReport(
        src=src, dst=dst, was_finished=reader.finished, messages=reader.message_count,
        channels=len(reader.channels), valid_bytes=reader.valid_bytes,
        dropped_bytes=reader.torn_bytes, first_log_time_ns=stats.first,
        last_log_time_ns=stats.last, last_log_time_by_key=dict(stats.last_by_key),
        error=reader.error,
    )  # fmt: skip
