"""A report document's tables as tidy CSV: one table per file (Diering 2011 §10.6 "automatic
reports").

Every table of the :class:`~millwatch.reports.render.document.Document` — the printed ones and the
data behind the figures (``printed=False``: starts per day, damage per day, component and phase) —
becomes one CSV document (RFC 4180, ``\\r\\n`` line ends, UTF-8): a header row of column names
with their units (``switch_on_pct [% rated]``, ``damage [1]``), then one row per table row, so
a spreadsheet, pandas or Grafana loads it as one rectangular table. Numbers are written at full
precision (``repr`` of floats), booleans as ``true``/``false``, missing values as empty cells.

* :func:`document_csv_zip` — every table in one zip (``<mill>-<month>-<table>.csv``), the API's
  ``format=csv``;
* :func:`document_csv_table` — one table by name, ``format=csv&table=NAME``; an unknown name is
  a :class:`~millwatch.errors.BadRequest` (422) that lists the valid ones.
"""

from __future__ import annotations

import csv
import io
import zipfile

from millwatch.errors import BadRequest
from millwatch.reports.render.document import Cell, Document, Table

__all__ = ["document_csv_table", "document_csv_zip", "table_csv"]

#: A fixed time for the zip members, so the same report gives the same bytes.
ZIP_TIME = (2000, 1, 1, 0, 0, 0)


def _value(v: Cell) -> str | int | float:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if v == v and v not in (float("inf"), float("-inf")) else ""
    return v


def table_csv(t: Table) -> str:
    """One table as CSV text: header row with units, then the rows."""
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow([c.csv_name for c in t.columns])
    writer.writerows([_value(v) for v in row] for row in t.rows)
    return buf.getvalue()


def document_csv_zip(doc: Document) -> bytes:
    """Every table of ``doc`` as ``<file_stem>-<table>.csv`` in one zip."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for t in doc.tables():
            info = zipfile.ZipInfo(f"{doc.file_stem}-{t.name}.csv", ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, table_csv(t).encode("utf-8"))
    return buf.getvalue()


def document_csv_table(doc: Document, name: str) -> str:
    """One table of ``doc`` as CSV text; :class:`BadRequest` (422) naming the valid tables for
    an unknown name."""
    try:
        return table_csv(doc.table(name))
    except KeyError:
        raise BadRequest(
            "Unknown report table",
            f"table {name!r} is not one of {', '.join(doc.table_names())}.",
        ) from None
