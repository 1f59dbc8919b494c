"""The REST routes: one file per resource, aggregated in millwatch.api.router.

Each file returns an ``APIRouter`` over a backend;
:func:`millwatch.api.router.api_router` includes them all.

* :mod:`~millwatch.api.routes.health` — ``/health``, ``/ready``.
* :mod:`~millwatch.api.routes.mills` — ``/mills``, ``/mills/{id}``, ``/life``, ``/starts``,
  ``/spectrum``, and ``/sites/{site}/fleet`` (all mills of a site, in visit order).
* :mod:`~millwatch.api.routes.reports` — ``/mills/{id}/reports/monthly`` (json, html, csv, pdf).
* :mod:`~millwatch.api.routes.alarms` — ``/alarms`` (ETag and change-cursor polling),
  ``/alarms/{id}``, ``/alarms/{id}/ack``.
* :mod:`~millwatch.api.routes.journal` — ``/alarms/journal`` (stored transitions by mill and
  time, paged); included before ``alarms``, whose ``/alarms/{id}`` would take ``journal``.
* :mod:`~millwatch.api.routes.metrics` — ``/metrics`` (Prometheus).
* :mod:`~millwatch.api.routes.params` — the shared parameters (``MillId``, ``AlarmId``,
  ``Month``, ``Site``): every path parameter is one of them.

A route validates its parameters, calls one backend method and shapes the response; no SQL, no
runtime access here. Every GET route also answers HEAD (:class:`millwatch.api.app.HeadAsGet`). A
new route goes in its resource's file; a new resource is a new file added to
:func:`~millwatch.api.router.api_router`.
"""
