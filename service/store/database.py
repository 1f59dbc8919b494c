"""The embedded store: SQLite in WAL mode, schema versioned with forward migrations.

What the worker keeps (DESIGN.md "Persistence and recovery"): events (starts, stops, barring,
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
* Damage rows are *set*, not added: the worker writes each day's running totals (exact sums
  kept in the analyzer), so replaying the archive tail after a crash is idempotent.
* Migrations: ``MIGRATIONS[i]`` brings the schema from version ``i`` to ``i + 1``. Opening an
  older file migrates it; opening a file written by a newer millwatch is refused.
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "SCHEMA_VERSION",
    "AlarmRow",
    "AlarmTransitionRow",
    "DamageRow",
    "EventRow",
    "Store",
    "StoreError",
]

log = logging.getLogger(__name__)

MIGRATIONS: tuple[tuple[str, ...], ...] = (
    (  # 0 → 1
        """CREATE TABLE mills (
            mill_id TEXT PRIMARY KEY, site TEXT NOT NULL, config_json TEXT NOT NULL,
            updated_ns INTEGER NOT NULL)""",
        """CREATE TABLE events (
            id INTEGER PRIMARY KEY, mill_id TEXT NOT NULL, kind TEXT NOT NULL,
            t_ns INTEGER NOT NULL, t_end_ns INTEGER, data_json TEXT NOT NULL)""",
        "CREATE INDEX events_by_mill_time ON events (mill_id, kind, t_ns)",
        """CREATE UNIQUE INDEX events_unique ON events (mill_id, kind, t_ns)""",
        """CREATE TABLE damage_daily (
            mill_id TEXT NOT NULL, component TEXT NOT NULL, phase TEXT NOT NULL,
            day TEXT NOT NULL, damage REAL NOT NULL, cycles REAL NOT NULL,
            PRIMARY KEY (mill_id, component, phase, day))""",
        """CREATE TABLE records (
            id INTEGER PRIMARY KEY, mill_id TEXT NOT NULL, kind TEXT NOT NULL,
            t_ns INTEGER NOT NULL, data_json TEXT NOT NULL)""",
        "CREATE UNIQUE INDEX records_unique ON records (mill_id, kind, t_ns)",
        """CREATE TABLE checkpoints (
            id INTEGER PRIMARY KEY, created_ns INTEGER NOT NULL, position_json TEXT NOT NULL,
            state_json TEXT NOT NULL)""",
    ),
    (  # 1 → 2: alarms (current state per alarm) and their transitions (alarms.lifecycle)
        """CREATE TABLE alarms (
            alarm_id TEXT PRIMARY KEY, mill_id TEXT NOT NULL, rule TEXT NOT NULL,
            subject TEXT NOT NULL, quantity TEXT NOT NULL, unit TEXT NOT NULL,
            severity TEXT NOT NULL, state TEXT NOT NULL, condition INTEGER NOT NULL,
            raised_ns INTEGER NOT NULL, updated_ns INTEGER NOT NULL, acked_ns INTEGER,
            acked_by TEXT, cleared_ns INTEGER, value REAL, threshold REAL,
            message TEXT NOT NULL, seq INTEGER NOT NULL)""",
        "CREATE INDEX alarms_by_state ON alarms (state, updated_ns)",
        "CREATE INDEX alarms_by_mill ON alarms (mill_id, updated_ns)",
        """CREATE TABLE alarm_transitions (
            alarm_id TEXT NOT NULL, seq INTEGER NOT NULL, kind TEXT NOT NULL,
            t_ns INTEGER NOT NULL, severity TEXT NOT NULL, state TEXT NOT NULL, value REAL,
            threshold REAL, by TEXT, message TEXT NOT NULL, PRIMARY KEY (alarm_id, seq))""",
    ),
    (  # 2 → 3: several events of one kind at one time need a subject (e.g. a channel)
        "ALTER TABLE events ADD COLUMN subject TEXT NOT NULL DEFAULT ''",
        "DROP INDEX events_unique",
        "CREATE UNIQUE INDEX events_unique ON events (mill_id, kind, t_ns, subject)",
    ),
    (  # 3 → 4: checkpoints per part (a mill), each written on its own with its own archive
        # position; the whole-worker checkpoints of schema 3 (arrays as JSON lists) are dropped
        """CREATE TABLE checkpoint_parts (
            id INTEGER PRIMARY KEY, part TEXT NOT NULL, created_ns INTEGER NOT NULL,
            position_json TEXT NOT NULL, state_json TEXT NOT NULL)""",
        "CREATE INDEX checkpoint_parts_by_part ON checkpoint_parts (part, id)",
        "DROP TABLE checkpoints",
    ),
)
SCHEMA_VERSION = len(MIGRATIONS)
_PART_CHECKPOINTS = 4  # the schema version that brought checkpoint_parts
#: Object keys of records are first read from one record per this interval (then checked).
_KEY_SAMPLE_NS = 3_600 * 10**9
#: Checkpoints kept per part (older ones of the part are deleted when a new one is written).
CHECKPOINTS_KEPT = 2


class StoreError(RuntimeError):
    """The store file cannot be used (newer schema, corrupt, not writable)."""


@dataclass(frozen=True, slots=True)
class EventRow:
    """An event of a mill: ``kind`` (start, stop, barring, data_quality, …), times in ns UTC."""

    mill_id: str
    kind: str
    t_ns: int
    data: dict[str, Any]
    t_end_ns: int | None = None
    subject: str = ""  # what the event is about when one time has several (e.g. a channel)


@dataclass(frozen=True, slots=True)
class DamageRow:
    """Miner damage and cycles of one component and phase on one local calendar day."""

    mill_id: str
    component: str
    phase: str
    day: str  # YYYY-MM-DD in the site's time zone
    damage: float
    cycles: float


@dataclass(frozen=True, slots=True)
class AlarmRow:
    """Current state of one alarm (fields of ``alarms.lifecycle.Alarm.to_dict()``); times ns
    UTC; ``condition`` is False while a latched alarm waits for acknowledgement."""

    alarm_id: str
    mill_id: str
    rule: str
    subject: str
    quantity: str
    unit: str
    severity: str
    state: str
    raised_ns: int
    updated_ns: int
    value: float | None
    threshold: float | None
    message: str
    condition: bool = True
    acked_ns: int | None = None
    acked_by: str | None = None
    cleared_ns: int | None = None
    seq: int = 0


@dataclass(frozen=True, slots=True)
class AlarmTransitionRow:
    """One transition of an alarm (the fields of ``alarms.lifecycle.Transition.to_row()``,
    i.e. without ``alarm``); ``seq`` numbers an alarm's transitions from 1."""

    alarm_id: str
    seq: int
    kind: str
    t_ns: int
    severity: str
    state: str
    value: float | None
    threshold: float | None
    message: str
    by: str | None = None


