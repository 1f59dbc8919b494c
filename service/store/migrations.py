"""The store's schema: forward migrations, applied when a file is opened.

``MIGRATIONS[i]`` brings the schema from version ``i`` to ``i + 1`` (SQLite's ``user_version``);
:func:`migrate` applies the missing ones, each in its own transaction, and refuses a file written
by a newer millwatch. A new table or column is a new entry at the end, never an edit of an old
one. The alarm tables' columns are the fields of :mod:`millwatch.alarms.lifecycle`'s records
(``tests/service/store/test_alarms.py`` checks it).
"""

from __future__ import annotations

import logging
import sqlite3

__all__ = ["MIGRATIONS", "SCHEMA_VERSION", "StoreError", "migrate"]

log = logging.getLogger(__name__)


class StoreError(RuntimeError):
    """The store file cannot be used (newer schema, corrupt, not writable)."""


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
    (  # 1 → 2: alarms (current state per alarm) and their transitions (millwatch.alarms.lifecycle)
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
    (  # 4 → 5: the monitored time per mill and local day (first and last analysed sample, ns),
        # which remaining life measures monitoring by; alarms about simulated data say so
        """CREATE TABLE mill_days (
            mill_id TEXT NOT NULL, day TEXT NOT NULL, first_ns INTEGER NOT NULL,
            last_ns INTEGER NOT NULL, PRIMARY KEY (mill_id, day))""",
        "ALTER TABLE alarms ADD COLUMN simulated INTEGER NOT NULL DEFAULT 0",
    ),
    (  # 5 → 6: seconds per mill, operating phase and local day, as the analyzer counts them
        # (stopped and unknown included), which the cost of a start and the report read
        """CREATE TABLE phase_daily (
            mill_id TEXT NOT NULL, phase TEXT NOT NULL, day TEXT NOT NULL,
            seconds REAL NOT NULL, PRIMARY KEY (mill_id, phase, day))""",
    ),
    (  # 6 → 7: an alarm keeps the value and limit it was raised with, counts its exceedances
        # (event alarms re-annunciate) and carries its advice beside the short message
        "ALTER TABLE alarms ADD COLUMN value_at_raise REAL",
        "ALTER TABLE alarms ADD COLUMN threshold_at_raise REAL",
        "ALTER TABLE alarms ADD COLUMN exceed_count INTEGER NOT NULL DEFAULT 1",
        "ALTER TABLE alarms ADD COLUMN advice TEXT NOT NULL DEFAULT ''",
    ),
    (  # 7 → 8: operator actions (millwatch.alarms.actions): confirmation, shelving, suppression by
        # design, out of service, comments — on the alarm, and each transition's comment
        "ALTER TABLE alarms ADD COLUMN confirmed INTEGER NOT NULL DEFAULT 0",
        "ALTER TABLE alarms ADD COLUMN confirmed_at_ns INTEGER",
        "ALTER TABLE alarms ADD COLUMN confirmed_by TEXT",
        "ALTER TABLE alarms ADD COLUMN shelving_state TEXT NOT NULL DEFAULT 'unshelved'",
        "ALTER TABLE alarms ADD COLUMN shelved_until_ns INTEGER",
        "ALTER TABLE alarms ADD COLUMN shelved_by TEXT",
        "ALTER TABLE alarms ADD COLUMN suppressed INTEGER NOT NULL DEFAULT 0",
        "ALTER TABLE alarms ADD COLUMN out_of_service INTEGER NOT NULL DEFAULT 0",
        "ALTER TABLE alarms ADD COLUMN comment_count INTEGER NOT NULL DEFAULT 0",
        "ALTER TABLE alarms ADD COLUMN last_comment TEXT",
        "ALTER TABLE alarms ADD COLUMN last_comment_by TEXT",
        "ALTER TABLE alarms ADD COLUMN last_commented_ns INTEGER",
        "ALTER TABLE alarm_transitions ADD COLUMN comment TEXT",
    ),
)
SCHEMA_VERSION = len(MIGRATIONS)
_PART_CHECKPOINTS = 4  # the schema version that brought checkpoint_parts


def schema_version(db: sqlite3.Connection) -> int:
    """The schema version of an open file (0: empty)."""
    return int(db.execute("PRAGMA user_version").fetchone()[0])


def migrate(db: sqlite3.Connection, name: str) -> None:
    """Bring the file open on ``db`` (autocommit mode; ``name`` for messages) to
    :data:`SCHEMA_VERSION`; :class:`StoreError` for a file of a newer millwatch."""
    version = schema_version(db)
    if version > SCHEMA_VERSION:
        raise StoreError(
            f"{name}: schema version {version} was written by a newer millwatch "
            f"(this one knows up to {SCHEMA_VERSION}); upgrade millwatch to open it"
        )
    if 0 < version < _PART_CHECKPOINTS:
        _warn_old_checkpoints(db, name)
    for target in range(version + 1, SCHEMA_VERSION + 1):
        db.execute("BEGIN IMMEDIATE")
        try:
            for statement in MIGRATIONS[target - 1]:
                db.execute(statement)
            db.execute(f"PRAGMA user_version = {target}")
        except BaseException:
            db.execute("ROLLBACK")
            raise
        db.execute("COMMIT")
        log.info("store %s migrated to schema version %d", name, target)


def _warn_old_checkpoints(db: sqlite3.Connection, name: str) -> None:
    (n,) = db.execute("SELECT COUNT(*) FROM checkpoints").fetchone()
    if n:
        log.warning(
            "store %s: its %d checkpoint(s) are in the format of an older millwatch and are "
            "dropped; the worker rebuilds its state by replaying the whole archive once",
            name,
            n,
        )
