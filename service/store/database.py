"""The embedded store: SQLite in WAL mode, schema versioned with forward migrations.

What the worker keeps (README "Persistence and recovery"): events (starts, stops, barring,
data quality, alarms' transitions later), damage per mill, component, phase and day, per-day
rainflow matrices, steady-state metrics and harmonic tables as timestamped records, and
checkpoints: analyzer snapshots with the archive position they correspond to, one per part
(mill), each part written on its own.

Design notes:

* One writer (the worker thread) and any number of readers (the API): WAL mode lets readers see
  a consistent snapshot while the writer appends. ``synchronous=NORMAL`` is durable across a
  process crash (the MCAP archive is the log; a power cut loses at most the last transactions,
  which recovery rebuilds from the archive tail).
* Everything one analyzed frame produces is written in one transaction
  (:meth:`Store.transaction`), and the checkpoint that covers it is written in the same way, so
  after a crash the store never holds results newer than its last checkpoint plus replay.
* Damage rows (with their cycle counts) and phase seconds are *set*, not added: the worker
  writes each day's running totals (kept in the analyzer), so replaying the archive tail after a
  crash is idempotent.
* A failed write (a full disk: ``database or disk is full``) rolls its transaction back and
  raises; the worker keeps what it wanted to write and tries again
  (:meth:`millwatch.worker.worker.Worker.commit`). A store file deleted while the service runs
  is noticed (:meth:`Store.file_state`) and written again whole from the open connection
  (:meth:`Store.restore_file`: SQLite's online backup), so nothing stored is lost with it.
* Opening a file migrates it (:mod:`millwatch.store.migrations`); rows are mapped by column name
  (:mod:`millwatch.store.records`); the JSON ``records`` are read column-wise by
  :mod:`millwatch.store.sampler`.
"""

from __future__ import annotations

import json
import os
import sqlite3
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from millwatch.alarms.lifecycle import Alarm, Comment, TransitionRecord
from millwatch.analytics.mill.phase_damage import phase_totals
from millwatch.store import migrations, sampler
from millwatch.store.checkpoint_seal import CheckpointDamaged, Opened, seal, unseal
from millwatch.store.migrations import StoreError
from millwatch.store.records import (
    DamageRow,
    EventRow,
    PhaseRow,
    column_list,
    columns,
    from_row,
    to_params,
)

__all__ = ["CHECKPOINTS_KEPT", "CheckpointChoice", "RefusedCheckpoint", "Store"]

#: Checkpoints kept per part (older ones of the part are deleted when a new one is written).
CHECKPOINTS_KEPT = 2

_ALARM_UPSERT = (
    f"INSERT INTO alarms ({column_list(Alarm)}) VALUES ({', '.join('?' * len(columns(Alarm)))}) "
    "ON CONFLICT (alarm_id) DO UPDATE SET "
    + ", ".join(f"{c} = excluded.{c}" for c in columns(Alarm) if c != "alarm_id")
    + " WHERE excluded.seq >= alarms.seq"
)
_TRANSITION_INSERT = (
    f"INSERT OR REPLACE INTO alarm_transitions ({column_list(TransitionRecord)}) "
    f"VALUES ({', '.join('?' * len(columns(TransitionRecord)))})"
)


@dataclass(frozen=True)
class RefusedCheckpoint:
    """A kept checkpoint that is not intact (:mod:`millwatch.store.checkpoint_seal`): its part
    (mill), row id, when it was written (ns UTC) and what is wrong with it."""

    part: str
    checkpoint_id: int
    created_ns: int
    reason: str


@dataclass
class CheckpointChoice:
    """Per part, the newest intact kept checkpoint (``parts``: ``part → (position, state)``),
    the newer ones refused on the way (``refused``, newest first per part), the row id and
    write time of each chosen one (``chosen``), and the parts whose chosen checkpoint was
    written by an older millwatch without a checksum (``unsealed``: taken unverified)."""

    parts: dict[str, tuple[dict[str, Any], dict[str, Any]]] = field(default_factory=dict)
    refused: list[RefusedCheckpoint] = field(default_factory=list)
    chosen: dict[str, tuple[int, int]] = field(default_factory=dict)
    unsealed: list[str] = field(default_factory=list)


