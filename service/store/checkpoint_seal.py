"""Checkpoints sealed with a checksum, verified before anything of them is used.

A checkpoint row holds the archive position (JSON) and the mill's snapshot (JSON, ~2 MB for a
mill with spectra). A damaged row — truncated by a failing disk or a careless edit, or a bit
flipped on the way — must be *refused* with a message that names the mill and the store, not
parsed into a worker that stops every mill ("Unterminated string … char 96754") or, worse,
accepted: a single flipped bit in a number once became a damage projection of 2.16e+295.

The snapshot is stored as one header line and the JSON::

    millwatch-checkpoint 1 sha256=<64 hex digits> length=<characters of the JSON>
    {"pipelines": …}

The SHA-256 covers the position's JSON, a newline and the snapshot's JSON (ASCII, as
``json.dumps`` writes it), so a changed position is caught as well. ``length`` tells a
truncated row (fewer characters than written) from a changed one. Rows written by an older
millwatch (the JSON alone, starting with ``{``) are still read, with :attr:`Opened.sealed`
False, so the worker can say they were not verified.

The row is written in one SQLite transaction (the store's WAL), which is atomic: a crash
mid-write leaves the previous rows as they were, never half a row.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from typing import Any

__all__ = ["CheckpointDamaged", "Opened", "seal", "unseal"]

_MAGIC = "millwatch-checkpoint"
_VERSION = 1
_HEADER = re.compile(rf"{_MAGIC} (\d+) sha256=([0-9a-f]{{64}}) length=(\d+)")


class CheckpointDamaged(ValueError):
    """A stored checkpoint is not what was written (truncated, changed, not JSON); the message
    says what is wrong in words (the caller adds the mill and the store)."""


@dataclass(frozen=True)
class Opened:
    """A verified checkpoint: its archive ``position`` and ``state`` (both parsed JSON), and
    whether it was ``sealed`` (False: written by an older millwatch, taken unverified)."""

    position: dict[str, Any]
    state: dict[str, Any]
    sealed: bool


def _digest(position_text: str, state_text: str) -> str:
    """SHA-256 (hex) of the position, a newline and the state (fed in parts: no 2 MB copy)."""
    digest = hashlib.sha256(position_text.encode())
    digest.update(b"\n")
    digest.update(state_text.encode())
    return digest.hexdigest()


def seal(position_text: str, state_text: str) -> str:
    """The stored form of a snapshot's JSON ``state_text`` taken at the archive position
    ``position_text`` (JSON): the header line with its checksum and length, then the JSON."""
    header = f"{_MAGIC} {_VERSION} sha256={_digest(position_text, state_text)} "
    return f"{header}length={len(state_text)}\n{state_text}"


def unseal(position_text: str, stored: str) -> Opened:
    """Verify and parse a stored checkpoint (as :func:`seal` wrote it, or an older unsealed
    one); :class:`CheckpointDamaged` saying what is wrong when it is not intact."""
    if stored.startswith("{"):
        return Opened(_parse(position_text, "archive position"), _parse(stored, "snapshot"), False)
    head, newline, body = stored.partition("\n")
    found = _HEADER.fullmatch(head)
    if not newline and head.startswith(_MAGIC):
        raise CheckpointDamaged(f"it is truncated within its header ({len(head)} characters)")
    if not newline or found is None:
        raise CheckpointDamaged(f"its header is damaged (begins {head[:60]!r})")
    version, digest, length = int(found[1]), found[2], int(found[3])
    if version != _VERSION:
        raise CheckpointDamaged(f"it has format version {version}, this millwatch reads "
                                f"{_VERSION}")  # fmt: skip
    if len(body) != length:
        what = "truncated" if len(body) < length else "longer than written"
        raise CheckpointDamaged(f"it is {what}: {len(body)} of {length} characters")
    if _digest(position_text, body) != digest:
        raise CheckpointDamaged("its SHA-256 checksum does not match its content (changed "
                                "since it was written, e.g. a flipped bit)")  # fmt: skip
    return Opened(_parse(position_text, "archive position"), _parse(body, "snapshot"), True)


def _parse(text: str, what: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise CheckpointDamaged(f"its {what} is not valid JSON ({exc})") from exc
    if not isinstance(value, dict):
        raise CheckpointDamaged(f"its {what} is not a JSON object")
    return value
