"""The monthly report as files: ``<directory>/<mill>/<YYYY-MM>.<ext>``, written atomically.

The one place that calls the renderers for files (the month-end job, ``millwatch report``):
:func:`render_files` maps each wanted format to its file extension and bytes. The renderers (they
pull in matplotlib) are imported only when called.

Atomic writes (:func:`write_atomic`): the bytes go to a temporary file in the same directory,
are flushed to disk, and the file is renamed over the final name, so a reader (or a crash) sees
either no file or the whole file, never half of one. A file that exists is therefore complete,
which is what makes the month-end job idempotent across restarts.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from millwatch.settings import REPORT_FORMATS as FORMATS

if TYPE_CHECKING:
    from millwatch.reports.monthly import MonthlyReport

__all__ = ["EXTENSIONS", "FORMATS", "render_files", "report_path", "write_atomic"]

#: File extension of each format (:data:`millwatch.settings.REPORT_FORMATS`); ``csv`` is a zip of
#: tidy tables, one CSV per table (:mod:`millwatch.reports.render.csv_tables`).
EXTENSIONS: dict[str, str] = {"html": "html", "pdf": "pdf", "csv": "zip"}


def render_files(report: MonthlyReport, formats: Iterable[str] = FORMATS) -> dict[str, bytes]:
    """The report rendered in each of ``formats``: file extension → bytes."""
    from millwatch.reports.monthly_document import monthly_document
    from millwatch.reports.render.csv_tables import document_csv_zip
    from millwatch.reports.render.html_page import document_html
    from millwatch.reports.render.pdf_pages import document_pdf

    doc = monthly_document(report)  # one document for every format
    out: dict[str, bytes] = {}
    for fmt in formats:
        if fmt == "html":
            out[EXTENSIONS[fmt]] = document_html(doc).encode("utf-8")
        elif fmt == "pdf":
            out[EXTENSIONS[fmt]] = document_pdf(doc)
        elif fmt == "csv":
            out[EXTENSIONS[fmt]] = document_csv_zip(doc)
        else:
            raise ValueError(f"report format {fmt!r} is not one of {', '.join(FORMATS)}")
    return out


def report_path(directory: Path, mill_id: str, month: str, ext: str) -> Path:
    """Where a mill's report of ``month`` (``YYYY-MM``) goes in format ``ext``."""
    return directory / mill_id / f"{month}.{ext}"


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file and a rename (module docstring); the
    directory is created if needed. On an error nothing is left behind but the old file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
