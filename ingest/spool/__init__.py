"""A gateway's spool on disk: every block kept before it is published, recovery served from it.

What is here:

- ``runs``       ``SeqRuns``: sets of wire sequence numbers as runs (the index, the ledger)
- ``store``      ``Spool``: rotating unchunked MCAP files in one directory, each block with the
                 OS before it is published; index by (key, seq) rebuilt on open (sidecar JSON per
                 file; a killed writer's file read up to its last complete record); retention by
                 hours and bytes, oldest file first, what it dropped counted exactly (ledger);
                 the gateway's own metadata (a scene's anchor)
- ``query``      ``SpoolServer``: a zenoh queryable per spooled key
  (``millwatch.ingest.keys.spool_key``)
                 answering a seq range with the blocks in order and the dropped count;
                 ``fetch_spooled``: the client the worker calls
- ``recent``     ``RecentBlocks``: a gateway without a spool keeps its last minute in memory,
                 served by the same queryable (a restarted gateway's first blocks)
- ``resume``     ``unspooled``: a restarted gateway skips what its spool shows it published
- ``forwarder``  ``SpoolForwarder``: the edge forwarder for third-party gateways
                 (``millwatch spool``): subscribe locally, spool, serve recovery

Data flow: gateway (``simulate --publish``, ``replay``;
:class:`millwatch.ingest.gateway.GatewayPublisher`
with a spool) ──append──▶ store ──publish──▶ zenoh; worker gap ──fetch_spooled──▶ query ──▶
store ──▶ blocks in seq order ──▶ the worker's block path (``millwatch.worker.spool_recovery``).

Where a new thing goes: a file or retention rule → ``store``; a query parameter → ``query`` (both
sides); a new kind of gateway uses ``GatewayPublisher`` with a ``Spool`` and ``SpoolServer``.
"""
