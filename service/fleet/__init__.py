"""Fleet re-analysis: ``millwatch analyze`` spread over the machines of a Dask cluster.

* ``distributed`` — one task per mill (:class:`~millwatch.fleet.distributed.MillTask`: the mill,
  the files it reads in the recording's order, which of them it counts foreign blocks in),
  planned by :func:`~millwatch.fleet.distributed.plan_tasks`, run on a Dask scheduler (an
  address, or a local cluster of N worker processes) by
  :func:`~millwatch.fleet.distributed.run_on_dask`. Each task runs the offline analysis of one
  process (:func:`millwatch.worker.offline_analysis.analyze_files`) and returns the mill's report
  and reading counts as plain data, in the shape ``millwatch analyze --jobs`` merges: the output
  is the same, byte for byte.

Data flow: ``cli.analyze --scheduler`` → ``plan_tasks`` → Dask workers (each reads its files
from a filesystem every worker sees at the same path) → reports back to the command, which
merges and prints them as for one process. Dask is an optional dependency
(``pip install 'millwatch[distributed]'``), imported only when a scheduler is asked for.

Where a new thing goes: another engine (Ray, a batch queue) → a module beside ``distributed``
taking the same :class:`~millwatch.fleet.distributed.MillTask`\\ s.
"""