_ALARM_COLUMNS = (
    "alarm_id, mill_id, rule, subject, quantity, unit, severity, state, raised_ns, updated_ns, "
    "value, threshold, message, condition, acked_ns, acked_by, cleared_ns, seq"
)
_TRANSITION_COLUMNS = "alarm_id, seq, kind, t_ns, severity, state, value, threshold, message, by"


def _alarm_row(r: tuple[Any, ...]) -> AlarmRow:
    return AlarmRow(*r[:13], bool(r[13]), *r[14:])


def _record_window(
    mill_id: str, kind: str, since_ns: int | None, until_ns: int | None
) -> tuple[str, tuple[Any, ...]]:
    """WHERE clause (on the ``records_unique`` index) and its arguments."""
    where, args = "mill_id = ? AND kind = ?", [mill_id, kind]
    for clause, value in (("t_ns >= ?", since_ns), ("t_ns < ?", until_ns)):
        if value is not None:
            where += " AND " + clause
            args.append(value)
    return where, tuple(args)


def _column_paths(
    fields: Sequence[Sequence[str]], objects: Sequence[Sequence[str]], keys: list[list[str]]
) -> list[Sequence[str]]:
    """Key paths of the value columns of :meth:`Store.record_columns`."""
    paths = list(fields)
    for obj, names in zip(objects, keys, strict=True):
        paths += [(*obj, k) for k in names]
    return paths


