"""The monthly report in each format: its document (:mod:`millwatch.reports.monthly_document`)
rendered as HTML, PDF or CSV tables (:mod:`millwatch.reports.render`).

These are the calls of the API's ``FORMATS``; the month-end files
(:mod:`millwatch.reports.files`) build the document once and render it in every format.
"""

from __future__ import annotations

from millwatch.reports.monthly import MonthlyReport
from millwatch.reports.monthly_document import monthly_document
from millwatch.reports.render.csv_tables import document_csv_table, document_csv_zip
from millwatch.reports.render.html_page import document_html
from millwatch.reports.render.pdf_pages import document_pdf

__all__ = ["render_csv", "render_csv_table", "render_html", "render_pdf"]


def render_html(r: MonthlyReport) -> str:
    """The monthly report as one HTML page."""
    return document_html(monthly_document(r))


def render_pdf(r: MonthlyReport) -> bytes:
    """The monthly report as A4 PDF bytes."""
    return document_pdf(monthly_document(r))


def render_csv(r: MonthlyReport) -> bytes:
    """The monthly report's tables, one tidy CSV each, in a zip."""
    return document_csv_zip(monthly_document(r))


def render_csv_table(r: MonthlyReport, name: str) -> str:
    """One table of the monthly report as CSV text (422 naming the valid ones if unknown)."""
    return document_csv_table(monthly_document(r), name)
