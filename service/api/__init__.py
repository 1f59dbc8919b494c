"""The REST API (FastAPI): routes → backend → runtime and store, or zenoh.

Routes ask a backend: the store and runtime in process, or the workers over zenoh (remote).

What is here:

* :mod:`service.api.app` — :func:`~service.api.app.create_app`: the app over a backend;
  :class:`~service.api.app.HeadAsGet`: HEAD wherever GET exists (the GET without its body).
* :mod:`service.api.router` — the one router including every resource's routes.
* :mod:`service.api.routes` — one router file per resource (its own map).
* :mod:`service.api.backend` — the :class:`~service.api.backend.Backend` protocol: what the
  routes ask, whoever answers.
* :mod:`service.api.local_backend` — the backend over a runtime in this process (also what a
  worker answers zenoh queries with).
* :mod:`service.api.mill_views`, :mod:`service.api.alarm_views` — what the per-mill and alarm
  endpoints answer, from the store and the worker's status snapshot; operator actions
  (:mod:`alarms.actions`) applied through the worker thread.
* :mod:`service.api.alarm_board` — every alarm's current state in memory (cheap ``/alarms``),
  with the change cursor: a change number of the board and its epoch, never sample time, so a
  poller misses no change (an acknowledgement of an older alarm included).
* :mod:`service.api.journal` — the alarm journal (``/alarms/journal``): stored transitions in
  time order by mill and time, keyset-paged; per-mill pages of workers merged in order.
* :mod:`service.api.models` — the request and response bodies (OpenAPI schema); the typed
  results of the analysis (``MillStatus``, ``LifeReport``, ``MonthStarts``, ``FleetView``) are
  defined once by their producers and are the backend's return types and the response models.
* :mod:`service.api.errors` — domain errors and their ``application/problem+json`` answers.
* :mod:`service.api.identity` — who acts: the shared ``api_key`` and per-user keys
  (``[[api.users]]``, operator or viewer), resolved to the user an action is recorded as.
* :mod:`service.api.limits` — what one client can cost: body size (413 before reading), an
  operator's key before an action's body, concurrent report renders (503 + Retry-After).
* :mod:`service.api.metrics` — the Prometheus collector of a runtime;
  :mod:`service.api.domain_metrics` — its domain gauges (damage, remaining life, oscillation,
  bending, starts, lag, state) and the cache of the life computation they need.
* :mod:`service.api.times` — every ``*_ns`` time also as ISO-8601 UTC (every JSON answer,
  the report JSON and ``/reports/status`` included: a test walks every GET route); ISO query
  times.

Data flow: request → route (validates, calls one backend method) → ``LocalBackend`` → views →
store/runtime status (times given ISO-8601 beside, :func:`service.api.times.with_iso`, in the
route); or → ``service.remote.zenoh_backend.ZenohBackend`` → a worker's
queryable → its ``LocalBackend``. Either way errors are :mod:`service.api.errors` exceptions,
answered as problem JSON in one handler.

Where things go: a new endpoint is a route in the resource's file under ``routes/`` (a new
resource: a new file, included in :mod:`service.api.router`), a method of ``Backend``
implemented by ``LocalBackend`` (a view function) and by ``ZenohBackend`` (a question of
:mod:`service.remote.protocol`), and a body in :mod:`service.api.models`. The remote side of the
API (``millwatch api``) lives in :mod:`service.remote`; api never imports it.
"""