class Store:
    """A SQLite store file; thread-safe: one writing connection serialised by a lock, and a
    read-only connection per reading thread."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._db = self._connect()
        except sqlite3.Error as exc:
            raise StoreError(f"{self.path}: cannot open the store ({exc})") from exc
        self._lock = threading.RLock()
        self._local = threading.local()
        self._readers: list[sqlite3.Connection] = []
        migrations.migrate(self._db, str(self.path))
        self._identity = _identity(self.path)
        #: Bumped when the file is written anew (:meth:`restore_file`): readers reconnect.
        self._generation = 0

    # ------------------------------------------------------------------ schema
    @property
    def schema_version(self) -> int:
        return migrations.schema_version(self._db)

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """One atomic write (``BEGIN IMMEDIATE`` … ``COMMIT``, rolled back on error)."""
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
                self._db.execute("COMMIT")
            except BaseException:
                if self._db.in_transaction:  # (a failed COMMIT may leave it open, or not)
                    self._db.execute("ROLLBACK")
                raise

    # ------------------------------------------------------------------ the file itself
    def file_state(self) -> Literal["ok", "deleted", "replaced"]:
        """Whether the store's file is still the one opened: ``deleted`` when no file is at its
        path any more (the open connection still writes into the deleted one, which would be
        gone at the next start), ``replaced`` when another file is there."""
        now = _identity(self.path)
        if now is None:
            return "deleted"
        return "ok" if now == self._identity else "replaced"

    def restore_file(self) -> None:
        """Write the store anew at its path from the open connection (SQLite's online backup:
        everything committed, acknowledgements included), then write and read there; after
        :meth:`file_state` said ``deleted``. Raises :class:`sqlite3.Error` or
        :class:`OSError` when it cannot (tried again by the caller)."""
        with self._lock:
            if _identity(self.path) is not None:
                raise StoreError(f"{self.path}: a file is there; not overwritten")
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_name(self.path.name + ".restoring")
            tmp.unlink(missing_ok=True)
            target = sqlite3.connect(tmp)
            try:
                self._db.backup(target)
                target.execute("PRAGMA journal_mode=WAL")
            finally:
                target.close()
            os.replace(tmp, self.path)
            old, self._db = self._db, self._connect()
            old.close()
            self._identity = _identity(self.path)
            self._generation += 1

    def _connect(self) -> sqlite3.Connection:
        db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=NORMAL")
        db.execute("PRAGMA busy_timeout=5000")
        return db

    def close(self) -> None:
        with self._lock:
            for db in self._readers:
                db.close()
            self._readers.clear()
            self._db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ writing
    def put_mill(self, mill_id: str, site: str, config: dict[str, Any], now_ns: int) -> None:
        with self.transaction() as db:
            db.execute(
                "INSERT INTO mills VALUES (?, ?, ?, ?) ON CONFLICT (mill_id) DO UPDATE SET "
                "site = excluded.site, config_json = excluded.config_json, "
                "updated_ns = excluded.updated_ns",
                (mill_id, site, json.dumps(config), now_ns),
            )

    @staticmethod
    def add_events(db: sqlite3.Connection, events: Sequence[EventRow]) -> None:
        """Insert events (inside :meth:`transaction`); an event already stored (same mill,
        kind, time and subject, e.g. re-derived while replaying the archive tail) is replaced."""
        db.executemany(
            "INSERT OR REPLACE INTO events (mill_id, kind, t_ns, t_end_ns, data_json, subject) "
            "VALUES (?, ?, ?, ?, ?, ?)",
            [
                (e.mill_id, e.kind, e.t_ns, e.t_end_ns, json.dumps(e.data), e.subject)
                for e in events
            ],
        )

    @staticmethod
    def set_damage(db: sqlite3.Connection, rows: Sequence[DamageRow]) -> None:
        """Set running daily totals (inside :meth:`transaction`); idempotent."""
        db.executemany(
            f"INSERT OR REPLACE INTO damage_daily ({column_list(DamageRow)}) "
            f"VALUES ({', '.join('?' * len(columns(DamageRow)))})",
            [to_params(DamageRow, r) for r in rows],
        )

    @staticmethod
    def set_phases(db: sqlite3.Connection, rows: Sequence[PhaseRow]) -> None:
        """Set running daily phase seconds (inside :meth:`transaction`); idempotent."""
        db.executemany(
            f"INSERT OR REPLACE INTO phase_daily ({column_list(PhaseRow)}) "
            f"VALUES ({', '.join('?' * len(columns(PhaseRow)))})",
            [to_params(PhaseRow, r) for r in rows],
        )

    @staticmethod
    def extend_days(
        db: sqlite3.Connection, spans: Mapping[tuple[str, str], tuple[int, int]]
    ) -> None:
        """Widen each ``(mill, local day)``'s monitored span to include ``(first_ns,
        last_ns)`` (inside :meth:`transaction`); idempotent, so a replayed archive tail changes
        nothing."""
        db.executemany(
            "INSERT INTO mill_days (mill_id, day, first_ns, last_ns) VALUES (?, ?, ?, ?) "
            "ON CONFLICT (mill_id, day) DO UPDATE SET "
            "first_ns = min(first_ns, excluded.first_ns), last_ns = max(last_ns, excluded.last_ns)",
            [(m, d, int(a), int(b)) for (m, d), (a, b) in spans.items()],
        )

    @staticmethod
    def add_record(
        db: sqlite3.Connection, mill_id: str, kind: str, t_ns: int, data: dict[str, Any]
    ) -> None:
        """A timestamped record (steady-state metrics, harmonic table, matrix, health…)."""
        db.execute(
            "INSERT OR REPLACE INTO records (mill_id, kind, t_ns, data_json) VALUES (?, ?, ?, ?)",
            (mill_id, kind, t_ns, json.dumps(data)),
        )

    @staticmethod
    def put_checkpoint(
        db: sqlite3.Connection,
        part: str,
        created_ns: int,
        position: dict[str, Any],
        state: dict[str, Any],
    ) -> int:
        """Store the checkpoint of one ``part`` (e.g. a mill: its analyzer's snapshot) with the
        archive ``position`` it covers (inside :meth:`transaction`), and drop all but the newest
        :data:`CHECKPOINTS_KEPT` of that part. Parts are written one by one, each in a small
        transaction, so no write holds the store for long. The state is sealed with its
        checksum (:func:`~millwatch.store.checkpoint_seal.seal`). Returns the state's size in
        bytes."""
        text, where = json.dumps(state), json.dumps(position)
        db.execute(
            "INSERT INTO checkpoint_parts (part, created_ns, position_json, state_json) "
            "VALUES (?, ?, ?, ?)",
            (part, created_ns, where, seal(where, text)),
        )
        db.execute(
            "DELETE FROM checkpoint_parts WHERE part = ? AND id NOT IN "
            "(SELECT id FROM checkpoint_parts WHERE part = ? ORDER BY id DESC LIMIT ?)",
            (part, part, CHECKPOINTS_KEPT),
        )
        return len(text)

    @staticmethod
    def put_alarm_transitions(
        db: sqlite3.Connection,
        transitions: Sequence[TransitionRecord],
        alarms: Sequence[Alarm],
    ) -> None:
        """Record alarm transitions (a :class:`~millwatch.alarms.lifecycle.Transition` is one) and
        set the alarms' current state (inside
        :meth:`transaction`). Idempotent: ids and ``seq`` are deterministic, so the archive
        tail replayed after a crash rewrites the same rows; an older state never overwrites a
        newer one (higher ``seq`` wins)."""
        db.executemany(_TRANSITION_INSERT, [to_params(TransitionRecord, t) for t in transitions])
        db.executemany(_ALARM_UPSERT, [to_params(Alarm, a) for a in alarms])

    # ------------------------------------------------------------------ reading
    def alarms(
        self,
        state: str | Sequence[str] | None = None,
        since_ns: int | None = None,
        mill_id: str | None = None,
    ) -> list[Alarm]:
        """Alarms, most recently changed first; ``state`` one state or several (e.g.
        ``("raised", "acknowledged")`` for the open ones), ``since_ns`` changed at or after
        (``updated_ns``, for pollers), optionally of one mill."""
        states = [state] if isinstance(state, str) else list(state or [])
        sql = f"SELECT {column_list(Alarm)} FROM alarms WHERE 1"
        args: list[Any] = []
        if states:
            sql += f" AND state IN ({', '.join('?' * len(states))})"
            args += states
        for clause, value in (("updated_ns >= ?", since_ns), ("mill_id = ?", mill_id)):
            if value is not None:
                sql += " AND " + clause
                args.append(value)
        rows = self._query_rows(sql + " ORDER BY updated_ns DESC, alarm_id", tuple(args))
        return [from_row(Alarm, r) for r in rows]

    def alarm(self, alarm_id: str) -> Alarm | None:
        """One alarm's current state, or None."""
        sql = f"SELECT {column_list(Alarm)} FROM alarms WHERE alarm_id = ?"
        rows = self._query_rows(sql, (alarm_id,))
        return from_row(Alarm, rows[0]) if rows else None

    def alarm_transitions(self, alarm_id: str) -> list[TransitionRecord]:
        """An alarm's transitions in order."""
        sql = (f"SELECT {column_list(TransitionRecord)} FROM alarm_transitions "
               "WHERE alarm_id = ? ORDER BY seq")  # fmt: skip
        return [from_row(TransitionRecord, r) for r in self._query_rows(sql, (alarm_id,))]

    def alarm_comments(self) -> list[tuple[str, Comment]]:
        """Every stored comment as ``(alarm id, comment)``, each alarm's oldest first (the
        alarm board's load: :mod:`millwatch.api.alarm_board`)."""
        sql = ("SELECT alarm_id, seq, kind, t_ns, by, comment FROM alarm_transitions "
               "WHERE comment IS NOT NULL AND comment != '' ORDER BY alarm_id, seq")  # fmt: skip
        out = []
        for row in self._query_rows(sql, ()):
            comment = Comment.of_row(row)
            if comment is not None:
                out.append((str(row["alarm_id"]), comment))
        return out

    def alarm_journal(
        self,
        mill_id: str | None,
        from_ns: int,
        to_ns: int,
        after: tuple[int, str, int] | None,
        limit: int,
    ) -> list[sqlite3.Row]:
        """Alarm transitions with ``from_ns`` ≤ ``t_ns`` < ``to_ns`` (of one mill, or all),
        after the position ``after`` = ``(t_ns, alarm_id, seq)``, in that order, at most
        ``limit``; each row has the transition's columns and its alarm's ``mill_id``, ``rule``,
        ``subject``, ``quantity``, ``unit`` and ``simulated`` (``millwatch.api.journal``)."""
        picked = ", ".join(f"t.{c}" for c in columns(TransitionRecord))
        sql = (f"SELECT {picked}, a.mill_id, a.rule, a.subject, a.quantity, a.unit, a.simulated "
               "FROM alarm_transitions t JOIN alarms a ON a.alarm_id = t.alarm_id "
               "WHERE t.t_ns >= ? AND t.t_ns < ?")  # fmt: skip
        args: list[Any] = [from_ns, to_ns]
        if mill_id is not None:
            sql += " AND a.mill_id = ?"
            args.append(mill_id)
        if after is not None:
            sql += " AND (t.t_ns, t.alarm_id, t.seq) > (?, ?, ?)"
            args += after
        sql += " ORDER BY t.t_ns, t.alarm_id, t.seq LIMIT ?"
        return self._query_rows(sql, (*args, limit))

    def operator_actions(
        self, mill_id: str, after_ns: int, kinds: Sequence[str], limit: int = 1000
    ) -> list[sqlite3.Row]:
        """The transitions an operator made (``by`` set, ``kind`` one of ``kinds``) of
        ``mill_id``'s alarms at ``t_ns`` ≥ ``after_ns``, oldest first, at most ``limit``; each
        row has ``alarm_id``, ``seq``, ``kind``, ``t_ns``, ``by``, ``comment`` and the alarm's
        current ``shelving_state`` and ``shelved_until_ns`` (what a returning hot-standby pair
        worker reconciles, :mod:`millwatch.remote.handover`)."""
        marks = ", ".join("?" * len(kinds))
        sql = ("SELECT t.alarm_id, t.seq, t.kind, t.t_ns, t.by, t.comment, a.shelving_state, "
               "a.shelved_until_ns FROM alarm_transitions t JOIN alarms a "
               "ON a.alarm_id = t.alarm_id WHERE a.mill_id = ? AND t.t_ns >= ? "
               f"AND t.by IS NOT NULL AND t.kind IN ({marks}) "
               "ORDER BY t.t_ns, t.alarm_id, t.seq LIMIT ?")  # fmt: skip
        return self._query_rows(sql, (mill_id, after_ns, *kinds, limit))

    def last_operator_action_ns(self, mill_id: str, kinds: Sequence[str]) -> int | None:
        """The time (ns) of ``mill_id``'s newest operator transition (:meth:`operator_actions`),
        or None."""
        marks = ", ".join("?" * len(kinds))
        row = self._query_one(
            "SELECT MAX(t.t_ns) FROM alarm_transitions t JOIN alarms a ON a.alarm_id = t.alarm_id "
            f"WHERE a.mill_id = ? AND t.by IS NOT NULL AND t.kind IN ({marks})",
            (mill_id, *kinds),
        )
        return None if row is None or row[0] is None else int(row[0])

    def latest_checkpoints(self) -> dict[str, tuple[dict[str, Any], dict[str, Any]]]:
        """The newest intact checkpoint of every part: ``part → (position, state)`` (see
        :meth:`choose_checkpoints`, which also says what it refused)."""
        return self.choose_checkpoints().parts

    def choose_checkpoints(self) -> CheckpointChoice:
        """Per part, the newest kept checkpoint that is intact (its checksum verified), the
        newer ones refused; a part none of whose checkpoints is intact has none. Each row is
        read only when the newer ones were refused (a snapshot is ~2 MB)."""
        choice = CheckpointChoice()
        rows = self._query(
            "SELECT part, id, created_ns FROM checkpoint_parts ORDER BY part, id DESC", ()
        )
        for part, row_id, created_ns in rows:
            if part in choice.parts:
                continue
            try:
                opened = self._open_checkpoint(row_id)
            except CheckpointDamaged as exc:
                choice.refused.append(RefusedCheckpoint(part, row_id, created_ns, str(exc)))
                continue
            choice.parts[part] = (opened.position, opened.state)
            choice.chosen[part] = (row_id, created_ns)
            if not opened.sealed:
                choice.unsealed.append(part)
        return choice

    def _open_checkpoint(self, row_id: int) -> Opened:
        """One checkpoint row verified and parsed; :class:`CheckpointDamaged` if it is not
        intact (also when SQLite cannot read its text back)."""
        try:
            row = self._query_one(
                "SELECT position_json, state_json FROM checkpoint_parts WHERE id = ?", (row_id,)
            )
        except sqlite3.Error as exc:  # e.g. text that is no longer UTF-8
            raise CheckpointDamaged(f"it cannot be read ({exc})") from exc
        if row is None or not all(isinstance(v, str) for v in row):
            raise CheckpointDamaged("its position or snapshot is missing or not text")
        return unseal(row[0], row[1])

    def mills(self) -> list[dict[str, Any]]:
        rows = self._query("SELECT mill_id, site, config_json, updated_ns FROM mills", ())
        return [
            {"mill_id": m, "site": s, "config": json.loads(c), "updated_ns": u}
            for m, s, c, u in rows
        ]

    def events(
        self,
        mill_id: str,
        kind: str | None = None,
        since_ns: int | None = None,
        until_ns: int | None = None,
        *,
        limit: int | None = None,
        newest_first: bool = False,
    ) -> list[EventRow]:
        """Events of a mill in time order (``newest_first``: reversed), optionally of one kind,
        in ``[since, until)`` and at most ``limit`` of them."""
        sql = (
            "SELECT mill_id, kind, t_ns, data_json, t_end_ns, subject FROM events WHERE mill_id = ?"
        )
        args: list[Any] = [mill_id]
        for clause, value in (("kind = ?", kind), ("t_ns >= ?", since_ns), ("t_ns < ?", until_ns)):
            if value is not None:
                sql += " AND " + clause
                args.append(value)
        sql += " ORDER BY t_ns DESC, id DESC" if newest_first else " ORDER BY t_ns, id"
        if limit is not None:
            sql += " LIMIT ?"
            args.append(limit)
        rows = self._query_rows(sql, tuple(args))
        return [from_row(EventRow, {**r, "data": json.loads(r["data_json"])}) for r in rows]

    def losses(self, mill_id: str, limit: int = 20) -> list[dict[str, Any]]:
        """The mill's newest ``limit`` unrecoverable losses (the ``sequence_gap`` data-quality
        events: channel, first and last missing sequence number and time, count), newest
        first."""
        rows = self._query_rows(
            "SELECT data_json FROM events WHERE mill_id = ? AND kind = 'data_quality' "
            "AND subject LIKE '%:sequence_gap' ORDER BY t_ns DESC, id DESC LIMIT ?",
            (mill_id, limit),
        )
        return [json.loads(r["data_json"]) for r in rows]

    def damage(
        self, mill_id: str, since_day: str | None = None, until_day: str | None = None
    ) -> list[DamageRow]:
        """Daily damage rows of a mill, oldest first; days in ``[since_day, until_day]``
        (``YYYY-MM-DD``, both included) when given."""
        sql = f"SELECT {column_list(DamageRow)} FROM damage_daily WHERE mill_id = ?"
        args: list[Any] = [mill_id]
        for clause, value in (("day >= ?", since_day), ("day <= ?", until_day)):
            if value is not None:
                sql += " AND " + clause
                args.append(value)
        rows = self._query_rows(sql + " ORDER BY day, component, phase", tuple(args))
        return [from_row(DamageRow, r) for r in rows]

    def phases(self, mill_id: str) -> list[PhaseRow]:
        """Daily phase-seconds rows of a mill, oldest first."""
        sql = f"SELECT {column_list(PhaseRow)} FROM phase_daily WHERE mill_id = ?"
        rows = self._query_rows(sql + " ORDER BY day, phase", (mill_id,))
        return [from_row(PhaseRow, r) for r in rows]

    def phase_seconds(
        self, mill_id: str, since_day: str | None = None, until_day: str | None = None
    ) -> dict[str, float]:
        """Seconds per operating phase of a mill, summed over the local days in ``[since_day,
        until_day]`` (``YYYY-MM-DD``, both included; all days when not given): every phase
        the analyzer knows, 0 for one not seen, as ``millwatch analyze`` reports them
        (:func:`~millwatch.analytics.mill.phase_damage.phase_totals`)."""
        sql = "SELECT phase, seconds FROM phase_daily WHERE mill_id = ?"
        args: list[Any] = [mill_id]
        for clause, value in (("day >= ?", since_day), ("day <= ?", until_day)):
            if value is not None:
                sql += " AND " + clause
                args.append(value)
        rows = self._query(sql + " ORDER BY day, phase", tuple(args))
        return phase_totals((str(phase), float(seconds)) for phase, seconds in rows)

    def mill_span(self, mill_id: str) -> tuple[int | None, int | None]:
        """Time of the first analysed sample and just past the last one (ns), ``None`` before
        any (or in a store written by a millwatch before schema 5)."""
        row = self._query_one("SELECT min(first_ns), max(last_ns) FROM mill_days "
                              "WHERE mill_id = ?", (mill_id,))  # fmt: skip
        return (None, None) if row is None or row[0] is None else (int(row[0]), int(row[1]))

    def mill_days(self, mill_id: str, until_ns: int | None = None) -> list[tuple[str, int, int]]:
        """The monitored time per local day, oldest first: ``(day, first analysed sample,
        just past the last)`` in ns, clipped to before ``until_ns``."""
        sql = "SELECT day, first_ns, last_ns FROM mill_days WHERE mill_id = ?"
        args: list[Any] = [mill_id]
        if until_ns is not None:
            sql += " AND first_ns < ?"
            args.append(until_ns)
        rows = self._query(sql + " ORDER BY day", tuple(args))
        if until_ns is None:
            return [(d, int(a), int(b)) for d, a, b in rows]
        return [(d, int(a), min(int(b), until_ns)) for d, a, b in rows]

    def count_events(
        self, mill_id: str, kind: str, since_ns: int | None = None, until_ns: int | None = None
    ) -> int:
        """Number of events of one kind in ``[since, until)`` (counted on the index)."""
        sql = "SELECT count(*) FROM events WHERE mill_id = ? AND kind = ?"
        args: list[Any] = [mill_id, kind]
        for clause, value in (("t_ns >= ?", since_ns), ("t_ns < ?", until_ns)):
            if value is not None:
                sql += " AND " + clause
                args.append(value)
        row = self._query_one(sql, tuple(args))
        return 0 if row is None else int(row[0])

    def event_times(
        self, mill_id: str, kinds: Sequence[str], since_ns: int, until_ns: int
    ) -> list[EventRow]:
        """Events of some kinds in ``[since, until)`` in time order with only their times and
        ``failed`` flag in ``data`` (extracted by SQLite: no per-event JSON decode)."""
        rows = self._query(
            f"SELECT kind, t_ns, t_end_ns, json_extract(data_json, '$.failed') FROM events "
            f"WHERE mill_id = ? AND kind IN ({', '.join('?' * len(kinds))}) AND t_ns >= ? "
            "AND t_ns < ? ORDER BY t_ns, id",
            (mill_id, *kinds, since_ns, until_ns),
        )
        return [EventRow(mill_id, k, t, {"failed": bool(f)}, e) for k, t, e, f in rows]

    def damage_days(self, mill_id: str) -> tuple[str | None, str | None]:
        """First and last day with damage rows of a mill (``None`` without any)."""
        row = self._query_one("SELECT min(day), max(day) FROM damage_daily WHERE mill_id = ?",
                              (mill_id,))  # fmt: skip
        return (None, None) if row is None else (row[0], row[1])

    def records(
        self,
        mill_id: str,
        kind: str,
        since_ns: int | None = None,
        limit: int | None = None,
        *,
        until_ns: int | None = None,
        every_ns: int | None = None,
        oldest_first: bool = False,
    ) -> list[tuple[int, dict[str, Any]]]:
        """``(t_ns, data)`` records of one kind in ``[since, until)``, newest first (oldest
        first with ``oldest_first``). With ``every_ns`` only the first record of each interval
        of that length (counted from the epoch) is read: the choice is made on the index, so the
        skipped records are never read or decoded."""
        where, args = sampler.record_window(mill_id, kind, since_ns, until_ns, every_ns)
        sql = f"SELECT t_ns, data_json FROM records WHERE {where} ORDER BY t_ns"
        sql += "" if oldest_first else " DESC"
        if limit is not None:
            sql += " LIMIT ?"
            args = (*args, limit)
        return [(t, json.loads(d)) for t, d in self._query(sql, args)]

    def record_stats(
        self, mill_id: str, kind: str, since_ns: int | None = None, until_ns: int | None = None
    ) -> tuple[int, int | None, int | None]:
        """Number of records of one kind in ``[since, until)``, first and last time (read on
        the index only)."""
        where, args = sampler.record_window(mill_id, kind, since_ns, until_ns)
        row = self._query_one(f"SELECT count(*), min(t_ns), max(t_ns) FROM records WHERE {where}",
                              args)  # fmt: skip
        return (0, None, None) if row is None else (int(row[0]), row[1], row[2])

    def record_keys(
        self,
        mill_id: str,
        kind: str,
        paths: Sequence[Sequence[str]],
        since_ns: int | None = None,
        until_ns: int | None = None,
    ) -> list[list[str]]:
        """For each path (keys from the top), the sorted keys of the JSON object there over
        the records of one kind in ``[since, until)``; SQLite reads them without decoding
        records in Python."""
        where, args = sampler.record_window(mill_id, kind, since_ns, until_ns)
        return sampler.record_keys(self._query, where, args, paths)

    def record_fields(
        self,
        mill_id: str,
        kind: str,
        fields: Sequence[Sequence[str]],
        since_ns: int | None = None,
        until_ns: int | None = None,
    ) -> list[tuple[Any, ...]]:
        """``(t_ns, value, …)`` of the records of one kind in ``[since, until)``, oldest first:
        one scalar per field (a key path into the record; ``None`` where absent), extracted by
        SQLite (see :meth:`record_columns`)."""
        return self.record_columns(mill_id, kind, fields, (), since_ns, until_ns)[1]

    def record_columns(
        self,
        mill_id: str,
        kind: str,
        fields: Sequence[Sequence[str]],
        objects: Sequence[Sequence[str]],
        since_ns: int | None = None,
        until_ns: int | None = None,
    ) -> tuple[list[list[str]], list[tuple[Any, ...]]]:
        """Columns of the records of one kind in ``[since, until)``, extracted by SQLite, so a
        month of steady-state windows is read without decoding each record in Python.

        Returns ``(keys, rows)``: for each path in ``objects`` (keys from the top), the sorted
        keys of the JSON object there over all the records; rows ``(t_ns, *fields,
        *objects' values)``, oldest first, one value per field and per object key, ``None``
        where absent. The object keys are read from the first record of each hour and checked
        on every record in the same pass; a second pass reads them all only if some record
        has others. Records SQLite's JSON refuses (``NaN`` and ``Infinity``, which Python's
        json writes) are decoded in Python (:mod:`millwatch.store.sampler`)."""
        where, args = sampler.record_window(mill_id, kind, since_ns, until_ns)
        return sampler.record_columns(self._query, where, args, fields, objects)

    def record_values(
        self, mill_id: str, kind: str, paths: Sequence[Sequence[str]],
        window: tuple[int, int], every_ns: int | None = None,
    ) -> list[tuple[int, list[Any]]]:  # fmt: skip
        """``(t_ns, [value at each key path])`` of the records of one kind in ``window``
        (``[since, until)`` ns; only the first record of each ``every_ns`` interval, found by
        one index seek per interval), oldest first; SQLite extracts the values in one parse
        per record (:func:`millwatch.store.sampler.record_values`)."""
        where, args = sampler.record_window(mill_id, kind, *window, every_ns)
        return sampler.record_values(self._query, where, args, paths)

    @contextmanager
    def read_snapshot(self) -> Iterator[None]:
        """Reads of this thread inside the block see one snapshot of the store (one read
        transaction on its reader connection), whatever the writer commits meanwhile."""
        db = self._reader()
        if db.in_transaction:
            yield
            return
        db.execute("BEGIN")
        try:
            yield
        finally:
            db.execute("COMMIT")

    def _reader(self) -> sqlite3.Connection:
        """This thread's own read-only connection: WAL lets readers see the last commit while
        the writer works, so API reads never wait for the worker's lock or transaction."""
        db = getattr(self._local, "db", None)
        if db is not None and getattr(self._local, "generation", 0) != self._generation:
            db = None  # (the file was written anew: the old connection reads the deleted one)
        if db is None:
            db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, check_same_thread=False)
            db.execute("PRAGMA busy_timeout=5000")
            self._local.db, self._local.generation = db, self._generation
            with self._lock:
                self._readers.append(db)
        return db

    def _query(self, sql: str, args: tuple[Any, ...]) -> list[tuple[Any, ...]]:
        return self._reader().execute(sql, args).fetchall()

    def _query_rows(self, sql: str, args: tuple[Any, ...]) -> list[sqlite3.Row]:
        """Rows addressable by column name (:func:`millwatch.store.records.from_row`)."""
        cursor = self._reader().cursor()
        cursor.row_factory = sqlite3.Row
        return cursor.execute(sql, args).fetchall()

    def _query_one(self, sql: str, args: tuple[Any, ...]) -> tuple[Any, ...] | None:
        return self._reader().execute(sql, args).fetchone()


def _identity(path: Path) -> tuple[int, int] | None:
    """(device, inode) of the file at ``path``; None when there is none."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_dev, st.st_ino
