"""Both ends of the zenoh query protocol between the API and the workers.

Both ends of the zenoh query protocol between the API and the workers (README "Scale").

What is here:

* :mod:`service.remote.protocol` — the protocol, stated once: the questions, their arguments,
  the JSON encodings and the problem JSON of errors.
* :mod:`service.remote.queryables` — the worker's end: a queryable and a liveliness token per
  mill, answered by a :class:`~service.api.local_backend.LocalBackend`.
* :mod:`service.remote.zenoh_backend` — the API's end (``millwatch api``): the
  :class:`~service.api.backend.Backend` that asks the workers, tracks their tokens and keeps the
  alarm board from their ``…/@alarms`` messages.
* :mod:`service.remote.report_codec` — the monthly report back from its JSON, so the API renders it.
* :mod:`service.remote.metrics` — the Prometheus collector of ``millwatch api``.

Data flow: route → ``ZenohBackend`` → zenoh ``get`` ``…/@query/<question>`` → the worker's
``WorkerQueryables`` → ``LocalBackend`` → store/runtime → JSON reply (or ``reply_err`` with
problem JSON, raised again in the API as the same error).

Where things go: a new question is a member of :class:`~service.remote.protocol.Question`, an
entry of :data:`~service.remote.queryables.ANSWERS` and a method of ``ZenohBackend``.
"""
