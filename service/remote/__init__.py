"""Both ends of the zenoh query protocol between the API and the workers.

Both ends of the zenoh query protocol between the API and the workers (README "Scale").

What is here:

* :mod:`millwatch.remote.protocol` — the protocol, stated once: the questions, their arguments,
  the JSON encodings and the problem JSON of errors.
* :mod:`millwatch.remote.queryables` — the worker's end: a queryable and a liveliness token per
  mill, answered by a :class:`~millwatch.api.local_backend.LocalBackend`.
* :mod:`millwatch.remote.zenoh_backend` — the API's end (``millwatch api``): the
  :class:`~millwatch.api.backend.Backend` that asks the workers, tracks their tokens and keeps the
  alarm board from their ``…/@alarms`` messages.
* :mod:`millwatch.remote.handover` — a returning worker of a hot-standby pair (README
  "Scale-out"): it takes its mills' tokens once caught up with the other worker, after
  reconciling the operator actions it missed.
* :mod:`millwatch.remote.report_codec` — the monthly report back from its JSON, so the API renders
  it.
* :mod:`millwatch.remote.metrics` — the Prometheus collector of ``millwatch api``.

Data flow: route → ``ZenohBackend`` → zenoh ``get`` ``…/@query/<question>?worker=<name>`` (a
live primary, else its hot standby) → that worker's
``WorkerQueryables`` → ``LocalBackend`` → store/runtime → JSON reply (or ``reply_err`` with
problem JSON, raised again in the API as the same error).

Where things go: a new question is a member of :class:`~millwatch.remote.protocol.Question`, an
entry of :data:`~millwatch.remote.queryables.ANSWERS` and a method of ``ZenohBackend``.
"""
