"""The alarm board: every alarm's current state in memory, so ``GET /alarms`` costs no SQLite.

Control rooms poll ``/alarms`` every second or so (issue 7: p99 ≤ 20 ms at 200 requests/s from
50 pollers). The board mirrors the store's ``alarms`` table — one record
(:class:`~millwatch.alarms.lifecycle.Alarm`) per alarm — and is fed by whoever sees transitions
first:

* in-process (``millwatch serve``, the demo): the worker's stored transitions
  (:attr:`millwatch.worker.worker.Worker.on_alarms`, after their transaction committed), plus one
  load from the store when the API starts;
* remote (``millwatch api``): the workers' ``…/@alarms`` messages (:mod:`millwatch.alarms.wire`),
  plus a ``…/@query/alarms`` gather when the API starts and whenever a worker (re)joins.

Merging is by the alarm's ``seq`` (it counts the alarm's transitions): a row replaces the board's
only when its ``seq`` is higher, so the same transition arriving twice (store load and callback,
republished after a crash recovery, message and query reply) changes nothing, whatever the order.

Comments: every alarm's entry lists its comments (:class:`~millwatch.alarms.lifecycle.Comment`:
who, when, text; the issue's interface puts them in ``/alarms`` as in ``/alarms/{id}``), kept
here beside the rows, so a poll costs no store query for them either. They come with what feeds
the rows — a transition that carries a comment (callback or ``…/@alarms`` message), the
``comments`` of a query reply or an action's answer, every stored comment at the load (one
query, :meth:`millwatch.store.database.Store.alarm_comments`) — and merge as a set keyed by the
transition's ``seq``: the same comment twice is one, whatever the order. A comment new to the
board is a change of its alarm like a newer row (its seq grew with it anyway).

The change cursor: every row the board accepts gets the board's next *change number* (1, 2, …,
in the order the board took them, whatever the alarms' own times), and the board has an *epoch*,
a random id drawn when it is made. A listing's ``cursor`` (:class:`Cursor`, ``"<epoch>-<n>"``) is
the board's change number when the listing was made; ``since=<cursor>`` lists every alarm whose
change number is above it — in its current state, whatever the ``state`` filter (an alarm that
left the states a poller watches comes back once, so it can drop it). Sample time plays no part,
so an acknowledgement of an old alarm, a comment, or a lagging mill's new alarm is never missed
(``updated_ns``, the mill's clock, would miss them). A cursor of another epoch (the API process
restarted, or another replica answered) or one this board never issued gets the whole listing
with ``resync`` true: the poller replaces what it holds, never an empty answer.

Listings are computed once per board *version* (it increments on every change) and filter, and
kept as ready JSON bytes with their ETag (the listed ``(alarm_id, seq)`` pairs and the cursor: it
changes exactly when the body would): a poll that finds its listing cached costs a dict lookup,
and a ``304`` costs no serialisation at all.

Memory: the board holds every alarm ever stored, like the table (about 1 kB each), and every
comment twice (the record, and its listed form with the ISO time, made once).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import secrets
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields
from typing import Any

from millwatch.alarms.lifecycle import Alarm, Comment, Transition
from millwatch.alarms.wire import decode_transition
from millwatch.api.times import with_iso

__all__ = ["CURSOR_PATTERN", "AlarmBoard", "Cursor", "Listing", "row_from_dict", "row_to_dict"]

MAX_CACHED_LISTINGS = 256
_ROW_FIELDS = frozenset(f.name for f in fields(Alarm))


CURSOR_PATTERN = r"^[0-9a-f]{8}-[0-9]{1,19}$"
"""What a change cursor looks like: ``<epoch>-<change number>`` (module docstring)."""
_CURSOR = re.compile(CURSOR_PATTERN)


@dataclass(frozen=True, slots=True)
class Cursor:
    """A point in a board's changes: its ``epoch`` (8 hex digits) and a change number."""

    epoch: str
    change: int

    def __str__(self) -> str:
        return f"{self.epoch}-{self.change}"

    @classmethod
    def parse(cls, text: str) -> Cursor:
        """The cursor ``"<epoch>-<n>"``; ``ValueError`` naming the text when it is not one."""
        if not _CURSOR.match(text):
            raise ValueError(f"{text[:40]!r} is not a cursor (<8 hex digits>-<number>)")
        epoch, change = text.split("-")
        return cls(epoch, int(change))


@dataclass(frozen=True, slots=True)
class Listing:
    """One ``/alarms`` answer: the JSON body (bytes), its ETag, and the board version."""

    body: bytes
    etag: str
    version: int


def _finite(value: Any) -> Any:
    return None if isinstance(value, float) and not math.isfinite(value) else value


