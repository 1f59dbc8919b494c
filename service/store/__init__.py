"""The embedded store: SQLite in WAL mode; one writer, many readers.

The embedded store: SQLite in WAL mode (one writer, the worker; any number of readers, the API).

What is here:

* :mod:`millwatch.store.database` — :class:`~millwatch.store.database.Store`: the file, its
  transactions, the worker's writes (events, daily damage and cycles, daily phase seconds,
  monitored days, records, alarms, checkpoints) and
  the reads of the API and the reports.
* :mod:`millwatch.store.checkpoint_seal` — checkpoints sealed with a SHA-256 checksum and
  verified before use; ``Store.choose_checkpoints`` takes each mill's newest intact one and
  says which it refused.
* :mod:`millwatch.store.migrations` — the schema as forward migrations, applied on open.
* :mod:`millwatch.store.records` — the row types (``EventRow``, ``DamageRow``, ``PhaseRow``; the
  alarm records
  are :mod:`millwatch.alarms.lifecycle`'s) and their mapping to SQL by column name.
* :mod:`millwatch.store.sampler` — columns of the JSON ``records`` extracted by SQLite, so a
  month of steady windows is read without decoding each one.

Data flow: worker → one transaction per analysed frame (``Store.transaction`` + the static
writers) → SQLite ← read-only connection per reading thread (API views, reports).

Where things go: a new table or column is a new entry at the end of
:data:`~millwatch.store.migrations.MIGRATIONS`; a new row type is a dataclass whose fields are
its columns (mapped by :func:`~millwatch.store.records.from_row` / ``to_params``); a new read or
write is a method of ``Store``.
"""
