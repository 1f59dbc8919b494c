"""The REST API (FastAPI): routes → backend → runtime and store, or zenoh.

Routes ask a backend: the store and runtime in process, or the workers over zenoh (remote).

What is here:

* :mod:`millwatch.api.app` — :func:`~millwatch.api.app.create_app`: the app over a backend;
  :class:`~millwatch.api.app.HeadAsGet`: HEAD wherever GET exists (the GET without its body).
* :mod:`millwatch.api.router` — the one router including every resource's routes.
* :mod:`millwatch.api.routes` — one router file per resource (its own map).
* :mod:`millwatch.api.backend` — the :class:`~millwatch.api.backend.Backend` protocol: what the
  routes ask, whoever answers.
* :mod:`millwatch.api.local_backend` — the backend over a runtime in this process (also what a
  worker answers zenoh queries with).
* :mod:`millwatch.api.mill_views`, :mod:`millwatch.api.alarm_views` — what the per-mill and alarm
  endpoints answer, from the store and the worker's status snapshot; operator actions
  (:mod:`millwatch.alarms.actions`) applied through the worker thread.
* :mod:`millwatch.api.alarm_board` — every alarm's current state and comments in memory (cheap
  ``/alarms``), with the change cursor: a change number of the board and its epoch, never
  sample time, so a poller misses no change (an acknowledgement of an older alarm included).
* :mod:`millwatch.api.journal` — the alarm journal (``/alarms/journal``): stored transitions in
  time order by mill and time, keyset-paged; per-mill pages of workers merged in order.
* :mod:`millwatch.api.models` — the request and response bodies (OpenAPI schema); the typed
  results of the analysis (``MillStatus``, ``LifeReport``, ``MonthStarts``, ``FleetView``) are
  defined once by their producers and are the backend's return types and the response models.
* :mod:`millwatch.api.errors` — domain errors and their ``application/problem+json`` answers.
* :mod:`millwatch.api.identity` — who acts: the shared ``api_key`` and per-user keys
  (``[[api.users]]``, operator or viewer), resolved to the user an action is recorded as.
* :mod:`millwatch.api.limits` — what one client can cost: body size (413 before reading), an
  operator's key before an action's body, concurrent report renders (503 + Retry-After).
* :mod:`millwatch.api.metrics` — the Prometheus collector of a runtime;
  :mod:`millwatch.api.domain_metrics` — its domain gauges (damage, remaining life, oscillation,
  bending, starts, lag, state) and the cache of the life computation they need.
* :mod:`millwatch.api.times` — every ``*_ns`` time also as ISO-8601 UTC (every JSON answer,
  the report JSON and ``/reports/status`` included: a test walks every GET route); ISO query
  times.

Data flow: request → route (validates, calls one backend method) → ``LocalBackend`` → views →
store/runtime status (times given ISO-8601 beside, :func:`millwatch.api.times.with_iso`, in the
route); or → ``millwatch.remote.zenoh_backend.ZenohBackend`` → a worker's
queryable → its ``LocalBackend``. Either way errors are :mod:`millwatch.api.errors` exceptions,
answered as problem JSON in one handler.

Where things go: a new endpoint is a route in the resource's file under ``routes/`` (a new
resource: a new file, included in :mod:`millwatch.api.router`), a method of ``Backend``
implemented by ``LocalBackend`` (a view function) and by ``ZenohBackend`` (a question of
:mod:`millwatch.remote.protocol`), and a body in :mod:`millwatch.api.models`. The remote side of the
API (``millwatch api``) lives in :mod:`millwatch.remote`; api never imports it.
"""
