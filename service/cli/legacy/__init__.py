"""``millwatch archive import``: legacy recordings (CSV, .mat, TDMS, MF4, HDF5) in as MCAP.

* ``archive_import`` — the ``import`` action of ``millwatch archive`` (registered by
  :mod:`millwatch.cli.archive`): its options, a help with an example per format, progress bars
  and the summary. Argparse and light helpers only, so ``--help`` answers at once; the readers
  and the writer (:mod:`millwatch.ingest.legacy`) are imported when it runs.
"""