def row_from_dict(data: dict[str, Any]) -> Alarm:
    """An :class:`~millwatch.alarms.lifecycle.Alarm` from its plain fields (extra keys, e.g.
    ``transitions``, ignored)."""
    return Alarm.from_dict({k: v for k, v in data.items() if k in _ROW_FIELDS})


def row_to_dict(row: Alarm) -> dict[str, Any]:
    """Strict-JSON plain data of an alarm (non-finite numbers become None)."""
    return {k: _finite(v) for k, v in row.to_dict().items()}


def _listing_etag(rows: list[Alarm], cursor: Cursor) -> str:
    """Strong ETag of a listing: the listed ``(alarm_id, seq)`` pairs (as
    :func:`millwatch.api.alarm_views.etag`) and the cursor the body carries, so the tag changes
    exactly when the body would."""
    h = hashlib.blake2b(digest_size=12)
    h.update(f"{cursor};".encode())
    for r in rows:
        h.update(f"{r.alarm_id}:{r.seq};".encode())
    return f'"{len(rows)}-{h.hexdigest()}"'


def _encode(body: dict[str, Any]) -> bytes:
    """JSON bytes as Starlette's ``JSONResponse`` renders them."""
    return json.dumps(
        body, ensure_ascii=False, allow_nan=False, indent=None, separators=(",", ":")
    ).encode("utf-8")


