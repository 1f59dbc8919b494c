"""Commands that run at the plant's edge, beside the sensor gateways (not beside the worker).

- ``spool`` — ``millwatch spool``, the edge forwarder (a spool on disk for a third-party
  gateway, :mod:`ingest.spool`), and the ``--spool`` options every gateway command shares
  (``simulate --publish``, ``replay``).

A new edge-side command goes here, registered in :data:`service.cli.main.COMMANDS`.
"""