def _json_path(keys: Sequence[str]) -> str:
    """SQLite JSON path of object keys (``("range_pct", "motor")`` → ``$."range_pct"."motor"``)."""
    if isinstance(keys, str) or any('"' in k for k in keys):
        raise ValueError(f"a JSON path is a sequence of keys without double quotes, not {keys!r}")
    return "$" + "".join(f'."{k}"' for k in keys)


def _walk(data: Any, keys: Sequence[str]) -> Any:
    for k in keys:
        data = data.get(k) if isinstance(data, dict) else None
    return data


def _scalar(value: Any) -> Any:
    """What ``json_extract`` gives: objects and arrays as JSON text, booleans as 0/1."""
    if isinstance(value, dict | list):
        return json.dumps(value)
    return int(value) if isinstance(value, bool) else value


class Store:
    """A SQLite store file; thread-safe: one writing connection serialised by a lock, and a
    read-only connection per reading thread."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute("PRAGMA busy_timeout=5000")
        except sqlite3.Error as exc:
            raise StoreError(f"{self.path}: cannot open the store ({exc})") from exc
        self._lock = threading.RLock()
        self._local = threading.local()
        self._readers: list[sqlite3.Connection] = []
        self._migrate()

    # ------------------------------------------------------------------ schema
    @property
    def schema_version(self) -> int:
        return int(self._db.execute("PRAGMA user_version").fetchone()[0])

    def _migrate(self) -> None:
        version = self.schema_version
        if version > SCHEMA_VERSION:
            raise StoreError(
                f"{self.path}: schema version {version} was written by a newer millwatch "
                f"(this one knows up to {SCHEMA_VERSION}); upgrade millwatch to open it"
            )
        if 0 < version < _PART_CHECKPOINTS:
            self._warn_old_checkpoints()
        for target in range(version + 1, SCHEMA_VERSION + 1):
            with self.transaction() as db:
                for statement in MIGRATIONS[target - 1]:
                    db.execute(statement)
                db.execute(f"PRAGMA user_version = {target}")
            log.info("store %s migrated to schema version %d", self.path, target)

    def _warn_old_checkpoints(self) -> None:
        (n,) = self._db.execute("SELECT COUNT(*) FROM checkpoints").fetchone()
        if n:
            log.warning(
                "store %s: its %d checkpoint(s) are in the format of an older millwatch and are "
                "dropped; the worker rebuilds its state by replaying the whole archive once",
                self.path,
                n,
            )

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """One atomic write (``BEGIN IMMEDIATE`` … ``COMMIT``, rolled back on error)."""
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

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
            "INSERT OR REPLACE INTO damage_daily VALUES (?, ?, ?, ?, ?, ?)",
            [(r.mill_id, r.component, r.phase, r.day, r.damage, r.cycles) for r in rows],
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
        transaction, so no write holds the store for long. Returns the state's size in bytes."""
        text = json.dumps(state)
        db.execute(
            "INSERT INTO checkpoint_parts (part, created_ns, position_json, state_json) "
            "VALUES (?, ?, ?, ?)",
            (part, created_ns, json.dumps(position), text),
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
        transitions: Sequence[AlarmTransitionRow],
        alarms: Sequence[AlarmRow],
    ) -> None:
        """Record alarm transitions and set the alarms' current state (inside
        :meth:`transaction`). Idempotent: ids and ``seq`` are deterministic, so the archive
        tail replayed after a crash rewrites the same rows; an older state never overwrites a
        newer one (higher ``seq`` wins)."""
        db.executemany(
            f"INSERT OR REPLACE INTO alarm_transitions ({_TRANSITION_COLUMNS}) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            [(t.alarm_id, t.seq, t.kind, t.t_ns, t.severity, t.state, t.value, t.threshold,
              t.message, t.by) for t in transitions],
        )  # fmt: skip
        db.executemany(
            f"INSERT INTO alarms ({_ALARM_COLUMNS}) VALUES ({', '.join('?' * 18)}) "
            "ON CONFLICT (alarm_id) DO UPDATE SET "
            + ", ".join(f"{c} = excluded.{c}" for c in _ALARM_COLUMNS.split(", ")[1:])
            + " WHERE excluded.seq >= alarms.seq",
            [(a.alarm_id, a.mill_id, a.rule, a.subject, a.quantity, a.unit, a.severity, a.state,
              a.raised_ns, a.updated_ns, a.value, a.threshold, a.message, int(a.condition),
              a.acked_ns, a.acked_by, a.cleared_ns, a.seq) for a in alarms],
        )  # fmt: skip

    # ------------------------------------------------------------------ reading
    def alarms(
        self,
        state: str | Sequence[str] | None = None,
        since_ns: int | None = None,
        mill_id: str | None = None,
    ) -> list[AlarmRow]:
        """Alarms, most recently changed first; ``state`` one state or several (e.g.
        ``("raised", "acknowledged")`` for the open ones), ``since_ns`` changed at or after
        (``updated_ns``, for pollers), optionally of one mill."""
        states = [state] if isinstance(state, str) else list(state or [])
        sql = f"SELECT {_ALARM_COLUMNS} FROM alarms WHERE 1"
        args: list[Any] = []
        if states:
            sql += f" AND state IN ({', '.join('?' * len(states))})"
            args += states
        for clause, value in (("updated_ns >= ?", since_ns), ("mill_id = ?", mill_id)):
            if value is not None:
                sql += " AND " + clause
                args.append(value)
        rows = self._query(sql + " ORDER BY updated_ns DESC, alarm_id", tuple(args))
        return [_alarm_row(r) for r in rows]

    def alarm(self, alarm_id: str) -> AlarmRow | None:
        """One alarm's current state, or None."""
        sql = f"SELECT {_ALARM_COLUMNS} FROM alarms WHERE alarm_id = ?"
        row = self._query_one(sql, (alarm_id,))
        return None if row is None else _alarm_row(row)

    def alarm_transitions(self, alarm_id: str) -> list[AlarmTransitionRow]:
        """An alarm's transitions in order."""
        sql = f"SELECT {_TRANSITION_COLUMNS} FROM alarm_transitions WHERE alarm_id = ? ORDER BY seq"
        return [AlarmTransitionRow(*r) for r in self._query(sql, (alarm_id,))]

    def latest_checkpoints(self) -> dict[str, tuple[dict[str, Any], dict[str, Any]]]:
        """The newest checkpoint of every part: ``part → (position, state)``."""
        rows = self._query(
            "SELECT part, position_json, state_json FROM checkpoint_parts WHERE id IN "
            "(SELECT MAX(id) FROM checkpoint_parts GROUP BY part) ORDER BY part",
            (),
        )
        return {part: (json.loads(p), json.loads(s)) for part, p, s in rows}

    def latest_checkpoint(self) -> tuple[dict[str, dict[str, Any]], dict[str, Any]] | None:
        """The newest checkpoints of all parts together, or ``None`` when there is none:
        ``(positions by part, state)``, the state being the parts' states merged key by key
        (each part's entries under each top-level key, e.g. ``state["pipelines"][mill]``)."""
        parts = self.latest_checkpoints()
        if not parts:
            return None
        merged: dict[str, Any] = {}
        for _, state in parts.values():
            for key, value in state.items():
                if isinstance(value, dict):
                    merged.setdefault(key, {}).update(value)
                else:
                    merged[key] = value
        return {part: position for part, (position, _) in parts.items()}, merged

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
        rows = self._query(sql, tuple(args))
        return [EventRow(m, k, t, json.loads(d), e, sub) for m, k, t, d, e, sub in rows]

    def damage(
        self, mill_id: str, since_day: str | None = None, until_day: str | None = None
    ) -> list[DamageRow]:
        """Daily damage rows of a mill, oldest first; days in ``[since_day, until_day]``
        (``YYYY-MM-DD``, both included) when given."""
        sql = "SELECT * FROM damage_daily WHERE mill_id = ?"
        args: list[Any] = [mill_id]
        for clause, value in (("day >= ?", since_day), ("day <= ?", until_day)):
            if value is not None:
                sql += " AND " + clause
                args.append(value)
        rows = self._query(sql + " ORDER BY day, component, phase", tuple(args))
        return [DamageRow(*r) for r in rows]

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
        where, args = _record_window(mill_id, kind, since_ns, until_ns)
        if every_ns:
            where += f" AND t_ns IN (SELECT min(t_ns) FROM records WHERE {where} GROUP BY t_ns / ?)"
            args = (*args, *args, int(every_ns))
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
        where, args = _record_window(mill_id, kind, since_ns, until_ns)
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
        where, args = _record_window(mill_id, kind, since_ns, until_ns)
        return self._keys(where, args, paths, self._unparsable(where, args))

    def _keys(
        self,
        where: str,
        args: tuple[Any, ...],
        paths: Sequence[Sequence[str]],
        odd: list[tuple[int, Any]],
        sample_ns: int | None = None,
    ) -> list[list[str]]:
        """Object keys at ``paths`` over the records in ``where`` (only the first of each
        ``sample_ns`` interval if given) and the ``odd`` ones decoded in Python."""
        sql = (f"SELECT DISTINCT j.key FROM records, json_each(data_json, ?) AS j WHERE {where} "
               "AND json_valid(data_json) AND j.key IS NOT NULL")  # fmt: skip
        params = args
        if sample_ns:
            sql += f" AND t_ns IN (SELECT min(t_ns) FROM records WHERE {where} GROUP BY t_ns / ?)"
            params = (*args, *args, int(sample_ns))
        keys = [{str(k) for (k,) in self._query(sql, (_json_path(p), *params))} for p in paths]
        for _t, data in odd:
            for found, path in zip(keys, paths, strict=True):
                obj = _walk(data, path)
                found.update(obj if isinstance(obj, dict) else ())
        return [sorted(k) for k in keys]

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
        json writes) are decoded in Python."""
        where, args = _record_window(mill_id, kind, since_ns, until_ns)
        odd = self._unparsable(where, args)
        keys = self._keys(where, args, objects, odd, sample_ns=_KEY_SAMPLE_NS)
        rows = self._columns(where, args, fields, objects, keys, check=True)
        if rows is None:  # some record has keys the hourly sample missed
            keys = self._keys(where, args, objects, odd)
            rows = self._columns(where, args, fields, objects, keys, check=False)
            assert rows is not None
        if odd:
            paths = _column_paths(fields, objects, keys)
            rows += [(t, *(_scalar(_walk(d, p)) for p in paths)) for t, d in odd]
            rows.sort(key=lambda r: r[0])
        return keys, rows

    def _columns(
        self,
        where: str,
        args: tuple[Any, ...],
        fields: Sequence[Sequence[str]],
        objects: Sequence[Sequence[str]],
        keys: list[list[str]],
        check: bool,
    ) -> list[tuple[Any, ...]] | None:
        """Rows of :meth:`record_columns` from SQLite; with ``check``, ``None`` if an object
        has a key outside ``keys`` in some record (what ``json_remove`` leaves of it)."""
        paths = _column_paths(fields, objects, keys)
        columns = ["json_extract(data_json, ?)"] * len(paths)
        params = [_json_path(p) for p in paths]
        if check:
            for obj, names in zip(objects, keys, strict=True):
                columns.append(f"json_remove(json_extract(data_json, ?){', ?' * len(names)})")
                params += [_json_path(obj), *(_json_path((k,)) for k in names)]
        sql = (f"SELECT {', '.join(['t_ns', *columns])} FROM records WHERE {where} "
               "AND json_valid(data_json) ORDER BY t_ns")  # fmt: skip
        rows = self._query(sql, (*params, *args))
        n = len(objects) if check else 0
        if not n:
            return rows
        if any(rest not in (None, "{}") for row in rows for rest in row[-n:]):
            return None
        return [row[:-n] for row in rows]

    def _unparsable(self, where: str, args: tuple[Any, ...]) -> list[tuple[int, Any]]:
        """``(t_ns, data)`` of the records in ``where`` that SQLite's JSON functions refuse."""
        sql = f"SELECT t_ns, data_json FROM records WHERE {where} AND NOT json_valid(data_json)"
        return [(t, json.loads(d)) for t, d in self._query(sql, args)]

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
        if db is None:
            db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, check_same_thread=False)
            db.execute("PRAGMA busy_timeout=5000")
            self._local.db = db
            with self._lock:
                self._readers.append(db)
        return db

    def _query(self, sql: str, args: tuple[Any, ...]) -> list[tuple[Any, ...]]:
        return self._reader().execute(sql, args).fetchall()

    def _query_one(self, sql: str, args: tuple[Any, ...]) -> tuple[Any, ...] | None:
        return self._reader().execute(sql, args).fetchone()
