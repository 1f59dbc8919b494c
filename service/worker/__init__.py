"""The worker: each block archived first, then analysed per mill and stored.

Block path (``millwatch serve``; README "Data flow")::

    zenoh callback ─▶ admission.IngressGate (size, key) ─▶ block_queue
    ─▶ archive_first (archiving thread): a gap ─▶ catch-up thread (spooled span, then the
        mill's held blocks); archive (raw bytes, every block) ─▶ its feed in memory, or —
        behind — the archive itself
    archive_first.ArchiveFirst.step (worker thread): for each block (a backlog's runs through
        the batch lane's arrays)
        admission (route, decode, health) ─▶ mill_job.MillJob (queued)
    end of the batch: each mill's analysis ─▶ one store transaction ─▶ alarms to ``on_alarms``
    every checkpoint interval, one mill at a time: snapshot + the analysis's archive position

Modules, low to high (a module imports only those above it):

* ``block_queue`` — the bounded queue between zenoh callbacks and the worker; drops counted.
* ``health`` — per-channel sequencing (a block is new only if its sequence number is; repeats
  and clock faults counted), plausibility (a block judged against its channel's history and its
  receive time: ``implausible_reason``), lifetime counters (checkpointed), losses, staleness,
  rates, latency; the archive's and the store's write-failure episodes (``WriteEpisodes``:
  ``/ready``, metric, alarms, one log line per episode).
* ``admission`` — :class:`~millwatch.worker.admission.BlockAdmission`, the one decision whether a
  block is analysed (route by key, decode, sequence, plausibility) and its counters, for the
  live worker, its replay and offline analysis alike; ``IngressGate``, what a zenoh callback
  may queue at all (no oversize payloads, no keys of no configured channel).
* ``checkpoints`` — when each mill is checkpointed; which archived blocks a checkpoint covers;
  what a mill whose checkpoints are damaged (refused: their checksum) starts from instead.
* ``partition`` — which configured mills this worker analyses when several share a router.
* ``batch_lane`` — many blocks as arrays (archive replay, a live backlog): repeats dropped and
  counted, regular runs admitted at once, the rest block by block — through the worker's public
  methods (``BlockSink``).
* ``worker`` — :class:`~millwatch.worker.worker.Worker`: routing, the block path above, commits,
  checkpoints, restoring them (held mills), acknowledgements, status; the ``MillPipeline``
  Protocol a mill's analysis meets.
* ``mill_job`` — :class:`~millwatch.worker.mill_job.MillJob`, the worker's unit per mill: the
  analyzer plus alarms, turned into store rows.
* ``parallel_replay`` — a long archive tail replayed by several processes, mills split.
* ``offline_analysis`` — ``millwatch analyze``: archive files through the batch lane into the
  mills' analyzers, with no store (the replay path's cost per sample); ``export_files`` reads
  the same way into a Foxglove export (``millwatch archive export``).
* ``recovery`` — :func:`~millwatch.worker.recovery.recover`: restore checkpoints, replay the
  archive tail (one process or several), then go live.
* ``spool_recovery`` — :class:`~millwatch.worker.spool_recovery.SpoolRecovery`: a gap a live
  block reveals is first fetched from the gateways' spools (:mod:`millwatch.ingest.spool`) and
  handled in sequence order before that block (the worker's ``before_live`` hook).
  :class:`~millwatch.worker.spool_recovery.CatchUp`: in ``millwatch serve``, a mill
  whose live block reveals a gap is caught up from the spools on a thread of its own, its
  channels page by page together, its live blocks held meanwhile; the other mills flow.
* ``archive_first`` — the archive is the log and the analysis tails it: an archiving thread
  writes every block first; the analysis takes them from a bounded feed and, behind, reads
  them back from the archive (batch lane) until caught up; lag and backlog.
* ``drain_watch`` — whether each mill's blocks are still being analysed (``/ready``).
* ``runtime`` — :class:`~millwatch.worker.runtime.ServiceRuntime` owns the resources (store,
  archive, zenoh session, archiving and worker threads), starts them in order and closes them
  in reverse.

Where things go: a new per-block check or counter → ``health`` and ``admission`` (and
``ChannelHealth.repeats_in`` / ``follows_on`` / ``observe_run`` for the batch lane's array path,
which must count the same); a new per-mill result or store row
→ ``mill_job``; a new start-up or shutdown step → ``runtime``; a new recovery step →
``recovery``, calling only public ``Worker`` methods.
"""
