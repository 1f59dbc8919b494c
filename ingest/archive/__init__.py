"""The MCAP archive: millwatch's log of raw blocks, byte-identical as received.

What is here:

- ``files``          the encoding (one channel per key, payload = wire block), file names and
                     their order, ``ArchivePosition`` (checkpoints), ``ArchiveError``
- ``writer``         ``ArchiveWriter``: rotating, standalone, zstd-chunked files, bounded data loss;
                     failed writes (a full disk) kept in memory (bounded) and written again in
                     order, the file readable to its last good chunk meanwhile
- ``mcap_append``    fast appends into the ``mcap`` writer's open chunk (used by ``writer``)
- ``reader``         ``TailTolerantReader`` (one file, survives a torn tail) and ``ArchiveReader``
                     (a prefix's files in order, filtered by key, time and position)
- ``recovery``       ``recover_file``: a killed writer's file rewritten finished and indexed
- ``batches``        ``BatchReader``, ``archive_batches``: the same messages as arrays (fast replay)
- ``batch_kernels``  compiled record scans and payload packing for ``batches``
- ``copy_kernels``   ``copy_bytes``: a bounds-checked ``memcpy`` usable inside compiled code
- ``sample_spans``   ``SampleSpans``: what a file's blocks say of their samples, per key (first
                     and last *sample* time, count, rate, dtype, unit; ``millwatch archive info``)
- ``foxglove_export`` ``FoxgloveExportWriter``: a derived MCAP file Foxglove plots — samples
                     and analysis results as protobuf topics stamped with *sample* time (the
                     archive's log time is receive time: ``files``)

Data flow: worker ──write──▶ writer ──files──▶ reader / batches ──▶ recovery of the worker,
replay, ``millwatch analyze``, ``millwatch archive export`` (→ ``foxglove_export``); recovery
rewrites what a crash left. A file written before a
crash is readable by both readers up to its last complete record.

Where a new thing goes: a format or naming change → ``files`` (both sides read it); a new way
to read → beside ``reader``, extending ``TailTolerantBase`` so the stopping rules stay one;
compiled loops → a ``*_kernels.py`` module.
"""
