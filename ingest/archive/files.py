"""Archive files: the encoding, the file names, their order, and positions in the log.

The archive is millwatch's log: every zenoh message is written *first* and
*byte-identical* as received, one MCAP channel per key (topic = key expression).

Encoding choice
---------------
Byte-identical raw payloads and "Foxglove can plot it" are in tension: Foxglove
plots only well-known encodings (CDR/ros2msg, JSON, protobuf, …), and wrapping the
payload in any of those changes the bytes (CDR adds an encapsulation header and a
length prefix). We choose **byte-identical**:

- channel ``message_encoding = "millwatch.block.v1"``: message data *is* the wire
  payload of :mod:`millwatch.ingest.wire`, untouched;
- one schema per file, name ``millwatch.block.v1``, encoding
  ``millwatch.block.v1.layout``, whose data is the human-readable byte layout (the
  :mod:`millwatch.ingest.wire` docstring), so every file documents itself.

Reasons: (1) malformed blocks must be archived as received (DESIGN: "archived as-is
if possible"), which no typed schema can hold; (2) replay and crash recovery must
feed the analyzer exactly the bytes live ingest saw, so results are identical;
(3) a checksum of a payload means the same thing on the wire and in the archive.
Standard MCAP tools (``mcap info``, ``mcap cat``, ``mcap.reader.make_reader``) list
and read these files; plotting in Foxglove needs the derived export of
:mod:`millwatch.ingest.archive.foxglove_export` (``millwatch archive export``).

Time base: a message's MCAP ``log_time`` (and ``publish_time``) is the time the worker
*received* the block (wall clock), which is what orders the log and positions checkpoints.
The time of the samples is in the block itself: wire header ``t0``, sample ``i`` at
``t0 + i·1e9/fs``. The two differ by the transport delay live, and by anything at all for a
replayed or simulated archive; the Foxglove export stamps every message with sample time.

Files
-----
Files are named ``<prefix>_<YYYYmmddTHHMMSS>Z.mcap`` after the UTC log time of their
first message (``-<n>`` is appended on a name clash, e.g. a size rotation within one
second); :func:`archive_file_order` sorts them, and an :class:`ArchivePosition` (file,
index) names a point in the log for checkpoints.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

__all__ = [
    "LIBRARY",
    "MCAP_MAGIC",
    "MESSAGE_ENCODING",
    "PREFIX_RE",
    "PROFILE",
    "SCHEMA_ENCODING",
    "SCHEMA_NAME",
    "ArchiveError",
    "ArchivePosition",
    "archive_file_name",
    "archive_file_order",
    "list_archive_files",
]

MESSAGE_ENCODING = "millwatch.block.v1"
SCHEMA_NAME = "millwatch.block.v1"
SCHEMA_ENCODING = "millwatch.block.v1.layout"
PROFILE = "millwatch"
LIBRARY = "millwatch-archive/1"
MCAP_MAGIC = b"\x89MCAP0\r\n"
PREFIX_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}")
"""What a writer's file prefix may be (it becomes part of every file name)."""
_FILE_RE = re.compile(r"(?P<prefix>.+)_(?P<ts>\d{8}T\d{6})Z(?:-(?P<n>\d{1,6}))?\.mcap")


class ArchiveError(Exception):
    """A file is not a readable millwatch MCAP archive."""


@dataclass(frozen=True, slots=True)
class ArchivePosition:
    """A point in the archive log, for checkpoints.

    ``file`` is the base name of an archive file; the first ``index`` messages of that
    file (file order) lie before the position; ``log_time_ns`` is the log time of the
    last of them (0 if ``index == 0``), ns since the Unix epoch (UTC).
    """

    file: str
    index: int
    log_time_ns: int = 0

    def as_dict(self) -> dict[str, str | int]:
        """JSON-ready form."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, str | int]) -> ArchivePosition:
        """Inverse of :meth:`as_dict`."""
        return cls(str(data["file"]), int(data["index"]), int(data.get("log_time_ns", 0)))


def archive_file_name(prefix: str, log_time_ns: int, clash: int = 0) -> str:
    """``<prefix>_<YYYYmmddTHHMMSS>Z[-<clash>].mcap`` for a UTC log time in ns."""
    stamp = datetime.fromtimestamp(log_time_ns // 1_000_000_000, tz=UTC).strftime("%Y%m%dT%H%M%S")
    suffix = "" if clash == 0 else "-" + str(clash)
    return prefix + "_" + stamp + "Z" + suffix + ".mcap"


def archive_file_order(name: str) -> tuple[str, int]:
    """Sort key of an archive file's base name: the files of one prefix in archive order (so
    positions in different files compare by it); :class:`ArchiveError` if not an archive name."""
    match = _FILE_RE.fullmatch(name)
    if match is None:
        raise ArchiveError(f"not an archive file name: {name!r}")
    return match["ts"], int(match["n"] or 0)


def list_archive_files(directory: str | Path, prefix: str) -> list[Path]:
    """Archive files of ``prefix`` in ``directory``, oldest first."""
    names = [
        p.name
        for p in Path(directory).glob(prefix + "_*.mcap")
        if (m := _FILE_RE.fullmatch(p.name)) is not None and m["prefix"] == prefix
    ]
    return [Path(directory) / n for n in sorted(names, key=archive_file_order)]
