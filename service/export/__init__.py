"""The archive for other tools: a span of a mill as an MCAP file that Foxglove plots.

* ``foxglove`` — :func:`~millwatch.export.foxglove.export_archive`: the archive's blocks of one mill
  in a span, written by :class:`millwatch.ingest.archive.foxglove_export.FoxgloveExportWriter` at
  sample time, beside what the real analyzer and alarm rules conclude over the span (states, events,
  start peaks, harmonic lines, damage, alarms); :class:`~millwatch.export.foxglove.SpanExport`
  is the per-block composition, :data:`~millwatch.export.foxglove.Admit` what the caller passes to
  decode and admit messages.

Data flow: archive files → the command's reading and admission, as ``millwatch analyze``
(``Feed``: batches, regular runs as arrays into ``SpanExport.blocks``; or ``Admit``, message by
message) → ``SpanExport`` → analyzer, alarms → writer. Called by ``cli/archive`` (``millwatch
archive export``); imports ``analytics``, ``ingest`` and ``alarms`` only. A new
export format goes here as a module of its own.
"""