class AlarmBoard:
    """Current state of every alarm, versioned; see the module docstring. Thread-safe: writers
    are the worker thread or zenoh callbacks, readers the API's event loop."""

    def __init__(self, epoch: str | None = None) -> None:
        self._rows: dict[str, Alarm] = {}
        self._lock = threading.Lock()
        self._version = 0
        self._sorted: list[Alarm] | None = None
        self._listings: dict[tuple[tuple[str, ...], int | Cursor | None, str | None], Listing] = {}
        self.epoch = secrets.token_hex(4) if epoch is None else epoch
        """This board's epoch: 8 hex digits, random unless given (tests)."""
        self._change = 0
        # alarm id → its change number, in change order (a changed row is moved to the end)
        self._changes: dict[str, int] = {}
        # alarm id → its comments, oldest (lowest seq) first; a tuple replaced whole on change
        self._comments: dict[str, tuple[Comment, ...]] = {}
        # (alarm id, seq) → the comment as listed (ISO time added), made once: comments never
        # change, and adding the ISO times is most of a listing's rendering
        self._comment_bodies: dict[tuple[str, int], dict[str, Any]] = {}

    @property
    def version(self) -> int:
        """Increments on every change of the board."""
        return self._version

    @property
    def cursor(self) -> Cursor:
        """The board's latest change: ``since`` this lists nothing until the next change."""
        return Cursor(self.epoch, self._change)

    def __len__(self) -> int:
        return len(self._rows)

    # ------------------------------------------------------------------ writing
    def merge(self, rows: Iterable[Alarm], comments: Iterable[tuple[str, Comment]] = ()) -> int:
        """Take the rows that are newer (higher ``seq``) than the board's and the ``(alarm id,
        comment)`` pairs it does not hold yet (module docstring); returns how many alarms
        changed."""
        with self._lock:
            touched = [row.alarm_id for row in rows if self._take_row(row)]
            touched += [alarm_id for alarm_id, c in comments if self._take_comment(alarm_id, c)]
            changed = [a for a in dict.fromkeys(touched) if a in self._rows]
            for alarm_id in changed:
                self._change += 1
                self._changes.pop(alarm_id, None)
                self._changes[alarm_id] = self._change
            if changed:
                self._version += 1
                self._sorted = None
                self._listings = {}
        return len(changed)

    def _take_row(self, row: Alarm) -> bool:
        old = self._rows.get(row.alarm_id)
        if old is not None and row.seq <= old.seq:
            return False
        self._rows[row.alarm_id] = row
        return True

    def _take_comment(self, alarm_id: str, comment: Comment) -> bool:
        held = self._comments.get(alarm_id, ())
        if any(c.seq == comment.seq for c in held):
            return False
        self._comment_bodies[(alarm_id, comment.seq)] = with_iso(comment.to_dict())
        self._comments[alarm_id] = tuple(sorted((*held, comment), key=lambda c: c.seq))
        return True

    def apply_transitions(self, transitions: Iterable[Transition]) -> int:
        """Merge the alarms' states and comments after stored transitions
        (``Worker.on_alarms``)."""
        transitions = list(transitions)
        notes = [(t.alarm_id, c) for t in transitions if (c := Comment.of(t)) is not None]
        return self.merge((t.alarm for t in transitions), notes)

    def apply_message(self, payload: bytes) -> int:
        """Merge one ``…/@alarms`` message (the alarm, and the comment its transition carried);
        raises :class:`millwatch.alarms.wire.AlarmWireError`."""
        message = decode_transition(payload)
        row = row_from_dict(message["alarm"])
        step = message["transition"]
        comment = Comment.of_row(step) if step.get("comment") else None
        return self.merge([row], [] if comment is None else [(row.alarm_id, comment)])

    def merge_entries(self, entries: Iterable[Mapping[str, Any]]) -> int:
        """Merge alarms as plain data with their ``comments`` (:meth:`entry`'s, a query reply's,
        ``/alarms/{id}``'s, an action's answer); returns how many alarms changed."""
        rows, notes = [], []
        for entry in entries:
            row = row_from_dict(dict(entry))
            rows.append(row)
            notes += [(row.alarm_id, Comment.from_dict(c)) for c in entry.get("comments", ())]
        return self.merge(rows, notes)

    # ------------------------------------------------------------------ reading
    def get(self, alarm_id: str) -> Alarm | None:
        """One alarm's current state, or None."""
        return self._rows.get(alarm_id)

    def comments(self, alarm_id: str) -> tuple[Comment, ...]:
        """One alarm's comments, oldest first."""
        return self._comments.get(alarm_id, ())

    def entry(self, row: Alarm) -> dict[str, Any]:
        """An alarm's ``/alarms`` entry as plain data (no ISO times): :func:`row_to_dict` and
        its ``comments``. (Read without the lock: a comment tuple is replaced whole, so at
        worst a comment that arrived while this was made is listed one version early.)"""
        notes = self._comments.get(row.alarm_id, ())
        return {**row_to_dict(row), "comments": [c.to_dict() for c in notes]}

    def _listed(self, row: Alarm) -> dict[str, Any]:
        """:meth:`entry` with ISO-8601 beside every ``_ns`` (the comments' made once)."""
        notes = self._comments.get(row.alarm_id, ())
        bodies = [self._comment_bodies[(row.alarm_id, c.seq)] for c in notes]
        return {**with_iso(row_to_dict(row)), "comments": bodies}

    def rows(self, mill_id: str | None = None) -> list[Alarm]:
        """Alarms (of one mill), most recently changed first."""
        ordered = self._ordered()
        return ordered if mill_id is None else [r for r in ordered if r.mill_id == mill_id]

    def listing(
        self, states: tuple[str, ...], since: int | Cursor | None, mill_id: str | None
    ) -> Listing:
        """The ``/alarms`` answer for a filter (states: empty for all), cached per version.
        ``since``: a :class:`Cursor` (the changes after it, module docstring) or ns UTC (a
        sample-time filter: ``updated_ns`` at or after it)."""
        key = (states, since, mill_id)
        cached = self._listings.get(key)
        if cached is not None and cached.version == self._version:
            return cached
        with self._lock:
            version, cursor = self._version, self.cursor
            issued = isinstance(since, Cursor) and self._issued(since)
            if isinstance(since, Cursor) and issued:
                candidates = self._changed_after(since.change)
            else:
                candidates = self._ordered_locked()
        wanted = set(() if issued else states)
        since_ns = since if isinstance(since, int) else None
        rows = [
            r
            for r in candidates
            if (not wanted or r.state in wanted)
            and (since_ns is None or r.updated_ns >= since_ns)
            and (mill_id is None or r.mill_id == mill_id)
        ]
        alarms = [self._listed(r) for r in rows]
        body = {"alarms": alarms, "count": len(rows), "cursor": str(cursor),
                "resync": isinstance(since, Cursor) and not issued}  # fmt: skip
        listing = Listing(_encode(body), _listing_etag(rows, cursor), version)
        with self._lock:
            if len(self._listings) >= MAX_CACHED_LISTINGS:
                self._listings = {}
            if version == self._version:
                self._listings[key] = listing
        return listing

    def _issued(self, cursor: Cursor) -> bool:
        """Whether this board issued ``cursor`` (its epoch, not beyond its latest change)."""
        return cursor.epoch == self.epoch and cursor.change <= self._change

    def _changed_after(self, change: int) -> list[Alarm]:
        """The rows changed after ``change``, most recently changed first (under the lock)."""
        out = []
        for alarm_id in reversed(self._changes):
            if self._changes[alarm_id] <= change:
                break
            out.append(self._rows[alarm_id])
        out.sort(key=lambda r: (-r.updated_ns, r.alarm_id))
        return out

    def _ordered(self) -> list[Alarm]:
        with self._lock:
            return self._ordered_locked()

    def _ordered_locked(self) -> list[Alarm]:
        if self._sorted is None:
            self._sorted = sorted(self._rows.values(), key=lambda r: (-r.updated_ns, r.alarm_id))
        return self._sorted
