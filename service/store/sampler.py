"""Columns out of the JSON ``records`` without decoding them in Python.

``records`` keeps each steady-state window, harmonic table, … as one JSON object
(``data_json``). A month's report needs a few scalars of thousands of them: here SQLite extracts
them (``json_extract``, ``json_each``), so a month of windows is read without decoding each one.
The functions take a read query (the store passes its reader's) and are
exposed as :meth:`~millwatch.store.database.Store.record_keys`,
:meth:`~millwatch.store.database.Store.record_fields` and
:meth:`~millwatch.store.database.Store.record_columns`.

Records SQLite's JSON refuses (``NaN`` and ``Infinity``, which Python's json writes) are decoded
in Python and merged in, so the answer is the same as decoding every record.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import Any

__all__ = [
    "KEY_SAMPLE_NS",
    "Query",
    "record_columns",
    "record_keys",
    "record_values",
    "record_window",
]

Query = Callable[[str, tuple[Any, ...]], list[tuple[Any, ...]]]
"""A read: SQL and its arguments → rows."""

#: Object keys of records are first read from one record per this interval (then checked).
KEY_SAMPLE_NS = 3_600 * 10**9


def record_window(
    mill_id: str,
    kind: str,
    since_ns: int | None,
    until_ns: int | None,
    every_ns: int | None = None,
) -> tuple[str, tuple[Any, ...]]:
    """WHERE clause (on the ``records_unique`` index) and its arguments; with ``every_ns`` only
    the first record of each interval of that length (counted from the epoch) is selected, the
    choice made on the index, so the skipped records are never read."""
    where, args = "mill_id = ? AND kind = ?", list[Any]([mill_id, kind])
    for clause, value in (("t_ns >= ?", since_ns), ("t_ns < ?", until_ns)):
        if value is not None:
            where += " AND " + clause
            args.append(value)
    if every_ns and since_ns is not None and until_ns is not None:
        # one index seek per interval (a recursive CTE of interval starts): a year of windows
        # sampled every few hours is read in milliseconds, the skipped ones never touched
        step, first = int(every_ns), int(since_ns) // int(every_ns) * int(every_ns)
        where = (
            "mill_id = ? AND kind = ? AND t_ns IN (SELECT t FROM (WITH RECURSIVE b(x) AS "
            "(SELECT ? UNION ALL SELECT x + ? FROM b WHERE x + ? < ?) SELECT (SELECT min(t_ns) "
            "FROM records WHERE mill_id = ? AND kind = ? AND t_ns >= max(x, ?) "
            "AND t_ns < min(x + ?, ?)) AS t FROM b) WHERE t IS NOT NULL)"
        )
        bounds = [first, step, step, int(until_ns), mill_id, kind, since_ns, step, until_ns]
        args = [mill_id, kind, *bounds]
    elif every_ns:
        where += f" AND t_ns IN (SELECT min(t_ns) FROM records WHERE {where} GROUP BY t_ns / ?)"
        args += [*args, int(every_ns)]
    return where, tuple(args)


def _column_paths(
    fields: Sequence[Sequence[str]], objects: Sequence[Sequence[str]], keys: list[list[str]]
) -> list[Sequence[str]]:
    """Key paths of the value columns of :func:`record_columns`."""
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


def record_keys(
    query: Query, where: str, args: tuple[Any, ...], paths: Sequence[Sequence[str]]
) -> list[list[str]]:
    """For each path (keys from the top), the sorted keys of the JSON object there over the
    records in ``where`` (:func:`record_window`)."""
    return _keys(query, where, args, paths, _unparsable(query, where, args))


def _keys(
    query: Query,
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
    keys = [{str(k) for (k,) in query(sql, (_json_path(p), *params))} for p in paths]
    for _t, data in odd:
        for found, path in zip(keys, paths, strict=True):
            obj = _walk(data, path)
            found.update(obj if isinstance(obj, dict) else ())
    return [sorted(k) for k in keys]


def record_columns(
    query: Query,
    where: str,
    args: tuple[Any, ...],
    fields: Sequence[Sequence[str]],
    objects: Sequence[Sequence[str]],
) -> tuple[list[list[str]], list[tuple[Any, ...]]]:
    """``(keys, rows)`` of the records in ``where``: see
    :meth:`millwatch.store.database.Store.record_columns`. The object keys are read from the
    first record of each hour and checked on every record in the same pass; a second pass reads
    them all only if some record has others."""
    odd = _unparsable(query, where, args)
    keys = _keys(query, where, args, objects, odd, sample_ns=KEY_SAMPLE_NS)
    rows = _columns(query, where, args, fields, objects, keys, check=True)
    if rows is None:  # some record has keys the hourly sample missed
        keys = _keys(query, where, args, objects, odd)
        rows = _columns(query, where, args, fields, objects, keys, check=False)
        assert rows is not None
    if odd:
        paths = _column_paths(fields, objects, keys)
        rows += [(t, *(_scalar(_walk(d, p)) for p in paths)) for t, d in odd]
        rows.sort(key=lambda r: r[0])
    return keys, rows


def _columns(
    query: Query,
    where: str,
    args: tuple[Any, ...],
    fields: Sequence[Sequence[str]],
    objects: Sequence[Sequence[str]],
    keys: list[list[str]],
    check: bool,
) -> list[tuple[Any, ...]] | None:
    """Rows of :func:`record_columns` from SQLite; with ``check``, ``None`` if an object has a
    key outside ``keys`` in some record (what ``json_remove`` leaves of it)."""
    paths = _column_paths(fields, objects, keys)
    columns = ["json_extract(data_json, ?)"] * len(paths)
    params = [_json_path(p) for p in paths]
    if check:
        for obj, names in zip(objects, keys, strict=True):
            columns.append(f"json_remove(json_extract(data_json, ?){', ?' * len(names)})")
            params += [_json_path(obj), *(_json_path((k,)) for k in names)]
    sql = (f"SELECT {', '.join(['t_ns', *columns])} FROM records WHERE {where} "
           "AND json_valid(data_json) ORDER BY t_ns")  # fmt: skip
    rows = query(sql, (*params, *args))
    n = len(objects) if check else 0
    if not n:
        return rows
    if any(rest not in (None, "{}") for row in rows for rest in row[-n:]):
        return None
    return [row[:-n] for row in rows]


def record_values(
    query: Query, where: str, args: tuple[Any, ...], paths: Sequence[Sequence[str]]
) -> list[tuple[int, list[Any]]]:
    """``(t_ns, [value at each path])`` of the records in ``where``, oldest first: SQLite
    extracts every path in one parse of each record (``None`` where absent). The ``NaN`` and
    ``Infinity`` Python's json writes, which SQLite's JSON refuses, are read as ``null``
    and ``±1e999`` (±inf): the keys of the records never contain them. Meant for a few
    thousand records (a year of a mill's steady windows sampled every few hours)."""
    if not paths:
        return [(t, []) for (t,) in query(f"SELECT t_ns FROM records WHERE {where} ORDER BY t_ns",
                                           args)]  # fmt: skip
    # one more path than asked, so SQLite always answers a JSON array (one path: a scalar)
    extract = ", ".join("?" for _ in paths)
    text = "replace(replace(data_json, 'NaN', 'null'), 'Infinity', '1e999')"
    sql = (f"SELECT t_ns, json_extract({text}, {extract}, '$.__none__') FROM records "
           f"WHERE {where} ORDER BY t_ns")  # fmt: skip
    n = len(paths)
    rows = query(sql, (*[_json_path(p) for p in paths], *args))
    return [(t, json.loads(values)[:n]) for t, values in rows]


def _unparsable(query: Query, where: str, args: tuple[Any, ...]) -> list[tuple[int, Any]]:
    """``(t_ns, data)`` of the records in ``where`` that SQLite's JSON functions refuse."""
    sql = f"SELECT t_ns, data_json FROM records WHERE {where} AND NOT json_valid(data_json)"
    return [(t, json.loads(d)) for t, d in query(sql, args)]
