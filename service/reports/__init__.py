"""Reports a person reads: monthly damage report, remaining life, starts, the fleet.

Reports a person reads: the monthly damage report, remaining life, the starts of a month, all
mills of a site side by side.

What is here:

* :mod:`millwatch.reports.starts` — calendar months of a site and the starts of one month against
  the norm and the limits (``GET /mills/{id}/starts`` and the report share it); the answer is
  the typed ``MonthStarts`` (pydantic, every field described), as REST, the remote protocol and
  OPC UA take it.
* :mod:`millwatch.reports.life` — remaining life per component (pure): damage before monitoring,
  minimum history, a range of rates, what drives it; one computation for ``/life``, the report
  and the fleet. The answer is the typed ``LifeReport`` (dataclasses whose field docstrings
  describe them in OpenAPI; ``life_to_dict`` / ``life_from_dict`` across the remote protocol),
  read by attribute by OPC UA, ``/metrics`` and the fleet view.
* :mod:`millwatch.reports.history` — a mill's history read from the store (bounded, indexed):
  the life inputs as of a time, the per-month trend, phase seconds.
* :mod:`millwatch.reports.monthly` — the monthly report as plain data, built from the store (a
  package: building, the report's dataclasses, the store reader, the trend sections);
  :mod:`millwatch.reports.month_summary` — its page 1 and cumulative damage against design life.
* :mod:`millwatch.reports.fleet` — the mills of a site side by side and the visit order by the
  machines' condition, the monitoring's own alarms apart (``GET /sites/{site}/fleet``;
  ``millwatch report --fleet`` from a store file).
* :mod:`millwatch.reports.fleet_document` — the fleet report (HTML, PDF, CSV) from the fleet
  answer (``GET /sites/{site}/reports/fleet``).
* :mod:`millwatch.reports.plain` — report data to JSON-ready plain data.
* :mod:`millwatch.reports.numbers` — the one formatting of life and damage numbers (≤ 3
  significant digits; "no finite life predicted at these loads" beyond the horizon, no end
  date then); the renderers' ``fmt`` uses it.
* :mod:`millwatch.reports.actions` — what drives the damage in words and the recommended actions
  (pure rules on a month's evidence, each threshold with its source), carried to next month.
* :mod:`millwatch.reports.monthly_document` — what the monthly report says, once: its sections in
  order (summary first) as a document of :mod:`millwatch.reports.render`, which renders it as
  HTML, PDF and tidy CSV tables; :mod:`millwatch.reports.figures` draws its plots;
  :mod:`millwatch.reports.monthly_formats` — the report in each format (the API's ``FORMATS``).
* :mod:`millwatch.reports.files` — the report as files ``<mill>/<YYYY-MM>.<ext>`` (``html``,
  ``pdf``, ``zip`` of the CSV tables): the one call of the renderers for files, atomic writes.
* :mod:`millwatch.reports.mail` — a report's mail (SMTP, STARTTLS, login; stdlib only).
* :mod:`millwatch.reports.month_end` — the month-end job of the service: each finished local
  month's reports written and mailed, catch-up, retries, the ``report_delivery`` alarm.

Data flow: store rows (+ the worker's status for life) → ``MonthlyReport`` (plain dataclasses)
→ :func:`~millwatch.reports.monthly_document.monthly_document` → ``Document`` → renderers of
:mod:`millwatch.reports.render` → bytes; the API's routes choose the format
(:mod:`millwatch.api.routes.reports`); the month-end job and ``millwatch report`` write files
through :mod:`millwatch.reports.files`. HTML and PDF are generic over the document, so they cannot
diverge: same sections, tables, figures and numbers.
Every answer about a mill carries ``simulated`` from its configuration (the demo's mills are
simulated).

Where things go: new data of the monthly report is a field of ``MonthlyReport`` built in
:mod:`millwatch.reports.monthly` (its map says which module); showing it is a section function in
:mod:`millwatch.reports.monthly_document` added to its ``SECTIONS`` (a figure is a builder in
:mod:`millwatch.reports.figures`) — every format follows without a change. A new format is a
renderer over ``Document`` in :mod:`millwatch.reports.render` and an entry of ``FORMATS`` in
:mod:`millwatch.api.routes.reports`.
"""
