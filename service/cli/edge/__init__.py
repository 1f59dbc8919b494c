"""Commands that run at the plant's edge, beside the sensor gateways, and for its zenoh network.

- ``spool`` — ``millwatch spool``, the edge forwarder (a spool on disk for a third-party
  gateway, :mod:`millwatch.ingest.spool`), and the ``--spool`` options every gateway command shares
  (``simulate --publish``, ``replay``).
- ``zenoh_certs`` — ``millwatch zenoh-certs``: the site CA and one certificate per role (router,
  worker, api, a gateway per mill) for zenoh over mutual TLS (:mod:`millwatch.ingest.zenoh_tls`).

A new edge-side command goes here, registered in :data:`millwatch.cli.main.COMMANDS`.
"""
