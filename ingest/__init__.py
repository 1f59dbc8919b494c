"""The edge: how telemetry gets in, is kept, and is played back.

Data path::

    sensor gateway / sim.publisher / replay ──(spool.store, first)──gateway publisher (cache)
        ──▶ zenoh ──▶ (recovering) subscriber ──▶ worker (millwatch.worker)
        ──▶ archive.writer (raw, first) ──▶ analytics
    worker gap ──spool.query──▶ the gateway's spool (or a ``spool.forwarder`` beside it)

What is here (lower lines never import higher ones):

- ``wire``           the versioned block format: one zenoh message = one block of one channel
- ``keys``           the one owner of zenoh key expressions (build/parse pairs, patterns, matching)
- ``zenoh_session``  explicit zenoh configs (connect retried, never fatal), always-closed
  sessions, BLOCK publishers/subscribers, connected-peer count
- ``zenoh_tls``      zenoh over mutual TLS: the files of a session, a CA and per-role
  certificates (the router's access control knows the roles by common name)
- ``gateway``        the only user of the unstable ``zenoh.ext``: the gateway publisher that
  keeps the last ``retention`` of a channel, the worker's recovering subscriber
- ``pacing``         when a timestamped block is due on the wall clock at ``speed`` × real time
- ``mill_files``     reading mill configuration files (the model is in
  ``millwatch.analytics.drivetrain``)
- ``archive/``       the MCAP log: writer with rotation, tail-tolerant reader, recovery, batches
- ``spool/``         a gateway's spool on disk (blocks kept before they are published, for
  hours), recovery served from it by a zenoh queryable, the edge forwarder
- ``replay``         archived blocks back onto zenoh, byte-identical, paced, on replay keys
- ``sim/``           the scene simulator: synthetic telemetry with ground truth, published live
- ``legacy/``        legacy recordings (CSV, .mat, TDMS, MF4, HDF5) as the blocks a gateway
  would have sent (``millwatch archive import``)

Where a new thing goes:

- a new wire version → ``wire`` (``FORMAT_VERSION``, the layout in its docstring, the decoder;
  archived blocks keep the bytes and version they arrived with),
- a new key kind (tag, pattern) → ``keys`` and nowhere else: no f-string keys outside it,
- a new legacy file format → a reader in ``legacy/`` (its map says how),
- a new scene → ``sim/scenes.py`` (catalogue) or a scene file; a new event kind →
  ``sim/spec.py`` plus its segment (``sim/segments.py``) or fault (``sim/faults.py``),
- compiled code → a ``*_kernels.py`` module beside its user.

``ingest`` imports ``analytics`` only.
"""
