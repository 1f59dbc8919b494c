"""A report as a document, rendered alike as HTML, PDF and tidy CSV tables.

One content, three renderings (issue 17): what a report says is built once as a
:class:`~millwatch.reports.render.document.Document` (for the monthly report:
:mod:`millwatch.reports.monthly_document`), and each renderer is generic over it, so the formats
cannot diverge — same sections, tables, figures and numbers (formatted once).

What is here:

* :mod:`millwatch.reports.render.document` — the model: sections of paragraphs, tables (header row
  of columns with units, raw cells, column groups for wide tables) and figures; number
  formatting; the lock held while matplotlib draws; the garbage collector paused while a
  renderer runs (``collector_paused``: full collections walked the whole built report).
* :mod:`millwatch.reports.render.html_page` — one self-contained HTML page (inline SVG plots, CSS
  that fits and prints tables on A4).
* :mod:`millwatch.reports.render.pdf_pages` — an A4 PDF with fpdf2 (pure Python): running header,
  page numbers, paragraphs wrapped with cached word widths, figures as images;
  :mod:`millwatch.reports.render.pdf_table` typesets its tables (wrapped cells, repeated headers,
  never cut), :mod:`millwatch.reports.render.pdf_fonts` gives it
  DejaVu Sans from matplotlib's own fonts; :mod:`millwatch.reports.render.agg_text` draws the
  figures' text as one cached bitmap a line (matplotlib 3.11 lays out and renders it glyph by
  glyph: a fifth of the figures' drawing time).
* :mod:`millwatch.reports.render.csv_tables` — every table as tidy CSV (header row with units),
  zipped or one by name.

Data flow: ``Document`` → renderer → ``str``/``bytes``. Nothing here knows a report's data: a new
report is a new document builder elsewhere; a new format is a renderer here over ``Document``.
"""
